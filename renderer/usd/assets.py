"""The asset a prim belongs to, by USD model kinds: the name Cryptomatte's asset layer gives each instance.

A prim's asset is the nearest ancestor-or-self whose ``kind`` is ``component`` (or a kind derived from it); else
the outermost ancestor whose kind is a model kind (``assembly``, ``group``); else its top-level ancestor under the
pseudo-root (``/World`` for ``/World/a/b``). Kinds are read as authored (``Usd.ModelAPI.GetKind``), without USD's
model-hierarchy validation, so a component prototype under a PointInstancer (a gprim, which breaks the model
hierarchy) still counts. The instances of a PointInstancer take the component inside their prototype if there is
one, else the asset of the instancer itself (``within``).
"""
from __future__ import annotations

from pxr import Kind, Usd


class AssetNames:
    """Asset names of prims, with the walk up the namespace cached per prim path."""

    def __init__(self):
        # path -> (nearest component ancestor-or-self or None, outermost model ancestor-or-self or None, top path)
        self._info: dict[str, tuple[str | None, str | None, str]] = {}

    def of(self, prim: Usd.Prim) -> str:
        """The asset name of a prim (prim path of its asset, see the module docstring)."""
        component, model, top = self._walk(prim)
        return component or model or top

    def within(self, prim: Usd.Prim, root: Usd.Prim) -> str | None:
        """The nearest component ancestor-or-self of prim that is root or below it; None if there is none."""
        component = self._walk(prim)[0]
        if component is None:
            return None
        root_path = str(root.GetPath())
        return component if component == root_path or component.startswith(root_path.rstrip("/") + "/") else None

    def _walk(self, prim: Usd.Prim) -> tuple[str | None, str | None, str]:
        path = str(prim.GetPath())
        hit = self._info.get(path)
        if hit is not None:
            return hit
        parent = prim.GetParent()
        if not parent or parent.IsPseudoRoot():
            component = model = None
            top = path
        else:
            component, model, top = self._walk(parent)
        kind = Usd.ModelAPI(prim).GetKind()
        if kind:
            if Kind.Registry.IsA(kind, Kind.Tokens.component):  # the nearest one wins
                component = path
            if model is None and Kind.Registry.IsA(kind, Kind.Tokens.model):  # the outermost one wins
                model = path
        hit = self._info[path] = (component, model, top)
        return hit
