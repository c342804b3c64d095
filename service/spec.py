"""A job's render spec: a scene reference plus the renderer's ``RenderRequest``, built from the wire settings
(``schemas.JobCreate``) the way ``drt render`` builds it from its flags (``RenderRequest.from_settings``); and the
products a job's frame writes (``frame_products``).

A ``RenderSpec`` is what a Dask task needs to know about a job: plain, frozen and hashable, so it pickles cheaply
and keys the worker's scene cache. It never holds pydantic objects (workers need not import the wire format).

**Products.** Which files a frame writes is ``renderer.output.frame_products``' decision, the one ``drt render``
takes: a frame is rendered once, with the overrides of its render settings' first RenderProduct (as
``RenderRequest.product`` None says), and every raster product that shares those overrides is written from that
render, each with its RenderVars as layers (``renderer.output.var_channels``). A product with overrides of its own
(another camera, resolution, ...) would need a render of its own: the service (one view per frame) names it in a
warning. A stage without products writes one image, named after the scene file.
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

from renderer.output.frame_products import FrameProduct
from renderer.settings.options import RenderOptions
from renderer.settings.request import RenderRequest
from schemas import JobCreate


@dataclass(frozen=True)
class RenderSpec:
    scene_sha256: str
    # Its scene_path is the stored upload (inspection), or the upload's file name (tasks: workers use their copy).
    request: RenderRequest
    # what the products' RenderVars alone need rendered (``renderer.output.var_channels.needs``: AOVs, LPE, Cryptomatte and
    # hit items; in request.options too, but not asked for by the job)
    product_aovs: tuple[str, ...] = ()

    @classmethod
    def from_settings(cls, settings: JobCreate, scene_path: str, scene_sha256: str,
                      product_aovs: tuple[str, ...] = ()) -> "RenderSpec":
        from renderer.output.var_channels import with_needs

        request = RenderRequest.from_settings(scene_path, None, settings.render_settings())
        options, extra = with_needs(request.options, product_aovs)
        if extra:
            request = dataclasses.replace(request, options=options)
        return cls(scene_sha256, request, extra)

    @property
    def user_aovs(self) -> tuple[str, ...]:
        """The AOVs the job asked for: a product without vars holds these, one with vars these after its vars."""
        return tuple(a for a in self.request.options.aovs if a not in self.product_aovs)

    @property
    def user_cryptomatte(self) -> tuple[str, ...]:
        """The Cryptomatte layers the job asked for (every product holds them)."""
        return tuple(k for k in self.request.options.cryptomatte if "cryptomatte:" + k not in self.product_aovs)

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


def default_product_name(scene_name: str) -> str:
    """The name pattern of a stage's one image when its render settings have no RenderProduct: the scene's."""
    return os.path.splitext(os.path.basename(scene_name))[0] + ".####.exr"


def frame_products(stage, request: RenderRequest, frame: float, warn) -> list[FrameProduct]:
    """The products one render of ``frame`` writes (``renderer.output.frame_products``, the rules ``drt render``
    follows, with one view per frame and the scene's name for a stage without products); ``warn(message)`` hears of
    the products and vars it leaves out. RenderError when the settings have products but none to write."""
    from renderer.output.frame_products import frame_products as decide
    from renderer.output.var_channels import UNWRITTEN, unwritten
    from renderer.usd.render_products import read_products, resolve_settings_path

    products = read_products(stage, resolve_settings_path(stage, request.settings_prim, lambda *a: None), frame)
    out = decide(products, frame, fallback=default_product_name(request.scene_path), one_view=True,
                 warn=lambda message, item=None: warn(message if item is None else f"{message}: {item}"))
    skipped = unwritten([v for p in out for v in p.vars])
    if skipped:
        warn(f"{UNWRITTEN}: {', '.join(dict.fromkeys(skipped))}")
    return out
