"""Scale-out efficiency: the same job through `drt serve --scheduler` on one single-threaded `dask worker`, then on
two; samples/s per worker, and the efficiency (samples/s with two) / (2 x samples/s with one); goal >= 0.9.

    python bench/scale_out.py [--width 320 --height 240 --spp 64 --tile 32] [--scene examples/demo.usda]

Everything on loopback, in a temporary directory; the workers get a working directory of their own and no DRT_*
variable (they need only the scheduler's address). The job's samples/s is the service's own figure (samples
rendered over the time from its start to its end), measured after a warm-up job so that both runs find the kernels
compiled and the scene cached per worker process the same way. On a machine with fewer free cores than workers
the figure says so rather than the cluster's efficiency.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

REPO = Path(__file__).absolute().parents[1]
BIN = Path(sys.executable).parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def env() -> dict:
    e = {k: v for k, v in os.environ.items() if not k.startswith("DRT_")}
    e["PYTHONPATH"] = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    return e


def spawn(args: list[str], log: Path, cwd: Path, extra: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen(args, env={**env(), **(extra or {})}, cwd=cwd, stdout=open(log, "ab"),
                            stderr=subprocess.STDOUT, start_new_session=True)


def wait_workers(url: str, n: int, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{url}/healthz", timeout=2).json().get("workers") == n:
                return
        except (httpx.HTTPError, ValueError):
            pass
        time.sleep(0.2)
    sys.exit(f"scale_out: the cluster did not reach {n} worker(s)")


def run_job(http: httpx.Client, scene: Path, settings: dict) -> dict:
    with open(scene, "rb") as f:
        r = http.post("/v1/jobs", files={"scene": (scene.name, f)}, data={"settings": json.dumps(settings)})
    r.raise_for_status()
    job_id = r.json()["id"]
    while (job := http.get(f"/v1/jobs/{job_id}").json())["state"] in ("queued", "running"):
        time.sleep(0.1)
    if job["state"] != "succeeded":
        sys.exit(f"scale_out: job {job_id} {job['state']}: {job['error']}")
    return job


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default=str(REPO / "examples" / "demo.usda"))
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--tile", type=int, default=32)
    args = p.parse_args(argv)
    settings = {"width": args.width, "height": args.height, "spp": args.spp, "tile": args.tile}
    procs: list[subprocess.Popen] = []
    with tempfile.TemporaryDirectory(prefix="drt-scale-") as tmp:
        tmp = Path(tmp)
        (tmp / "workers").mkdir()
        try:
            port = free_port()
            address = f"tcp://127.0.0.1:{port}"
            procs.append(spawn([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                "--no-dashboard"], tmp / "scheduler.log", tmp / "workers"))
            time.sleep(2)
            worker = [str(BIN / "dask"), "worker", address, "--nthreads", "1", "--no-dashboard"]
            procs.append(spawn(worker, tmp / "worker0.log", tmp / "workers"))
            api_port = free_port()
            url = f"http://127.0.0.1:{api_port}"
            procs.append(spawn([str(BIN / "drt"), "serve", "--port", str(api_port), "--scheduler", address,
                                "--log-level", "warning"], tmp / "serve.log", tmp,
                               {"DRT_DATA_DIR": str(tmp / "data")}))
            wait_workers(url, 1)
            http = httpx.Client(base_url=url, timeout=60)
            run_job(http, Path(args.scene), {**settings, "spp": 1})  # warm-up: kernels, scene cache
            one = run_job(http, Path(args.scene), settings)["samples_per_second"]
            procs.append(spawn(worker, tmp / "worker1.log", tmp / "workers"))
            wait_workers(url, 2)
            run_job(http, Path(args.scene), {**settings, "spp": 1, "seed": 1})  # warm the second worker
            two = run_job(http, Path(args.scene), {**settings, "seed": 2})["samples_per_second"]
            efficiency = two / (2 * one)
            cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
            print(f"job: {args.width}x{args.height}, {args.spp} spp, {args.tile}-pixel tiles of "
                  f"{Path(args.scene).name}; {cores} core(s) on this machine")
            print(f"1 worker x 1 thread : {one / 1e6:.3f} Msamples/s ({one / 1e6:.3f} per worker)")
            print(f"2 workers x 1 thread: {two / 1e6:.3f} Msamples/s ({two / 2e6:.3f} per worker)")
            print(f"scale-out efficiency: {efficiency:.2f} of linear (goal >= 0.90: "
                  f"{'met' if efficiency >= 0.9 else 'NOT met'})")
            return 0
        finally:
            for proc in reversed(procs):
                try:
                    os.killpg(proc.pid, signal.SIGTERM)
                    proc.wait(timeout=20)
                except (ProcessLookupError, subprocess.TimeoutExpired):
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()


if __name__ == "__main__":
    sys.exit(main())
