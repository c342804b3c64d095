"""Light linking and shadow linking (usdLux LightAPI ``collection:lightLink`` / ``collection:shadowLink``) and
the ShadowAPI controls, read into ``scene.Light``.

Membership is UsdCollectionAPI's own query (``ComputeMembershipQuery``: includeRoot, includes, excludes,
expansionRule, nested collections, membership expressions), asked about each instance's prim path (instance
proxies by their proxy path, PointInstancer instances by the instancer's path). A collection that includes
everything (includeRoot, the schema's fallback, with no excludes and no expression) leaves the light unlinked.

ShadowAPI: ``shadow:enable`` off casts no shadows from the light; ``shadow:color`` is what fully shadowed light
is replaced by (L (T + (1 - T) color) with T the transmittance, black by default); ``shadow:distance`` > 0 limits
the distance from the shaded point within which occluders cast shadows; ``shadow:falloff`` (at most that distance)
and ``shadow:falloffGamma`` fade shadows out over the end of it (``renderer.lights.linking``).
"""
from __future__ import annotations

import numpy as np
from pxr import Sdf, UsdLux

from renderer.scene import model as sc
from renderer.usd.reads import reads


def _everything(api) -> bool:
    if api.IsInExpressionMode():
        return False
    root = api.GetIncludeRootAttr().Get()
    return bool(root) and not api.GetExcludesRel().GetTargets()


def instance_prim_path(name: str) -> str:
    """The prim path membership is asked about for an instance named ``name`` (``/Instancer[3]/proto`` ->
    ``/Instancer``)."""
    return name.split("[", 1)[0] if "[" in name else name


def _members(api, instances: list[sc.Instance]) -> np.ndarray | None:
    if _everything(api):
        return None
    query = api.ComputeMembershipQuery()
    cache: dict[str, bool] = {}
    out = np.zeros(len(instances), bool)
    for i, inst in enumerate(instances):
        path = instance_prim_path(inst.name)
        if path not in cache:
            cache[path] = bool(path) and Sdf.Path.IsValidPathString(path) and \
                query.IsPathIncluded(Sdf.Path(path))
        out[i] = cache[path]
    return out


def _get(prim, name: str, frame: float, default):
    for n in ("inputs:" + name, name):
        a = prim.GetAttribute(n)
        if a and a.HasAuthoredValue():
            v = a.Get(frame)
            if v is not None:
                return v
    return default


@reads("LightAPI", *(f"collection:{c}{part}" for c in ("lightLink", "shadowLink")
                     for part in ("", ":includeRoot", ":expansionRule", ":membershipExpression", ":mode")))
@reads("ShadowAPI", "inputs:shadow:enable", "inputs:shadow:color", "inputs:shadow:distance", "inputs:shadow:falloff",
       "inputs:shadow:falloffGamma")
def apply_linking(light: sc.Light, prim, instances: list[sc.Instance], frame: float, warn) -> None:
    """Fill ``light``'s linking masks and shadow controls from its prim."""
    api = UsdLux.LightAPI(prim)
    light.illuminates = _members(api.GetLightLinkCollectionAPI(), instances)
    light.casts_shadow = _members(api.GetShadowLinkCollectionAPI(), instances)
    light.shadow_enable = bool(_get(prim, "shadow:enable", frame, True))
    light.shadow_color = tuple(float(x) for x in _get(prim, "shadow:color", frame, (0.0, 0.0, 0.0)))
    light.shadow_distance = float(_get(prim, "shadow:distance", frame, -1.0))
    falloff = float(_get(prim, "shadow:falloff", frame, -1.0))
    gamma = float(_get(prim, "shadow:falloffGamma", frame, 1.0))
    if falloff > 0 and light.shadow_distance > 0:  # "cannot exceed the shadow max distance"
        light.shadow_falloff = min(falloff, light.shadow_distance)
        light.shadow_falloff_gamma = gamma if gamma > 0 and gamma == gamma else 1.0
