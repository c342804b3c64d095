"""A job's render spec: a scene reference plus the renderer's ``RenderRequest``, built from the wire settings
(``schemas.JobCreate``) the way ``drt render`` builds it from its flags (``RenderRequest.from_settings``).

A ``RenderSpec`` is what a Dask task needs to know about a job: plain, frozen and hashable, so it pickles cheaply
and keys the worker's scene cache. It never holds pydantic objects (workers need not import the wire format).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from renderer.options import RenderOptions
from renderer.request import RenderRequest
from schemas import JobCreate


@dataclass(frozen=True)
class RenderSpec:
    scene_sha256: str
    # Its scene_path is the stored upload (inspection), or the upload's file name (tasks: workers use their copy).
    request: RenderRequest

    @classmethod
    def from_settings(cls, settings: JobCreate, scene_path: str, scene_sha256: str) -> "RenderSpec":
        return cls(scene_sha256, RenderRequest.from_settings(scene_path, None, settings.render_settings()))

    @property
    def scene_path(self) -> str:
        return self.request.scene_path

    def cache_key(self, frame: float | None) -> tuple:
        """What a prepared scene depends on: not the file's path (the same content is the same scene), nor the
        sampling and output settings (``RenderRequest.scene_key``)."""
        return self.request.at_frame(frame).scene_key()

    def options(self) -> RenderOptions:
        return self.request.options

    def request_at(self, frame: float | None) -> RenderRequest:
        """One frame of this job as the renderer's RenderRequest."""
        return self.request.at_frame(frame)

    def load(self, frame: float | None, scene_path: str | None = None):
        """Load one frame as the renderer's Scene, with the camera overrides applied; ``scene_path``: a worker's
        own copy of the scene."""
        request = self.request_at(frame)
        if scene_path is not None:
            request = dataclasses.replace(request, scene_path=scene_path)
        return request.load()
