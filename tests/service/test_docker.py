"""docker/compose.yaml and docker/Dockerfile against the real CLIs (Docker itself is not needed): every command
parses with ``drt``'s, ``dask scheduler``'s and ``dask worker``'s own parsers, every ``DRT_*`` variable is a setting
that accepts its value, and only the api has the data volume."""
from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest
import yaml

from service.cli.main import build_parser
from service.settings import ServiceSettings

DOCKER = Path(__file__).resolve().parents[2] / "docker"


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load((DOCKER / "compose.yaml").read_text())


def parse_drt(argv: list[str]):
    assert argv[0] == "drt", argv
    try:
        return build_parser().parse_args(argv[1:])
    except SystemExit:
        pytest.fail(f"drt does not accept {argv}")


def parse_dask(argv: list[str]) -> dict:
    from distributed.cli import dask_scheduler, dask_worker

    assert argv[0] == "dask", argv
    command = {"scheduler": dask_scheduler.main, "worker": dask_worker.main}[argv[1]]
    try:
        return command.make_context(f"dask {argv[1]}", list(argv[2:])).params
    except Exception as e:  # noqa: BLE001 - click's usage errors
        pytest.fail(f"dask {argv[1]} does not accept {argv[2:]}: {e}")


def resolved(value) -> str:
    """Compose's ${VAR:-default} with VAR unset."""
    return re.sub(r"\$\{[A-Z_]+:-([^}]*)\}", r"\1", str(value))


def test_every_compose_command_parses_with_the_real_cli(compose):
    services = compose["services"]
    api = parse_drt(services["api"]["command"])
    assert api.command == "serve" and api.scheduler == "tcp://scheduler:8786" and api.host == "0.0.0.0"
    sched = parse_dask(services["scheduler"]["command"])
    assert sched["port"] == "8786" or sched["port"] == 8786
    worker = parse_dask(services["worker"]["command"])
    assert worker["scheduler"] == "tcp://scheduler:8786" and worker["nthreads"] == 1
    assert api.scheduler.rsplit(":", 1)[1] == str(sched["port"])  # the api talks to the scheduler's port


def test_compose_environment_names_real_settings_and_only_the_api_has_the_data(compose):
    services = compose["services"]
    fields = ServiceSettings.model_fields
    for name, svc in services.items():
        for var, value in (svc.get("environment") or {}).items():
            assert var.startswith("DRT_") and var[4:].lower() in fields, f"{name}: {var} is not a setting"
            ServiceSettings(**{var[4:].lower(): resolved(value)})  # and its value is accepted
    assert services["api"]["volumes"] == ["drt-data:/data"]
    assert services["api"]["environment"]["DRT_DATA_DIR"] == "/data"
    for name in ("scheduler", "worker"):
        assert "volumes" not in services[name], f"{name} must not see the data volume"
        assert not any(k.startswith("DRT_") for k in services[name].get("environment") or {})


def test_dockerfile_commands_parse_and_warm_the_kernel_cache():
    text = (DOCKER / "Dockerfile").read_text().replace("\\\n", " ")
    cmd = json.loads(re.search(r"^CMD (\[.*\])$", text, re.M).group(1))
    assert parse_drt(cmd).command == "serve"
    warm = re.search(r"^RUN (drt render .*?)(&&|$)", text, re.M).group(1)
    args = parse_drt(shlex.split(warm))
    assert args.command == "render" and args.spp == 1  # a real render compiles every kernel a job will use
    env_names = re.findall(r"\b(DRT_[A-Z_]+)=", text)
    assert env_names and all(n[4:].lower() in ServiceSettings.model_fields for n in env_names)
