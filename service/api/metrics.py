"""``/metrics`` in the Prometheus text exposition format (written by hand: a dozen lines need no library)."""
from __future__ import annotations

from schemas import JobState


def render(counts: dict[JobState, int], *, tiles_completed: int, tiles_failed: int, tiles_per_second: float,
           tiles_in_flight: int, tiles_pending: int, workers: int, threads: int, tiles_lost: int = 0,
           cluster_reachable: bool = True) -> str:
    out: list[str] = []

    def metric(name: str, kind: str, help_: str, samples: list[tuple[str, float]]) -> None:
        out.append(f"# HELP {name} {help_}")
        out.append(f"# TYPE {name} {kind}")
        for labels, value in samples:
            out.append(f"{name}{labels} {value:g}" if isinstance(value, float) else f"{name}{labels} {value}")

    metric("drt_jobs", "gauge", "Jobs by state.", [(f'{{state="{s.value}"}}', counts.get(s, 0)) for s in JobState])
    metric("drt_queue_depth", "gauge", "Jobs waiting to start (state queued).", [("", counts.get(JobState.queued, 0))])
    metric("drt_tiles_pending", "gauge", "Tiles of active jobs not yet submitted to the cluster.",
           [("", tiles_pending)])
    metric("drt_tiles_in_flight", "gauge", "Tasks submitted to the cluster and not finished.", [("", tiles_in_flight)])
    metric("drt_tiles_completed_total", "counter", "Tiles rendered and checkpointed since the service started.",
           [("", tiles_completed)])
    metric("drt_task_failures_total", "counter", "Task attempts that failed (and were retried or failed the job).",
           [("", tiles_failed)])
    metric("drt_tiles_per_second", "gauge", "Tiles finished per second over the last minute.",
           [("", float(tiles_per_second))])
    metric("drt_tasks_lost_total", "counter", "Tasks lost with the scheduler connection and resubmitted "
           "(not failures).", [("", tiles_lost)])
    metric("drt_cluster_reachable", "gauge", "1 while the Dask scheduler is reachable.", [("", int(cluster_reachable))])
    metric("drt_workers", "gauge", "Dask workers connected.", [("", workers)])
    metric("drt_worker_threads", "gauge", "Dask worker threads connected.", [("", threads)])
    return "\n".join(out) + "\n"
