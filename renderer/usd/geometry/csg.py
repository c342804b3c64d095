"""Reading CSG groups: the ``drt:csg:operation`` schema (an extension; no USD schema describes CSG).

On any prim (typically an Xform)::

    uniform token drt:csg:operation = "difference"   # or "union", "intersection"

makes a group of its **children**: each direct child subtree is one operand (its closed meshes and implicit
primitives together), in child order; ``difference`` keeps what is inside the first operand and outside all
the others, ``intersection`` what is inside every operand, ``union`` what is inside any. Operands move, deform
and are instanced as usual (the result is motion-blurred by ``renderer/accel/csg``); each keeps its own
material, so the carved faces show the material of the operand that carved them. Operands should be closed
meshes (a warning names the ones that are not). Groups do not nest (an inner group is read as a plain operand
of the outer one, with a warning), and PointInstancer prototypes are not operands.
"""
from __future__ import annotations

from pxr import Sdf

from renderer.scene.mesh_facts import is_closed

ATTRIBUTE = "drt:csg:operation"
OPERATIONS = ("union", "intersection", "difference")
MAX_OPERANDS = 30  # operand states are bits of an int32 in the traversal


class CsgGroups:
    """Collects groups while the stage is walked and marks the instances of their operands."""

    def __init__(self, warn):
        self.warn = warn
        self.operations: list[str] = []
        self._roots: dict[Sdf.Path, int] = {}  # root prim path -> group
        self._children: dict[Sdf.Path, list[Sdf.Path]] = {}
        self._members: list[tuple[int, int, int, str]] = []  # (instance, group, operand, prim path)

    def visit(self, prim) -> None:
        """Register prim as a group root if it names an operation."""
        attr = prim.GetAttribute(ATTRIBUTE)
        if not attr or not attr.HasAuthoredValue():
            return
        path = str(prim.GetPath())
        op = str(attr.Get())
        if op not in OPERATIONS:
            self.warn(f"{ATTRIBUTE} must be one of {', '.join(OPERATIONS)}; the children render as plain geometry",
                      f"{path} ({op!r})")
            return
        if self._group_of(prim.GetPath()) is not None:
            self.warn("nested CSG groups are read as plain operands of the outer group", path)
            return
        children = [c.GetPath() for c in prim.GetChildren()]
        if len(children) > MAX_OPERANDS:
            self.warn(f"CSG groups of more than {MAX_OPERANDS} operands render as plain geometry", path)
            return
        self._roots[prim.GetPath()] = len(self.operations)
        self._children[prim.GetPath()] = children
        self.operations.append(op)

    def _group_of(self, path: Sdf.Path):
        """(group, operand) of a prim below a group root, or None."""
        if not self._roots:
            return None
        child = path
        parent = path.GetParentPath()
        while not parent.isEmpty and parent != Sdf.Path.absoluteRootPath:
            g = self._roots.get(parent)
            if g is not None:
                return g, self._children[parent].index(child)
            child, parent = parent, parent.GetParentPath()
        return None

    def place(self, prim, instances) -> None:
        """The instances just made for a gprim: members of a group if the prim is below a root."""
        hit = self._group_of(prim.GetPath())
        if hit is not None:
            for i in instances:
                self._members.append((i, hit[0], hit[1], str(prim.GetPath())))

    def finish(self, instances, meshes) -> list[str]:
        """Mark member instances (``csg_group``, ``csg_operand``); returns the group operations."""
        closed: dict[int, bool] = {}
        for i, g, operand, path in self._members:
            inst = instances[i]
            m = inst.mesh
            if m not in closed:
                mesh = meshes[m].realize()  # CSG walks classify triangles: an exact shape's stand-in won't do
                closed[m] = bool(is_closed(mesh.triangles, mesh.points[0]))
            if not closed[m]:
                self.warn("CSG operands that are not closed meshes (inside/outside is ill-defined)", path)
            inst.csg_group = g
            inst.csg_operand = operand
        return list(self.operations)
