"""What the job monitor reads besides jobs: ``GET /v1/jobs/{id}/tiles`` (a job's tile map) and ``GET /v1/farm``
(Dask's workers and the tiles each holds)."""
from __future__ import annotations

from fastapi import APIRouter

from schemas import ErrorBody, Farm, TileMap

from .. import errors
from ..errors import ApiError
from ..farm import view as farm
from ..queue.store import JobNotFound
from .deps import Authorized, RuntimeDep

router = APIRouter(tags=["monitor"], dependencies=[Authorized], responses={401: {"model": ErrorBody}})


@router.get("/jobs/{job_id}/tiles", response_model=TileMap, responses={404: {"model": ErrorBody}})
def job_tiles(runtime: RuntimeDep, job_id: str):
    """Per frame: the tiles checkpointed so far and the tiles workers hold now (row-major tile indices)."""
    try:
        row = runtime.store.get_job(job_id)
    except JobNotFound:
        raise ApiError(404, errors.JOB_NOT_FOUND) from None
    return farm.tile_map(row, runtime.store, runtime.coordinator.farm())


@router.get("/farm", response_model=Farm)
def get_farm(runtime: RuntimeDep):
    """The Dask workers (threads, memory, CPU) with the drt tasks each holds, and the Dask dashboard's link."""
    coordinator = runtime.coordinator
    return farm.farm(runtime.settings, coordinator.farm(), runtime.store, coordinator.stats())
