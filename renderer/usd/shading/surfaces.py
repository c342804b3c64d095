"""Surface shaders mapped onto the renderer's material model (the UsdPreviewSurface inputs of ``Material``).

Three models are read, each input a signal of the shading network (``shading_network``):

* **UsdPreviewSurface** (``UsdPreviewSurface``, MaterialX ``ND_UsdPreviewSurface_surfaceshader``): one to one.
* **Autodesk Standard Surface** (MaterialX ``ND_standard_surface_surfaceshader`` and Arnold's
  ``arnold:standard_surface``, one spec whatever the id, defaults of its MaterialX nodedef):
  diffuseColor = base * base_color, metallic = metalness, roughness = specular_roughness,
  ior = specular_IOR, clearcoat = coat, clearcoatRoughness = coat_roughness,
  emissiveColor = emission * emission_color, opacity = opacity (its first channel) * (1 - transmission),
  normal = a ``normalmap`` node's tangent-space normal.
* **OpenPBR** (``ND_open_pbr_surface_surfaceshader``): base_weight * base_color, base_metalness,
  specular_roughness, specular_ior, coat_weight / coat_roughness, emission_luminance * emission_color (as the
  MaterialX graph of open_pbr_surface multiplies them), geometry_opacity * (1 - transmission_weight),
  geometry_normal.
* **Arnold's own surfaces** (``arnold:flat``, ``lambert``, ``standard``, ``utility``): see ``arnold_nodes``.

Specular weight and colour: white (the default) is the metallic workflow with F0 from the IOR; otherwise, for a
dielectric (metalness 0), the specular workflow with specularColor = weight * colour * F0(ior). Inputs of these
models that the BSDF does not have (subsurface, sheen/fuzz, thin film, anisotropy, coloured coat or
transmission, diffuse roughness) warn once per material, naming them, when set away from their defaults.
"""
from __future__ import annotations

import numpy as np

from renderer.usd.shading import arnold_nodes
from renderer.usd.shading.network import Network
from renderer.usd.shading.nodes import node_kind, shader_id
from renderer.usd.shading.signals import Const, Tex, const

PREVIEW = "UsdPreviewSurface"
STANDARD = "standard_surface"
OPENPBR = "open_pbr_surface"
ARNOLD = "arnold"  # Arnold's own surfaces (flat, lambert, standard, utility): ``arnold_nodes``

# UsdPreviewSurface spec defaults
PREVIEW_DEFAULTS = {
    "diffuseColor": (0.18, 0.18, 0.18), "emissiveColor": (0.0, 0.0, 0.0), "useSpecularWorkflow": 0,
    "specularColor": (0.0, 0.0, 0.0), "metallic": 0.0, "roughness": 0.5, "clearcoat": 0.0,
    "clearcoatRoughness": 0.01, "opacity": 1.0, "opacityThreshold": 0.0, "ior": 1.5, "normal": (0.0, 0.0, 1.0),
    "occlusion": 1.0,
}

# Inputs each model has beyond our BSDF, with their defaults (a warning when set otherwise).
_UNRENDERED = {
    STANDARD: {"diffuse_roughness": 0.0, "specular_anisotropy": 0.0, "transmission_color": (1.0, 1.0, 1.0),
               "transmission_depth": 0.0, "transmission_scatter": (0.0, 0.0, 0.0), "subsurface": 0.0,
               "sheen": 0.0, "coat_color": (1.0, 1.0, 1.0), "thin_film_thickness": 0.0},
    OPENPBR: {"base_diffuse_roughness": 0.0, "specular_roughness_anisotropy": 0.0,
              "transmission_color": (1.0, 1.0, 1.0), "transmission_depth": 0.0,
              "transmission_scatter": (0.0, 0.0, 0.0), "subsurface_weight": 0.0, "fuzz_weight": 0.0,
              "coat_color": (1.0, 1.0, 1.0), "thin_film_weight": 0.0},
}

