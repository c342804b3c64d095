"""UsdRender products and vars as plain records: what files a frame writes and which layers each holds.

``read_products(stage, settings_path, frame)`` reads the RenderProducts of the chosen RenderSettings prim
(``camera.settings_prim``) at a frame: each one's ``productName`` (time-sampled as Solaris authors it), its
``productType``, the overrides it authors (``override_key``: products with equal keys share one render) and its
``orderedVars`` as ``VarSpec``s. Which pixels a var's source names is ``renderer.aovs``' business.
"""
from __future__ import annotations

from dataclasses import dataclass

from pxr import UsdRender

from renderer.usd.camera import settings_prim, settings_products

# the RenderSettingsBase attributes a product may override, besides its camera relationship
_OVERRIDES = ("resolution", "pixelAspectRatio", "aspectRatioConformPolicy", "dataWindowNDC", "disableMotionBlur",
              "instantaneousShutter", "disableDepthOfField")


@dataclass(frozen=True)
class VarSpec:
    """One RenderVar of a product: the EXR layer it becomes and what fills it."""

    path: str  # the RenderVar prim
    layer: str  # driver:parameters:aov:name, else the prim's name
    source: str  # sourceName
    source_type: str  # raw, primvar, lpe, intrinsic
    data_type: str  # color3f, float, normal3f, ...
    format: str | None  # driver:parameters:aov:format (half, float, ...) if authored


@dataclass(frozen=True)
class ProductSpec:
    """One RenderProduct at one frame."""

    path: str  # the RenderProduct prim
    name: str  # its productName at the frame (may still hold $F4 or #### to expand)
    type: str  # productType: raster, deepRaster, ...
    vars: tuple[VarSpec, ...]
    override_key: tuple  # the product's authored overrides: equal keys render alike


def _value(attr, frame: float):
    return attr.Get(frame) if attr and attr.HasAuthoredValue() else None


def _var(stage, path) -> VarSpec | None:
    prim = stage.GetPrimAtPath(path)
    if not prim or not prim.IsA(UsdRender.Var):
        return None
    rv = UsdRender.Var(prim)
    name = prim.GetAttribute("driver:parameters:aov:name")
    fmt = prim.GetAttribute("driver:parameters:aov:format")
    layer = str(name.Get()) if name and name.HasAuthoredValue() and name.Get() else prim.GetName()
    return VarSpec(path=str(path), layer=layer, source=str(rv.GetSourceNameAttr().Get() or ""),
                   source_type=str(rv.GetSourceTypeAttr().Get() or "raw"),
                   data_type=str(rv.GetDataTypeAttr().Get() or "color3f"),
                   format=str(fmt.Get()) if fmt and fmt.HasAuthoredValue() else None)


def resolve_settings_path(stage, settings_path: str | None, warn) -> str | None:
    """The RenderSettings prim a render uses (see ``camera.settings_prim``), as a path; None if there is none."""
    prim = settings_prim(stage, settings_path, warn)
    return str(prim.GetPath()) if prim else None


def read_products(stage, settings_path: str | None, frame: float) -> list[ProductSpec]:
    """The products of the RenderSettings prim ``settings_path`` (None: no products) at ``frame``."""
    if settings_path is None:
        return []
    out = []
    for prim in settings_products(stage, stage.GetPrimAtPath(settings_path)):
        product = UsdRender.Product(prim)
        name = _value(product.GetProductNameAttr(), frame)
        kind = _value(product.GetProductTypeAttr(), frame) or "raster"
        key = [tuple(str(t) for t in product.GetCameraRel().GetForwardedTargets())]
        for attr in _OVERRIDES:
            v = _value(prim.GetAttribute(attr), frame)
            key.append(None if v is None else str(v))
        variables = (_var(stage, t) for t in product.GetOrderedVarsRel().GetForwardedTargets())
        out.append(ProductSpec(path=str(prim.GetPath()), name=str(name) if name else "", type=str(kind),
                               vars=tuple(v for v in variables if v is not None), override_key=tuple(key)))
    return out


def default_frame(stage) -> float:
    """The frame rendered when none is given: the stage's startTimeCode, else 0 (as ``load_scene`` reads it)."""
    return float(stage.GetStartTimeCode()) if stage.HasAuthoredTimeCodeRange() else 0.0

