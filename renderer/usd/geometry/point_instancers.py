"""PointInstancers: each instance of each prototype placed over the shutter (positions, orientations, scales,
velocities and accelerations per instance, ``invisibleIds``, prototypes holding meshes, implicit prims, curves,
lights and volumes).

``PointInstancing`` is a part of the importer (``renderer.usd.importer._Importer`` derives from it): its methods
read and extend the importer's state (meshes, instances, lights, the transform sampler and the warnings).
"""
from __future__ import annotations

import numpy as np
from pxr import Usd, UsdGeom

from renderer.usd.geometry import curves as usd_curves
from renderer.usd.lights import lux as usd_lights
from renderer.usd.geometry import volumes as usd_volumes
from renderer.usd.motion import refine_keys, samples_in_shutter, shutter_interval
from renderer.usd.geometry.primitives import PRIMITIVE_TYPES
from renderer.usd.reads import reads

_PI_ATTRS = ("positions", "orientations", "orientationsf", "scales", "velocities", "angularVelocities",
             "accelerations", "protoIndices")


class PointInstancing:
    """The importer's PointInstancer expansion."""

    def _point_instancer(self, prim, interval) -> None:
        times = self._pi_key_times(prim)
        meshes, names, rows, assets = self._pi_placements(prim, times)
        if not meshes:
            return
        if len(times) > 1:
            times, rows = refine_keys(lambda ts: self._pi_placements(prim, ts)[2], times)
        is_light = np.asarray(meshes) < 0
        self._proto_light_prims = [p for _, p in sorted(self._proto_lights.values(), key=lambda ip: ip[0])]
        for j in np.nonzero(is_light)[0]:  # one light per instance of a light in a prototype
            light = usd_lights.read_light(self._proto_light_prims[-meshes[j] - 1], self.xf, self.warn,
                                          placement=(times, rows[j]), name=names[j], colors=self.colors)
            if light is not None:
                self.lights.append(light)
                self._light_prims.append((light, self._proto_light_prims[-meshes[j] - 1]))
        keep = np.nonzero(~is_light)[0]
        if len(keep):
            first = len(self.instances)
            own = self.assets.of(prim)  # the asset of placements whose prototype holds no component
            self._add_instances([meshes[j] for j in keep], [names[j] for j in keep], times, rows[keep], interval,
                                [assets[j] or own for j in keep])
            emitters: dict = {}  # MeshLightAPI prim path -> (prim, its placements' instance indices)
            for i in range(first, len(self.instances)):
                light_prim = self._placement_mesh_lights.get(self.instances[i].name)
                if light_prim is not None:
                    emitters.setdefault(str(light_prim.GetPath()), (light_prim, []))[1].append(i)
            self._mesh_lights += list(emitters.values())

    def _pi_key_times(self, prim) -> np.ndarray:
        sh = self.shutter
        if sh.static:
            return np.array([self.frame])
        moving, samples = self.xf.chain(prim)
        samples = list(samples)
        curved = False
        for name in _PI_ATTRS:
            a = prim.GetAttribute(name)
            if not a or not a.HasAuthoredValue():
                continue
            if name in ("velocities", "angularVelocities", "accelerations"):
                moving = True
                curved = curved or name != "velocities"
            if a.ValueMightBeTimeVarying():
                moving = True
                samples += samples_in_shutter(sh, a)
        for target in UsdGeom.PointInstancer(prim).GetPrototypesRel().GetForwardedTargets():
            proto = self.stage.GetPrimAtPath(target)
            if not proto:
                continue
            for p in Usd.PrimRange(proto, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)):
                xf = UsdGeom.Xformable(p)
                if xf and xf.TransformMightBeTimeVarying():
                    moving = True
                    samples += sh.inner(xf.GetTimeSamplesInInterval(shutter_interval(sh)))
        if not moving:
            return np.array([self.frame])
        keys = sh.keys(samples)
        return np.union1d(keys, sh.uniform(5)) if curved else keys

    @reads("PointInstancer", "positions", "orientations", "orientationsf", "scales", "velocities",
           "angularVelocities", "accelerations", "protoIndices", "ids", "invisibleIds")  # ids: the mask
    def _pi_placements(self, prim, times) -> tuple[list[int], list[str], np.ndarray, list[str | None]]:
        """(mesh per placement, names, row-vector world matrices (M, K, 4, 4), assets) of every instance's geometry;
        an asset is the component inside the prototype (``AssetNames.within``), None where there is none."""
        pi = UsdGeom.PointInstancer(prim)
        path = str(prim.GetPath())
        frame = self.frame
        targets = pi.GetPrototypesRel().GetForwardedTargets()
        proto_idx = pi.GetProtoIndicesAttr().Get(frame)
        k = len(times)
        empty = ([], [], np.zeros((0, k, 4, 4)), [])
        if proto_idx is None or len(proto_idx) == 0 or not targets:
            return empty
        proto_idx = np.asarray(proto_idx, np.int64)
        n = len(proto_idx)
        mask = np.asarray(pi.ComputeMaskAtTime(frame) or [True] * n, bool)
        if len(mask) != n:
            mask = np.ones(n, bool)
        tcs = [Usd.TimeCode(float(t)) for t in times]
        inst = pi.ComputeInstanceTransformsAtTimes(tcs, Usd.TimeCode(frame), UsdGeom.PointInstancer.ExcludeProtoXform,
                                                   UsdGeom.PointInstancer.IgnoreMask)
        if not inst or any(len(x) != n for x in inst):
            one = pi.ComputeInstanceTransformsAtTime(Usd.TimeCode(frame), Usd.TimeCode(frame),
                                                     UsdGeom.PointInstancer.ExcludeProtoXform,
                                                     UsdGeom.PointInstancer.IgnoreMask)
            if one is None or len(one) != n:
                self.warn("PointInstancers with inconsistent positions/protoIndices skipped", path)
                return empty
            self.warn("PointInstancers whose instance transforms cannot be evaluated over the shutter are static",
                      path)
            inst = [one] * k
        inst = np.stack([np.asarray(x, np.float64).reshape(n, 4, 4) for x in inst], axis=1)  # (N, K, 4, 4)
        inst = inst @ self.xf.world(prim, times)[None]
        if np.any((proto_idx < 0) | (proto_idx >= len(targets))):
            self.warn("PointInstancer protoIndices out of range ignored", path)
        meshes: list[int] = []
        names: list[str] = []
        rows: list[np.ndarray] = []
        assets: list[str | None] = []
        for j, target in enumerate(targets):
            sel = np.nonzero((proto_idx == j) & mask)[0]
            proto = self.stage.GetPrimAtPath(target)
            if len(sel) == 0 or not proto:
                continue
            sub_meshes, sub_names, sub_rows, sub_assets = self._subtree_placements(proto, times)
            if not sub_meshes:
                continue
            parent = np.linalg.inv(self.xf.world(proto.GetParent(), times))  # (K, 4, 4)
            rel = sub_rows @ parent[None]  # (M, K, 4, 4) relative to the prototype's parent
            world = np.einsum("mkab,nkbc->nmkac", rel, inst[sel])  # (n, M, K, 4, 4)
            rows.append(world.reshape(-1, k, 4, 4))
            meshes += sub_meshes * len(sel)
            base = str(proto.GetParent().GetPath()).rstrip("/")
            rel_names = [nm[len(base):] if nm.startswith(base + "/") else "/" + nm.lstrip("/") for nm in sub_names]
            names += [f"{path}[{i}]{nm}" for i in sel for nm in rel_names]
            assets += sub_assets * len(sel)
            for nm, rel in zip(sub_names, rel_names):  # placements of MeshLightAPI prims, by their names
                if nm in self._proto_mesh_lights:
                    for i in sel:
                        self._placement_mesh_lights[f"{path}[{i}]{rel}"] = self._proto_mesh_lights[nm]
        if not rows:
            return empty
        return meshes, names, np.concatenate(rows), assets

    def _subtree_placements(self, root, times) -> tuple[list[int], list[str], np.ndarray, list[str | None]]:
        """Geometry under a prototype root (visibility and purpose at the frame, nested instancers expanded)."""
        self._in_prototype += 1
        try:
            return self._subtree_placements_in(root, times)
        finally:
            self._in_prototype -= 1

    def _subtree_placements_in(self, root, times) -> tuple[list[int], list[str], np.ndarray, list[str | None]]:
        meshes: list[int] = []
        names: list[str] = []
        rows: list[np.ndarray] = []
        assets: list[str | None] = []
        it = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
        for prim in it:
            img = UsdGeom.Imageable(prim)
            if not img:
                continue
            vis = img.GetVisibilityAttr()
            if vis and vis.HasAuthoredValue() and vis.Get(self.frame) == UsdGeom.Tokens.invisible:
                it.PruneChildren()
                continue
            purpose = img.GetPurposeAttr().Get()
            if not self._may_draw(str(purpose)):
                it.PruneChildren()
                continue
            if purpose == UsdGeom.Tokens.proxy and self._saw_render and self._included is None:
                it.PruneChildren()
                continue
            if prim.IsA(UsdGeom.PointInstancer):
                it.PruneChildren()
                m, nm, r, a = self._pi_placements(prim, times)
                meshes += m
                names += nm
                rows.append(r)
                inner = self.assets.within(prim, root)
                assets += [x if x is not None else inner for x in a]
            elif prim.IsA(UsdGeom.Mesh) or prim.GetTypeName() in PRIMITIVE_TYPES or usd_curves.handles(prim):
                it.PruneChildren()
                mesh = self._mesh_index(prim)
                if usd_lights.is_light(prim):  # each placement becomes a mesh light (see _point_instancer)
                    self._proto_mesh_lights[str(prim.GetPath())] = prim
                else:
                    usd_lights.warn_shaping_without_light(prim, self.warn)
                if mesh is not None:
                    meshes.append(mesh)
                    names.append(str(prim.GetPath()))
                    rows.append(self.xf.world(prim, times)[None])
                    assets.append(self.assets.within(prim, root))
            elif usd_volumes.is_volume(prim):
                it.PruneChildren()
                self.warn("volumes inside PointInstancer prototypes skipped", str(prim.GetPath()))
            elif usd_lights.is_light(prim):  # placed like geometry, told apart by a negative index
                key = str(prim.GetPath())
                if key not in self._proto_lights:
                    self._proto_lights[key] = (len(self._proto_lights), prim)
                meshes.append(-1 - self._proto_lights[key][0])
                names.append(str(prim.GetPath()))
                rows.append(self.xf.world(prim, times)[None])
                assets.append(None)
        if not meshes:
            return [], [], np.zeros((0, len(times), 4, 4)), []
        return meshes, names, np.concatenate(rows), assets
