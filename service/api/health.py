"""``/healthz`` (never needs a token: load balancers call it) and ``/metrics`` (Prometheus text)."""
from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import PlainTextResponse, Response

from schemas import Health

from . import metrics
from .deps import Authorized, RuntimeDep
from .docs import UNAUTHORIZED_ANSWER

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Health)
async def healthz(runtime: RuntimeDep):
    """200 while the service runs (it still answers status requests and downloads while the cluster is away);
    ``cluster`` says whether the Dask scheduler is reachable, ``workers``/``threads`` what it has. Answers from
    facts the coordinator refreshes once a second: never waits on the scheduler."""
    facts = runtime.coordinator.facts()
    return Health(status="ok" if facts.reachable else "degraded",
                  cluster="reachable" if facts.reachable else "unreachable", workers=facts.workers,
                  threads=facts.threads)


# response_class=Response (no media type of its own): the errors are then documented as JSON, which they are.
@router.get("/metrics", response_class=Response, dependencies=[Authorized],
            responses={200: {"content": {"text/plain": {"schema": {"type": "string"}}},
                             "description": "Prometheus text format 0.0.4"}, **UNAUTHORIZED_ANSWER})
def get_metrics(runtime: RuntimeDep):
    """Jobs by state, queue depth, tiles in flight and pending, tiles/s, task failures, cluster size."""
    stats = runtime.coordinator.stats()
    facts = runtime.coordinator.facts()
    text = metrics.render(runtime.store.counts_by_state(), tiles_completed=stats.tiles_completed,
                          tiles_failed=stats.tiles_failed, tiles_per_second=stats.tiles_per_second,
                          tiles_in_flight=stats.in_flight, tiles_pending=stats.pending,
                          workers=facts.workers, threads=facts.threads, tiles_lost=stats.tiles_lost,
                          cluster_reachable=facts.reachable)
    return PlainTextResponse(text, media_type="text/plain; version=0.0.4; charset=utf-8")
