"""The service's wire format (pydantic v2): what clients send and what they get back.

``schemas`` knows nothing of the database or the queue; of the renderer it reads only the settings table
(``renderer.settings.options``, pure Python), from which ``RenderSettings`` is derived. Settings keys are named like the
``drt render`` flags.
"""
from .jobs import (ErrorBody, FramePublic, FrameState, Health, JobList, JobPublic, JobState, ProductPublic,
                   SceneInfo, product_name)
from .limits import Limits
from .monitor import Farm, FarmTask, FarmWorker, FrameTiles, TileMap
from .settings import MAX_FRAMES, FrameRange, JobCreate, RenderSettings

__all__ = ["MAX_FRAMES", "ErrorBody", "Farm", "FarmTask", "FarmWorker",
           "FramePublic", "FrameRange", "FrameState", "FrameTiles", "Health", "JobCreate", "JobList", "JobPublic",
           "JobState", "Limits", "ProductPublic", "RenderSettings", "SceneInfo", "TileMap", "product_name"]
