"""The service's wire format (pydantic v2): what clients send and what they get back.

``schemas`` knows nothing of the renderer, the database or the queue; the service converts these models to the
renderer's own plain dataclasses. Settings keys are named like the ``drt render`` flags.
"""
from .jobs import ErrorBody, FramePublic, FrameState, Health, JobList, JobPublic, JobState, SceneInfo
from .limits import Limits
from .monitor import Farm, FarmTask, FarmWorker, FrameTiles, TileMap
from .settings import AOVS, FILTERS, MAX_FRAMES, TIME_FILTERS, FrameRange, JobCreate, RenderSettings

__all__ = ["AOVS", "FILTERS", "MAX_FRAMES", "TIME_FILTERS", "ErrorBody", "Farm", "FarmTask", "FarmWorker",
           "FramePublic", "FrameRange", "FrameState", "FrameTiles", "Health", "JobCreate", "JobList", "JobPublic",
           "JobState", "Limits", "RenderSettings", "SceneInfo", "TileMap"]