# Per model: our input <- (its inputs with defaults)
_NAMES = {
    STANDARD: dict(base=("base", 0.8), base_color=("base_color", (1.0, 1.0, 1.0)), metal=("metalness", 0.0),
                   spec=("specular", 1.0), spec_color=("specular_color", (1.0, 1.0, 1.0)),
                   rough=("specular_roughness", 0.2), ior=("specular_IOR", 1.5), coat=("coat", 0.0),
                   coat_rough=("coat_roughness", 0.1), emission=("emission", 0.0),
                   emission_color=("emission_color", (1.0, 1.0, 1.0)), opacity=("opacity", (1.0, 1.0, 1.0)),
                   transmission=("transmission", 0.0), normal="normal"),
    OPENPBR: dict(base=("base_weight", 1.0), base_color=("base_color", (0.8, 0.8, 0.8)),
                  metal=("base_metalness", 0.0), spec=("specular_weight", 1.0),
                  spec_color=("specular_color", (1.0, 1.0, 1.0)), rough=("specular_roughness", 0.3),
                  ior=("specular_ior", 1.5), coat=("coat_weight", 0.0), coat_rough=("coat_roughness", 0.0),
                  emission=("emission_luminance", 0.0), emission_color=("emission_color", (1.0, 1.0, 1.0)),
                  opacity=("geometry_opacity", 1.0), transmission=("transmission_weight", 0.0),
                  normal="geometry_normal"),
}


def surface_model(sid: str) -> str | None:
    """PREVIEW, STANDARD, OPENPBR, ARNOLD or None for a surface shader id."""
    if arnold_nodes.is_surface(sid):
        return ARNOLD
    cat, _ = node_kind(sid)
    if cat == "UsdPreviewSurface":
        return PREVIEW
    if cat in ("standard_surface", "arnold:standard_surface"):
        return STANDARD
    if cat == "open_pbr_surface":
        return OPENPBR
    return None


def _mul(a, b):
    return a * b


def surface_inputs(net: Network, prim, path: str) -> dict:
    """{UsdPreviewSurface input name: signal or None (the spec default)} of a surface shader prim."""
    model = surface_model(shader_id(prim))
    if model == PREVIEW:
        return {name: net.input(prim, name) for name in PREVIEW_DEFAULTS}
    if model == ARNOLD:
        return arnold_nodes.surface_inputs(net, prim)
    names = _NAMES[model]
    sig = {k: net.input(prim, v[0], v[1]) for k, v in names.items() if k != "normal"}
    where = f"{prim.GetPath()}"
    out: dict = {}
    out["diffuseColor"] = net.apply(_mul, [sig["base"], sig["base_color"]], where)
    out["metallic"] = sig["metal"]
    out["roughness"] = sig["rough"]
    out["ior"] = sig["ior"]
    out["clearcoat"] = sig["coat"]
    out["clearcoatRoughness"] = sig["coat_rough"]
    out["emissiveColor"] = net.apply(_mul, [sig["emission"], sig["emission_color"]], where)
    opacity = sig["opacity"]
    if isinstance(opacity, Const):
        opacity = const(float(np.mean(opacity.value[:3])))
    out["opacity"] = net.apply(lambda o, t: o[..., :1] * (1.0 - t[..., :1]), [opacity, sig["transmission"]],
                               where)
    # Specular weight and colour: white -> metallic workflow; else a dielectric's specular colour.
    spec = net.apply(_mul, [sig["spec"], sig["spec_color"]], where)
    white = isinstance(spec, Const) and np.allclose(spec.value, 1.0)
    if not white:
        metal, ior = sig["metal"], sig["ior"]
        if isinstance(metal, Const) and float(metal.value[0]) == 0.0 and isinstance(ior, Const):
            n = float(ior.value[0])
            f0 = ((n - 1.0) / (n + 1.0)) ** 2
            out["useSpecularWorkflow"] = const(1.0)
            out["specularColor"] = net.apply(lambda s: s * f0, [spec], where)
        else:
            net.warn("specular weight/colour of metals or textured IORs ignored (white used)", path)
    src = net.source(prim, names["normal"])
    if src is not None:
        ncat, _ = node_kind(shader_id(src[0]))
        normal = net.input(prim, names["normal"])
        if ncat == "normalmap" and isinstance(normal, (Tex, Const)):
            out["normal"] = normal
        else:
            net.warn("surface normals not from a normalmap node ignored", f"{path} ({src[0].GetPath()})")
    odd = []
    for name, default in _UNRENDERED[model].items():
        s = net.input(prim, name, default)
        if not isinstance(s, Const) or not np.allclose(np.resize(s.value, np.size(default)), default):
            odd.append(name)
    if odd:
        net.warn(f"{model} inputs the BSDF does not have, ignored", f"{path} ({', '.join(odd)})")
    return out
