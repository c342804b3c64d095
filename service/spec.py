"""A job's render spec: a scene reference plus the renderer's ``RenderRequest``, built from the wire settings
(``schemas.JobCreate``) the way ``drt render`` builds it from its flags (``RenderRequest.from_settings``); and the
products a job's frame writes (``frame_products``).

A ``RenderSpec`` is what a Dask task needs to know about a job: plain, frozen and hashable, so it pickles cheaply
and keys the worker's scene cache. It never holds pydantic objects (workers need not import the wire format).

**Products.** A frame is rendered once, with the overrides of its render settings' first RenderProduct (as
``RenderRequest.product`` None says), and every raster product that shares those overrides is written from that
render, each with its RenderVars as layers (``renderer.output.var_channels``, as ``drt render`` writes them). A product with
overrides of its own (another camera, resolution, ...) would need a render of its own: the service names it in a
warning and leaves it to ``drt render``. A stage without products writes one image, named after the scene file.
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

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


@dataclass(frozen=True)
class FrameProduct:
    """One EXR a frame writes: its name (the productName at the frame, ``$F4``/``####`` expanded; not yet made safe,
    see ``schemas.product_name``), its RenderProduct prim (None: the image of a stage without products) and vars."""

    name: str
    prim: str | None
    vars: tuple = ()  # renderer.usd.render_products.VarSpec


def default_product_name(scene_name: str) -> str:
    """The name pattern of a stage's one image when its render settings have no RenderProduct: the scene's."""
    return os.path.splitext(os.path.basename(scene_name))[0] + ".####.exr"


def frame_products(stage, request: RenderRequest, frame: float, warn) -> list[FrameProduct]:
    """The products one render of ``frame`` writes (see the module docstring); ``warn(message)`` hears of the
    products and vars it leaves out. RenderError when the settings have products but none to write."""
    from renderer.output.names import expand_frame
    from renderer.errors import RenderError
    from renderer.output.var_channels import UNWRITTEN, unwritten
    from renderer.usd.render_products import read_products, resolve_settings_path

    products = read_products(stage, resolve_settings_path(stage, request.settings_prim, lambda *a: None), frame)
    if not products:
        return [FrameProduct(expand_frame(default_product_name(request.scene_path), frame), None)]
    out = []
    for p in products:
        if p.type != "raster":
            warn(f"RenderProduct {p.path}: {p.type} products are not written (drt writes raster images)")
        elif p.override_key != products[0].override_key:
            warn(f"RenderProduct {p.path} has a camera or image settings of its own: the service renders "
                 f"{products[0].path}'s view only, so it is not written (drt render writes it)")
        else:
            name = p.name or p.path.rsplit("/", 1)[-1] + ".####.exr"
            if not p.name:
                warn(f"RenderProduct {p.path} has no productName: written as {name}")
            out.append(FrameProduct(expand_frame(name, frame), p.path, p.vars))
    if not out:
        raise RenderError("the render settings have no raster RenderProduct the service can write")
    skipped = unwritten([v for p in out for v in p.vars])
    if skipped:
        warn(f"{UNWRITTEN}: {', '.join(dict.fromkeys(skipped))}")
    return out
