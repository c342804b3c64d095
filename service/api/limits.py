"""``/v1/limits``: what one job may cost on this farm (a submission over any limit is refused before queuing)."""
from __future__ import annotations

from fastapi import APIRouter

from schemas import Limits

from ..intake import limit_checks
from .deps import Authorized, SettingsDep
from .docs import UNAUTHORIZED_ANSWER

router = APIRouter(tags=["limits"], dependencies=[Authorized], responses=UNAUTHORIZED_ANSWER)


@router.get("/limits", response_model=Limits)
def get_limits(settings: SettingsDep):
    """The farm's limits (``DRT_MAX_*``): upload bytes, samples per job, pixels per frame, frames and tiles per
    job, jobs queued in total and per client."""
    return limit_checks.public(settings)
