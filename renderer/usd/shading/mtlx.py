"""MaterialX documents referenced from USD (``references = @look.mtlx@</MaterialX>``).

usd-core ships without the UsdMtlx file-format plugin, so such a reference composes nothing. ``compose_mtlx``
finds them, reads each document with the ``MaterialX`` package (its standard libraries give every node its
nodedef id) and translates it the way UsdMtlx does into an anonymous USD layer, which the stage's session layer
then references in place of the file (the scene's own layers are not edited):

* ``/MaterialX/Materials/<material>``: a Material whose ``outputs:mtlx:surface`` connects to its surface
  shader, a Shader with ``info:id`` = the nodedef (``ND_standard_surface_surfaceshader``, ...);
* every node graph the material uses, as a NodeGraph inside it (interface inputs and outputs connected), and
  free nodes as Shaders beside the surface shader;
* input values typed as in USD, ``filename`` values made absolute against the document's folder (and its
  ``fileprefix``), ``colorspace`` as the attribute's colorSpace metadata.

Without the MaterialX package a warning names the file and the reference stays empty (grey fallback).
"""
from __future__ import annotations

import os

from pxr import Ar, Sdf, Usd

try:
    import MaterialX as mx
except ImportError:  # optional: the looks fall back to grey with a warning
    mx = None

_SDF_TYPES = {"float": "Float", "color3": "Color3f", "color4": "Color4f", "vector2": "Float2", "vector3": "Float3",
              "vector4": "Float4", "integer": "Int", "boolean": "Bool", "string": "String", "filename": "Asset",
              "surfaceshader": "Token", "displacementshader": "Token", "volumeshader": "Token",
              "matrix33": "Matrix3d", "matrix44": "Matrix4d"}


def _mtlx_references(stage: Usd.Stage):
    """(prim, resolved .mtlx path, referenced prim path) for every reference to a .mtlx document."""
    for prim in stage.TraverseAll():
        for spec in prim.GetPrimStack():
            refs = spec.referenceList
            for ref in list(refs.explicitItems) + list(refs.prependedItems) + list(refs.appendedItems):
                path = ref.assetPath
                if not path or not path.lower().endswith(".mtlx"):
                    continue
                resolved = str(Ar.GetResolver().Resolve(spec.layer.ComputeAbsolutePath(path)) or "")
                yield prim, resolved or spec.layer.ComputeAbsolutePath(path), ref.primPath


def compose_mtlx(stage: Usd.Stage, warn) -> list[Sdf.Layer]:
    """Reference translated MaterialX documents from the session layer; returns the layers (keep them alive)."""
    layers: list[Sdf.Layer] = []
    if not any(str(dep).lower().endswith(".mtlx") for layer in stage.GetUsedLayers()
               for dep in layer.GetCompositionAssetDependencies()):
        return layers  # the usual case: no prim walk at all
    done: dict[str, Sdf.Layer | None] = {}
    for prim, path, prim_path in list(_mtlx_references(stage)):
        if path not in done:
            done[path] = _translate(path, warn)
        layer = done[path]
        if layer is None:
            continue
        layers.append(layer)
        target = prim_path if not prim_path.isEmpty else Sdf.Path("/MaterialX")
        with Usd.EditContext(stage, stage.GetSessionLayer()):
            prim.GetReferences().AddReference(layer.identifier, target)
    return layers


def _translate(path: str, warn) -> Sdf.Layer | None:
    if mx is None:
        warn("MaterialX documents need the MaterialX package (pip install MaterialX): looks left grey", path)
        return None
    try:
        doc = mx.createDocument()
        mx.readFromXmlFile(doc, path)
        lib = mx.createDocument()
        mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
        doc.importLibrary(lib)
    except Exception as e:  # noqa: BLE001 - MaterialX raises its own exception types
        warn("MaterialX documents that cannot be read: looks left grey", f"{path} ({' '.join(str(e).split())[:120]})")
        return None
    layer = Sdf.Layer.CreateAnonymous(os.path.basename(path) + ".usda")
    stage = Usd.Stage.Open(layer)
    stage.DefinePrim("/MaterialX", "Scope")
    stage.DefinePrim("/MaterialX/Materials", "Scope")
    folder = os.path.dirname(path)
    for mat in doc.getMaterialNodes():
        mpath = Sdf.Path("/MaterialX/Materials").AppendChild(mat.getName())
        stage.DefinePrim(mpath, "Material")
        graphs: set[str] = set()
        for inp in mat.getInputs():
            shader = inp.getConnectedNode()
            if shader is None or inp.getType() != "surfaceshader":
                continue
            for node, parent in _upstream(shader, doc):
                if parent is not None:
                    graphs.add(parent.getName())
                elif node.getName() != mat.getName():
                    _node(stage, mpath, node, folder, warn, path)
            out = stage.GetPrimAtPath(mpath).CreateAttribute("outputs:mtlx:surface", Sdf.ValueTypeNames.Token)
            out.AddConnection(mpath.AppendChild(shader.getName()).AppendProperty("outputs:out"))
        for name in graphs:
            _graph(stage, mpath, doc.getNodeGraph(name), folder, warn, path)
    return layer


