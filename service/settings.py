"""Service settings from environment variables with the prefix ``DRT_`` (pydantic-settings).

``create_app(settings)`` takes a ``ServiceSettings``; ``drt serve`` builds one from the environment and its flags.
"""
from __future__ import annotations

import os
from pathlib import Path

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


def default_cores() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


class ServiceSettings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="DRT_", extra="ignore")

    data_dir: Path = Field(Path("drt-data"), description="database, uploaded scenes, checkpoints and results")
    scheduler_address: str | None = Field(
        None, description="an external `dask scheduler` (tcp://host:8786); unset: start a LocalCluster")
    workers: int = Field(1, ge=1, le=256, description="LocalCluster worker processes")
    threads_per_worker: int = Field(0, ge=0, le=256, description="threads per LocalCluster worker (0: all cores)")
    processes: bool = Field(True, description="LocalCluster workers as processes (false: threads in the service)")
    scheduler_process: bool = Field(
        True, description="the job scheduler and the Dask client in a process of their own (false: threads of the "
                          "API process)")
    api_token: SecretStr | None = Field(None, description="bearer token required by every endpoint but /healthz")
    max_upload_bytes: int = Field(256 * 2**20, ge=1, description="largest scene upload (413 above)")
    # A job's cost, refused with 422 before it is queued. Defaults for one 2-core machine, which renders about
    # 6e5 samples/s on a simple scene: 2e9 samples is roughly an hour of it.
    max_samples_per_job: int = Field(2_000_000_000, ge=1,
                                     description="width x height x spp x frames of one job")
    max_pixels_per_frame: int = Field(4096 * 4096, ge=1, description="width x height of one frame")
    max_queued_jobs: int = Field(200, ge=1, description="jobs queued or running, all clients together")
    max_queued_jobs_per_client: int = Field(
        50, ge=1, description="jobs queued or running of one client (its bearer token, else its address)")
    max_usdz_unpacked_bytes: int = Field(1 * 2**30, ge=1, description="largest total size of a .usdz's entries")
    max_usdz_entries: int = Field(10_000, ge=1)
    max_frames: int = Field(10_000, ge=1, description="frames per job")
    max_tiles: int = Field(200_000, ge=1, description="tiles per job (frames x tiles per frame)")
    max_in_flight: int = Field(0, ge=0, description="tasks submitted to Dask at once (0: twice the worker threads)")
    task_samples: int = Field(
        65536, ge=0, description="a frame's tiles go to Dask in batches of up to this many samples, one task each "
                                 "(0: one tile per task); tiny jobs cost one task, not one per tile")
    tile_retries: int = Field(2, ge=0, le=20, description="extra attempts for a tile whose task failed")
    inspect_timeout: float = Field(120.0, gt=0, description="seconds to load a scene when a job is submitted")
    inspect_processes: int = Field(2, ge=1, le=64, description="local processes that inspect submitted scenes")
    scheduler_timeout: float = Field(
        30.0, gt=0, description="seconds the Dask client reconnects by itself before the service makes a new one")
    scene_cache_size: int = Field(2, ge=1, le=64, description="prepared scenes kept per worker process")
    poll_interval: float = Field(0.5, gt=0, description="scheduler wake-up interval, seconds")
    dashboard_url: str | None = Field(
        None, description="the Dask dashboard as browsers reach it (the monitor's farm page links to it)")

    @field_validator("data_dir")
    @classmethod
    def _absolute(cls, v: Path) -> Path:
        # The service's threads and processes (inspection) must agree on it whatever their working directory.
        return v.expanduser().absolute()

    @field_validator("api_token", "scheduler_address", "dashboard_url", mode="before")
    @classmethod
    def _empty_is_unset(cls, v):
        # `DRT_API_TOKEN=` (as compose files write an unset variable) means no token, not the empty token.
        return None if isinstance(v, str) and not v.strip() else v

    def local_threads(self) -> int:
        return self.threads_per_worker or max(1, default_cores() // self.workers)

    @property
    def db_path(self) -> Path:
        return self.data_dir / "drt.sqlite3"
