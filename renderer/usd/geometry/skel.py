"""UsdSkel skinning through usd-core's own API: skinned points (blend shapes, then linear or dual-quaternion
skinning, as ``UsdSkel.SkinningQuery`` computes them) and rigidly skinned transforms, at every key time inside
the shutter, so skinned characters motion-blur.

Skinned points are in the skeleton's space (UsdSkel): the geometry is placed by the *Skeleton*'s
local-to-world transform, not its own. Keys: the shutter ends, every joint-animation, blend-shape-weight, points
and skinning-primvar sample inside it, and ``CURVE_KEYS`` evenly spaced times when the skeleton moves (joint
rotations are slerped by UsdSkel, so points travel on arcs between samples).

Bindings come from the outermost SkelRoot above a gprim with native instances traversed as instance proxies, so
an instanced character asset (itself a SkelRoot) below an agent's SkelRoot is skinned by that agent's Skeleton,
and each instance of a prototype by its own (``Skinning.binding``).

A mesh's own ``skel:joints`` (any order, even the skeleton's) makes UsdSkel give it a joint mapper, which the
normals use too. What UsdSkel cannot do degrades alone, with one warning each: blend shapes it cannot apply are
left out, authored normals it cannot skin give way to the renderer's own; only when the points themselves cannot
be skinned is the mesh drawn as authored (never dropped).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pxr import Tf, Usd, UsdGeom, UsdSkel, Vt

from renderer.motion.shutter import Shutter
from renderer.usd.motion import shutter_interval
from renderer.usd.reads import reads

CURVE_KEYS = 5


@dataclass
class SkinBinding:
    query: UsdSkel.SkinningQuery
    skel_query: UsdSkel.SkelQuery
    skeleton: Usd.Prim


@reads("SkelRoot")
@reads("Skeleton", "joints", "bindTransforms", "restTransforms")
@reads("SkelAnimation", "joints", "translations", "rotations", "scales", "blendShapes", "blendShapeWeights")
@reads("BlendShape", "offsets", "pointIndices")
@reads("SkelBindingAPI", "skel:joints", "skel:blendShapes", "primvars:skel:jointIndices", "primvars:skel:jointWeights",
       "primvars:skel:geomBindTransform", "primvars:skel:skinningMethod")
class Skinning:
    """Finds the skinning of gprims below SkelRoots (one UsdSkel.Cache for the stage) and evaluates it."""

    def __init__(self, shutter: Shutter, warn):
        self.shutter = shutter
        self.warn = warn
        self.cache = UsdSkel.Cache()
        self._roots: set[str] = set()
        self._targets: dict[str, SkinBinding] = {}
        self._invalid: dict[str, str] = {}  # target path -> the Skeleton whose joints UsdSkel cannot read

    def binding(self, prim) -> SkinBinding | None:
        """The skinning of a prim, or None if it is not skinned (no SkelRoot above it, no joint influences).

        Bindings are computed from the *outermost* SkelRoot above the prim, as ``UsdSkel.BakeSkinning`` does: a
        character asset whose root prim is a SkelRoot, referenced below an agent's SkelRoot (a crowd agent's
        instanceable ``geometry``), is a nested SkelRoot with no binding of its own; its meshes inherit the agent's
        ``skel:skeleton``. Instance proxies are traversed, so every instance of a prototype is skinned by the
        Skeleton above it. A prim with joint influences or blend shapes that no Skeleton skins is named in one
        warning (it is drawn as authored)."""
        root = outermost_root(prim)
        if root is None:
            self._unskinned(prim, "no SkelRoot above it")
            return None
        key = str(root.GetPath())
        if key not in self._roots:
            self._roots.add(key)
            predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
            self.cache.Populate(root, predicate)
            for b in self.cache.ComputeSkelBindings(root, predicate):
                skel = b.GetSkeleton()
                skel_query = self.cache.GetSkelQuery(skel)
                for q in b.GetSkinningTargets():
                    if skel_query:
                        self._targets[str(q.GetPrim().GetPath())] = SkinBinding(q, skel_query, skel.GetPrim())
                    else:
                        self._invalid[str(q.GetPrim().GetPath())] = str(skel.GetPath())
        path = str(prim.GetPath())
        found = self._targets.get(path)
        if found is None:
            skel = self._invalid.get(path)
            self._unskinned(prim, f"Skeleton {skel} unreadable" if skel else "no Skeleton bound")
        return found

    def _unskinned(self, prim, reason: str) -> None:
        """One warning naming a prim that authors skinning (joint influences, blend shapes) nothing skins."""
        if any(_authored(prim, name) for name in ("primvars:skel:jointIndices", "skel:blendShapes")):
            self.warn("prims with skinning data that no Skeleton skins drawn as authored",
                      f"{prim.GetPath()} ({reason})")

    def key_times(self, prim, b: SkinBinding) -> np.ndarray:
        sh = self.shutter
        if sh.static:
            return np.array([sh.frame])
        iv = shutter_interval(sh)
        samples: list[float] = []
        anim = b.skel_query.GetAnimQuery()
        if anim:
            samples += list(anim.GetJointTransformTimeSamplesInInterval(iv))
            samples += list(anim.GetBlendShapeWeightTimeSamplesInInterval(iv))
        samples += list(b.query.GetTimeSamplesInInterval(iv))
        pb = UsdGeom.PointBased(prim)
        if pb:
            samples += list(pb.GetPointsAttr().GetTimeSamplesInInterval(iv))
        moving = anim and (anim.JointTransformsMightBeTimeVarying() or len(samples) > 0)
        keys = sh.keys(samples)
        return np.union1d(keys, sh.uniform(CURVE_KEYS)) if moving else np.array([sh.frame])

    def skinned_points(self, prim, b: SkinBinding, times: np.ndarray) -> np.ndarray | None:
        """(P, V, 3) float32 skinned points (skeleton space) at absolute times; None if UsdSkel cannot skin it.
        Blend shapes UsdSkel cannot apply are left out (one warning), the points still skinned."""
        blend = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim)) if b.query.HasBlendShapes() else None
        if blend is not None:
            try:
                return self._skinned_points(prim, b, times, blend)
            except (Tf.ErrorException, ValueError, TypeError, ArithmeticError):
                self.warn("blend shapes that UsdSkel could not apply ignored", str(prim.GetPath()))
        return self._skinned_points(prim, b, times, None)

    def _skinned_points(self, prim, b: SkinBinding, times: np.ndarray, blend) -> np.ndarray | None:
        attr = UsdGeom.PointBased(prim).GetPointsAttr()
        base = attr.Get(self.shutter.frame)
        if base is None:
            return None
        out = []
        for t in times:
            pts = attr.Get(float(t))
            if pts is None or len(pts) != len(base):
                pts = Vt.Vec3fArray(base)
            if blend is not None:
                pts = self._blend(prim, b, blend, pts, float(t))
            xforms = b.skel_query.ComputeSkinningTransforms(float(t))
            if xforms is None or not b.query.ComputeSkinnedPoints(xforms, pts, float(t)):
                return None
            out.append(np.asarray(pts, np.float32).reshape(-1, 3))
        return np.stack(out)

    def _blend(self, prim, b: SkinBinding, blend, pts, t: float):
        anim = b.skel_query.GetAnimQuery()
        weights = anim.ComputeBlendShapeWeights(t) if anim else None
        if weights is None:
            return pts
        mapper = b.query.GetBlendShapeMapper()
        if mapper is not None and not mapper.IsNull():
            weights = mapper.Remap(weights)
        sub_w, bs_idx, sub_idx = blend.ComputeSubShapeWeights(weights)
        point_idx = blend.ComputeBlendShapePointIndices()
        offsets = blend.ComputeSubShapePointOffsets()
        if not blend.ComputeDeformedPoints(sub_w, bs_idx, sub_idx, point_idx, offsets, pts):
            self.warn("blend shapes that UsdSkel could not apply ignored", str(prim.GetPath()))
        return pts

    def normal_matrices(self, prim, b: SkinBinding, t: float) -> np.ndarray | None:
        """(V, 3, 3) row-vector matrices carrying each point's authored normal to its skinned normal at time t
        (n' = n @ N, the inverse transpose of the point's linear-blend linear part), or None if not computable.
        Dual-quaternion bindings get the same linear-blend normals (close for the rotations they blend)."""
        xforms = b.skel_query.ComputeSkinningTransforms(float(t))
        influences = b.query.ComputeJointInfluences(float(t))
        if xforms is None or not influences:
            return None
        mapper = b.query.GetJointMapper()  # set by any authored skel:joints, even in the skeleton's own order
        if mapper is not None and not mapper.IsNull() and not mapper.IsIdentity():
            # usd-core's binding is RemapTransforms(source, target, elementSize=1), returning the remapped array
            xforms = mapper.RemapTransforms(xforms, Vt.Matrix4dArray(), 1)
        x = np.asarray(xforms, np.float64).reshape(-1, 4, 4)[:, :3, :3]
        idx = np.asarray(influences[0], np.int64)
        w = np.asarray(influences[1], np.float64)
        k = b.query.GetNumInfluencesPerComponent()
        n = len(UsdGeom.PointBased(prim).GetPointsAttr().Get(self.shutter.frame) or [])
        if k < 1 or len(idx) != len(w) or len(x) == 0 or idx.min(initial=0) < 0 or idx.max(initial=0) >= len(x):
            return None
        idx, w = idx.reshape(-1, k), w.reshape(-1, k)
        if len(idx) == 1:  # constant interpolation: one set of influences for every point
            idx, w = np.repeat(idx, n, axis=0), np.repeat(w, n, axis=0)
        if len(idx) != n:
            return None
        bind = np.asarray(b.query.GetGeomBindTransform(float(t)), np.float64)[:3, :3]
        lin = bind[None] @ np.einsum("pk,pkij->pij", w, x[idx])  # p' = p @ lin for the linear part
        det = np.linalg.det(lin)
        safe = np.abs(det) > 1e-12
        inv = np.linalg.inv(np.where(safe[:, None, None], lin, np.eye(3)))
        return np.swapaxes(inv, 1, 2)

    def skinned_transforms(self, b: SkinBinding, times: np.ndarray) -> np.ndarray | None:
        """(K, 4, 4) row-vector object-to-skeleton transforms of a rigidly skinned prim, or None."""
        out = []
        for t in times:
            xforms = b.skel_query.ComputeSkinningTransforms(float(t))
            if xforms is None:
                return None
            m = b.query.ComputeSkinnedTransform(xforms, float(t))
            if m is None:
                return None
            out.append(np.array(m, np.float64))
        return np.stack(out)


def outermost_root(prim) -> UsdSkel.Root | None:
    """The outermost SkelRoot at or above a prim (instance proxies included), or None."""
    root = UsdSkel.Root.Find(prim)
    if not root:
        return None
    while True:
        outer = UsdSkel.Root.Find(root.GetPrim().GetParent())
        if not outer:
            return root
        root = outer


def _authored(prim, name: str) -> bool:
    # HasAttribute first: half the cost of GetAttribute on the many prims that have no skinning at all
    return prim.HasAttribute(name) and prim.GetAttribute(name).HasAuthoredValue()
