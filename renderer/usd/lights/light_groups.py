"""Light groups: the label a light's (or an emissive prim's) light path events carry.

A light's group is the first of these attributes authored on its prim with a non-empty string (the renderers'
own spellings, so that a shot exported for any of them keeps its groups), else the light prim's name:

    karma:light:lpetag     Karma
    ri:light:lightGroup    RenderMan
    primvars:arnold:aov    Arnold

Emissive geometry (a prim whose material emits, without MeshLightAPI) joins a group only where its prim authors
one of the attributes; else its events carry no label. ``C.*<L.'key'>`` is then the light group ``key`` (and
``C.*<O.'key'>`` the emissive geometry of that group).
"""
from __future__ import annotations

from pxr import Sdf

GROUP_ATTRIBUTES = ("karma:light:lpetag", "ri:light:lightGroup", "primvars:arnold:aov")


def authored_group(prim) -> str | None:
    """The group a prim's attributes name, or None."""
    if not prim or not prim.IsValid():
        return None
    for name in GROUP_ATTRIBUTES:
        attr = prim.GetAttribute(name)
        if attr and attr.HasAuthoredValue():
            v = attr.Get()
            if isinstance(v, str) and v.strip():
                return v.strip()
    return None


def _prim(stage, name: str):
    if not name or not Sdf.Path.IsValidPathString(name):
        return None
    path = Sdf.Path(name)
    return stage.GetPrimAtPath(path) if path.IsAbsolutePath() and path.IsPrimPath() else None


def assign_light_groups(stage, lights) -> None:
    """Set ``group`` of every light (``renderer.scene.model.Light``, ``name`` its prim path)."""
    for light in lights:
        prim = _prim(stage, light.name)
        group = authored_group(prim)
        if group is None and not light.emissive_object:
            group = prim.GetName() if prim else light.name.rsplit("/", 1)[-1]
        light.group = group or ""