def _upstream(node, doc):
    """(node, its node graph or None) of a node and everything it reads, top-level nodes and graphs."""
    seen, stack, out = set(), [node], []
    while stack:
        n = stack.pop()
        if n.getName() in seen:
            continue
        seen.add(n.getName())
        out.append((n, None))
        for inp in n.getInputs():
            if inp.getNodeGraphString():
                g = doc.getNodeGraph(inp.getNodeGraphString())
                if g is not None:
                    out.append((g, g))
            elif inp.getNodeName():
                up = doc.getNode(inp.getNodeName())
                if up is not None:
                    stack.append(up)
    return out


def _node(stage, parent: Sdf.Path, node, folder: str, warn, path: str, graph: Sdf.Path | None = None) -> None:
    prim = stage.DefinePrim(parent.AppendChild(node.getName()), "Shader")
    nd = node.getNodeDef()
    prim.CreateAttribute("info:id", Sdf.ValueTypeNames.Token, custom=False).Set(
        nd.getName() if nd is not None else f"ND_{node.getCategory()}_{node.getType()}")
    if nd is None:
        warn("MaterialX nodes without a nodedef in the standard libraries", f"{path} ({node.getName()})")
    otype = node.getType()
    if otype == "multioutput" and nd is not None:
        for o in nd.getOutputs():
            prim.CreateAttribute(f"outputs:{o.getName()}", _sdf(o.getType()))
    else:
        prim.CreateAttribute("outputs:out", _sdf(otype))
    for inp in node.getInputs():
        attr = prim.CreateAttribute(f"inputs:{inp.getName()}", _sdf(inp.getType()))
        if inp.getNodeGraphString():
            g = stage.GetPrimAtPath(parent).GetPath() if graph is None else graph.GetParentPath()
            out = inp.getOutputString() or "out"
            attr.AddConnection(g.AppendChild(inp.getNodeGraphString()).AppendProperty(f"outputs:{out}"))
        elif inp.getNodeName():
            out = inp.getOutputString() or "out"
            attr.AddConnection(parent.AppendChild(inp.getNodeName()).AppendProperty(f"outputs:{out}"))
        elif inp.getInterfaceName() and graph is not None:
            attr.AddConnection(graph.AppendProperty(f"inputs:{inp.getInterfaceName()}"))
        else:
            _set(attr, inp, folder)


def _graph(stage, mpath: Sdf.Path, graph, folder: str, warn, path: str) -> None:
    gpath = mpath.AppendChild(graph.getName())
    prim = stage.DefinePrim(gpath, "NodeGraph")
    for inp in graph.getInputs():
        _set(prim.CreateAttribute(f"inputs:{inp.getName()}", _sdf(inp.getType())), inp, folder)
    for node in graph.getNodes():
        _node(stage, gpath, node, folder, warn, path, graph=gpath)
    for out in graph.getOutputs():
        attr = prim.CreateAttribute(f"outputs:{out.getName()}", _sdf(out.getType()))
        if out.getNodeName():
            attr.AddConnection(gpath.AppendChild(out.getNodeName()).AppendProperty(
                f"outputs:{out.getOutputString() or 'out'}"))


def _sdf(mtype: str):
    return getattr(Sdf.ValueTypeNames, _SDF_TYPES.get(mtype, "Token"))


def _set(attr, inp, folder: str) -> None:
    """An input's value on a USD attribute (absolute file paths, colorspace metadata)."""
    text = inp.getResolvedValueString() if inp.getType() == "filename" else inp.getValueString()
    if not text:
        return
    mtype = inp.getType()
    if mtype == "filename":
        attr.Set(Sdf.AssetPath(text if os.path.isabs(text) else os.path.normpath(os.path.join(folder, text))))
        cs = inp.getActiveColorSpace()
        if cs:
            attr.SetColorSpace(cs)
        return
    if mtype in ("string", "surfaceshader"):
        attr.Set(text)
        return
    if mtype == "boolean":
        attr.Set(text.strip().lower() == "true")
        return
    try:
        nums = [float(x) for x in text.replace(" ", "").split(",")]
    except ValueError:
        return
    if mtype == "integer":
        attr.Set(int(nums[0]))
    elif mtype == "boolean":
        attr.Set(bool(nums[0]))
    elif len(nums) == 1:
        attr.Set(nums[0])
    else:
        attr.Set(tuple(nums))
