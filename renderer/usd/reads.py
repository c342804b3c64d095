"""What the importer reads of each USD schema, and one warning for every schema attribute it leaves unread.

Each reader declares the schema attributes it consumes next to the code that reads them, by schema type name
(the concrete or API schema that defines them, or one they derive from):

    @reads("Camera", "focalLength", "horizontalAperture", ...)
    def read_camera(...): ...

(``reads(...)`` also works as a plain call). What a prim's readers consume is the union of the declarations for
its type and the types it derives from (a Mesh: Mesh, PointBased, Gprim, Boundable, Xformable, Imageable) and
for the API schemas applied to it (authored or built in: a RectLight has LightAPI). A declaration with no names
says the importer handles prims of that type.

After import, ``report_unread`` walks the stage (each instance prototype once) and, for the schemas we claim
(``CLAIMED``: UsdGeom, UsdLux, UsdShade, UsdSkel, UsdRender, UsdVol), names in one warning per (attribute, prim
type) every authored attribute that the prim's schemas define (``Usd.SchemaRegistry``'s prim definitions) and no
reader declared, unless its value is the schema's fallback (then there is nothing to ignore). User primvars,
custom and renderer attributes (``primvars:arnold:*``) belong to no schema and are not checked. Prims of a claimed
type that no reader handles are named once per type, except those the importer already skipped with a warning of
its own (``skipped``).
"""
from __future__ import annotations

from pxr import Plug, Usd

CLAIMED = ("usdGeom", "usdLux", "usdShade", "usdSkel", "usdRender", "usdVol")

_READS: dict[str, set[str]] = {}


def reads(schema: str, *names: str):
    """Declare that the importer consumes attributes ``names`` of schema type ``schema``; usable as a decorator
    on the function that reads them (it is returned unchanged)."""
    _READS.setdefault(schema, set()).update(names)

    def mark(fn):
        return fn
    return mark


def consumed(schema: str) -> frozenset[str]:
    """The attribute names declared for one schema type name (for tests and tools)."""
    return frozenset(_READS.get(schema, ()))


def _plugin(tf_type) -> str | None:
    plug = Plug.Registry().GetPluginForType(tf_type) if tf_type and not tf_type.isUnknown else None
    return plug.name if plug is not None else None


def _attributes(definition, instance: str = "") -> set[str]:
    if definition is None:
        return set()
    names = [n for n in definition.GetPropertyNames() if definition.GetAttributeDefinition(n)]
    return {n.replace("__INSTANCE_NAME__", instance) for n in names} if instance else set(names)


class _Schemas:
    """For one (type name, applied schemas): the attributes the claimed schemas define, those the readers consume,
    and whether a reader handles the type."""

    def __init__(self, type_name: str, applied: tuple[str, ...]):
        reg = Usd.SchemaRegistry()
        self.claimed: set[str] = set()
        names: list[str] = []
        self.handled = True
        self.type_claimed = False
        if type_name:
            t = Usd.SchemaRegistry.GetTypeFromSchemaTypeName(type_name)
            if _plugin(t) in CLAIMED:
                self.type_claimed = True
                self.claimed |= _attributes(reg.FindConcretePrimDefinition(type_name))
                names += [Usd.SchemaRegistry.GetSchemaTypeName(a) for a in t.GetAllAncestorTypes()]
                self.handled = type_name in _READS
        for schema in applied:
            api, instance = Usd.SchemaRegistry.GetTypeNameAndInstance(schema)
            names.append(str(api))
            if _plugin(Usd.SchemaRegistry.GetTypeFromSchemaTypeName(api)) in CLAIMED:
                self.claimed |= _attributes(reg.FindAppliedAPIPrimDefinition(api), instance)
        self.consumed: set[str] = set().union(*(_READS.get(n, set()) for n in names)) if names else set()


def _prims(stage: Usd.Stage):
    """(prim, the path to name it by): the stage's prims, and each instance prototype's once (named under its
    first instance)."""
    for prim in Usd.PrimRange.Stage(stage, Usd.PrimDefaultPredicate):
        yield prim, str(prim.GetPath())
    for proto in stage.GetPrototypes():
        instances = proto.GetInstances()
        base = str(instances[0].GetPath()) if instances else str(proto.GetPath())
        root = str(proto.GetPath())
        for prim in Usd.PrimRange(proto, Usd.PrimDefaultPredicate):
            yield prim, base + str(prim.GetPath())[len(root):]


def report_unread(stage: Usd.Stage, warn, skipped: set[str] = frozenset()) -> None:
    """One warning per (attribute, prim type) naming authored attributes of claimed schemas that no reader
    consumes, and one per claimed type no reader handles; prims under ``skipped`` paths (already named by the
    importer) are left out."""
    cache: dict[tuple, _Schemas] = {}
    for prim, path in _prims(stage):
        if skipped and any(path == s or path.startswith(s + "/") for s in skipped):
            continue
        type_name = str(prim.GetTypeName())
        key = (type_name, tuple(prim.GetAppliedSchemas()))
        info = cache.get(key)
        if info is None:
            info = cache[key] = _Schemas(*key)
        if not info.claimed and not info.type_claimed:
            continue
        if not info.handled:
            warn("prims of types the importer does not read ignored", f"{path} ({type_name})")
            continue
        for attr in prim.GetAuthoredAttributes():
            name = attr.GetName()
            if name in info.claimed and name not in info.consumed and not _is_fallback(prim, attr):
                warn(f"{type_name or 'untyped prim'} attribute {name} not read: ignored", path)


MAX_SAMPLES_COMPARED = 64


def _is_fallback(prim, attr) -> bool:
    """Whether an authored attribute says nothing its schema's fallback does not (its default and every time
    sample equal the fallback, e.g. an empty ``clippingPlanes``): ignoring it changes nothing."""
    fallback = prim.GetPrimDefinition().GetAttributeFallbackValue(attr.GetName())
    if fallback is None:
        return False
    samples = attr.GetTimeSamples()
    if len(samples) > MAX_SAMPLES_COMPARED:
        return False
    values = [attr.Get(t) for t in samples] if samples else [attr.Get(Usd.TimeCode.Default())]
    try:
        return all(v is not None and bool(v == fallback) for v in values)
    except (TypeError, ValueError):
        return False


__all__ = ["CLAIMED", "reads", "consumed", "report_unread"]
