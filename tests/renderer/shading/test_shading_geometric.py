"""MaterialX nodes driven by the hit's position, normal and tangent (renderer/usd/shading/signals.py ``Geo``,
renderer/shading/materials.py ``projected_rgba``): the geometric nodes in object and world space, image lookups
projected from the position, triplanar projections, and a render that evaluates them at every hit."""
from __future__ import annotations

import numpy as np
import pytest

from renderer.film.film import resolve
from renderer.render import RenderOptions, prepare, render_frame
from renderer.shading import material_upload as U, materials as M
from renderer.shading.textures import image_bilinear_np
from renderer.usd.importer import load_scene
from test_shading_network import HEAD, QUAD, load, warnings, write_png

EMIT = """
def Material "M"
{{
    token outputs:mtlx:surface.connect = </M/SS.outputs:out>
    def Shader "SS"
    {{
        uniform token info:id = "ND_standard_surface_surfaceshader"
        float inputs:base = 0
        float inputs:specular = 0
        float inputs:emission = 1
        color3f inputs:emission_color.connect = </M/{out}.outputs:out>
        token outputs:out
    }}
{nodes}
}}
"""


def node(name, sid, **inputs):
    lines = [f'    def Shader "{name}"', "    {", f'        uniform token info:id = "{sid}"']
    for key, (typ, value) in inputs.items():
        if isinstance(value, str) and value.startswith("</"):
            lines.append(f"        {typ} inputs:{key}.connect = {value}")
        else:
            lines.append(f"        {typ} inputs:{key} = {value}")
    lines += ["        float3 outputs:out", "    }"]
    return "\n".join(lines)


def emitting(tmp_path, out, *nodes, name="g.usda", prefix=""):
    return load(tmp_path, prefix + QUAD.format(mat="M") + EMIT.format(out=out, nodes="\n".join(nodes)), name)


def emission_at(scene, **geometry):
    """The emission of the quad's material at N hits described by ``geometry`` (``materials.hit_geometries``)."""
    n = len(next(iter(geometry.values())))
    mats = scene.materials
    i = int(scene.meshes[0].material_ids[0])
    return M.evaluate_materials(U.upload_materials(mats), U.upload_material_textures(mats), [i] * n,
                                np.zeros((n, 2)), geometry=M.hit_geometries(n, **geometry))["emissive_color"]


@pytest.mark.parametrize("space", ["object", "world"])
def test_normal_node_as_a_colour(tmp_path, space):
    """emission = normal * 0.5 + 0.5 (the usual normal visualisation), in the space asked for."""
    scene = emitting(tmp_path, "C", node("N", "ND_normal_vector3", space=("string", f'"{space}"')),
                     node("H", "ND_multiply_vector3FA", in1=("float3", "</M/N.outputs:out>"), in2=("float", 0.5)),
                     node("C", "ND_add_vector3FA", in1=("float3", "</M/H.outputs:out>"), in2=("float", 0.5)))
    n_obj = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    n_world = np.array([[0.0, 1.0, 0.0], [0.0, 0.6, 0.8]])
    got = emission_at(scene, n_object=n_obj, n_world=n_world)
    want = (n_obj if space == "object" else n_world) * 0.5 + 0.5
    np.testing.assert_allclose(got, want, atol=1e-6)
    assert "not affine" not in warnings(scene) and "unsupported" not in warnings(scene)


def test_geometric_values_without_a_hit_take_their_mean(tmp_path):
    """Where the hit's geometry is unknown (``eval_material``: shadow rays, points sampled on lights) an input
    driven by position takes its value without a hit (MaterialX's default output, mapped)."""
    scene = emitting(tmp_path, "C", node("P", "ND_position_vector3"),
                     node("C", "ND_add_vector3FA", in1=("float3", "</M/P.outputs:out>"), in2=("float", 0.25)))
    mats = scene.materials
    i = int(scene.meshes[0].material_ids[0])
    out = M.evaluate_materials(U.upload_materials(mats), U.upload_material_textures(mats), [i], [(0.5, 0.5)])
    np.testing.assert_allclose(out["emissive_color"][0], [0.25, 0.25, 0.25], atol=1e-6)
    np.testing.assert_allclose(emission_at(scene, p_object=[[0.5, 0.0, 1.0]]), [[0.75, 0.25, 1.25]], atol=1e-6)


def test_dot_product_of_the_normal_is_a_mask(tmp_path):
    """dotproduct(normal(world), up) — a common "faces pointing up" mask — stays affine in the normal."""
    scene = emitting(tmp_path, "D", node("N", "ND_normal_vector3", space=("string", '"world"')),
                     node("D", "ND_dotproduct_vector3", in1=("float3", "</M/N.outputs:out>"),
                          in2=("float3", "(0, 1, 0)")))
    n_world = np.array([[0.0, 1.0, 0.0], [0.0, 0.6, 0.8], [1.0, 0.0, 0.0]])
    np.testing.assert_allclose(emission_at(scene, n_world=n_world), np.repeat(n_world[:, 1:2], 3, 1), atol=1e-6)


def checker_png(tmp_path, name="checker.png", n=4):
    """An n x n checker of red and blue texels (row 0 = top in the file)."""
    checks = (np.indices((n, n)).sum(0) % 2).astype(np.float32)
    img = np.stack([checks, np.zeros_like(checks), 1 - checks], -1)
    write_png(tmp_path / name, img)
    return img[::-1]  # bottom row first, as the renderer stores it


def test_image_looked_up_by_world_position(tmp_path):
    """An image whose texcoord is the world position's (x, z) (extract + combine2): a planar projection, the
    texel under each hit as the bilinear lookup at st = (x, z) gives it."""
    texels = checker_png(tmp_path)
    scene = emitting(
        tmp_path, "I", node("P", "ND_position_vector3", space=("string", '"world"')),
        node("X", "ND_extract_vector3", **{"in": ("float3", "</M/P.outputs:out>"), "index": ("int", 0)}),
        node("Z", "ND_extract_vector3", **{"in": ("float3", "</M/P.outputs:out>"), "index": ("int", 2)}),
        node("ST", "ND_combine2_vector2", in1=("float", "</M/X.outputs:out>"), in2=("float", "</M/Z.outputs:out>")),
        node("I", "ND_image_color3", file=("asset", "@checker.png@"), texcoord=("float2", "</M/ST.outputs:out>")))
    p = np.array([[0.125, 5.0, 0.125], [0.375, -2.0, 0.125], [0.625, 0.0, 0.875], [1.3, 0.0, 0.6]])
    want = image_bilinear_np(texels, p[:, [0, 2]])[:, :3]
    got = emission_at(scene, p_world=p, p_object=np.zeros_like(p))
    np.testing.assert_allclose(got, want, atol=1e-6)
    assert np.ptp(got[:, 0]) > 0.9, "the hits see different checks"


def triplanar(tmp_path, blend=1.0, upaxis=2, files=("x.png", "y.png", "z.png"), space=None):
    for f, colour in zip(("x.png", "y.png", "z.png"), np.eye(3)):
        write_png(tmp_path / f, np.tile(colour, (2, 2, 1)))
    inputs = {k: ("asset", f"@{f}@") for k, f in zip(("filex", "filey", "filez"), files)}
    inputs.update(blend=("float", blend), upaxis=("int", upaxis))
    nodes = [node("T", "ND_triplanarprojection_color3", **inputs)]
    if space is not None:  # position and normal in that space
        nodes += [node("P", "ND_position_vector3", space=("string", f'"{space}"')),
                  node("N", "ND_normal_vector3", space=("string", f'"{space}"'))]
        nodes[0] = node("T", "ND_triplanarprojection_color3", position=("float3", "</M/P.outputs:out>"),
                        normal=("float3", "</M/N.outputs:out>"), **inputs)
    return emitting(tmp_path, "T", *nodes, name=f"tri_{blend}_{upaxis}_{space}.usda")


@pytest.mark.parametrize("blend, weights", [(1.0, (3 / 7, 4 / 7)), (0.5, (9 / 25, 16 / 25))])
def test_triplanar_weights_follow_the_normal(tmp_path, blend, weights):
    """Images red (x), green (y), blue (z): a normal along an axis sees that axis' image; between two axes the
    MaterialX weights |n| / sum |n|, raised to 1 / blend and normalised."""
    scene = triplanar(tmp_path, blend)
    n = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.8, 0.0]])
    got = emission_at(scene, n_object=n, p_object=np.zeros_like(n), n_world=np.roll(n, 1, axis=1))
    np.testing.assert_allclose(got[:3], np.eye(3), atol=1e-6)
    np.testing.assert_allclose(got[3], [weights[0], weights[1], 0.0], atol=1e-6)


@pytest.mark.parametrize("upaxis, st_of_x", [(2, (1, 2)), (1, (2, 1)), (0, (2, 1))])
def test_triplanar_st_from_the_position_axes(tmp_path, upaxis, st_of_x):
    """The x image is looked up at (Py, Pz) with Z up (MaterialX's default), at (Pz, Py) with Y or X up: a
    checker image tells the coordinates apart."""
    texels = checker_png(tmp_path, "checker.png")
    scene = triplanar(tmp_path, upaxis=upaxis, files=("checker.png", "y.png", "z.png"))
    p = np.array([[0.0, 0.125, 0.375], [0.0, 0.375, 0.125], [5.0, 0.625, 0.125]])
    got = emission_at(scene, p_object=p, n_object=np.tile([1.0, 0.0, 0.0], (3, 1)))
    np.testing.assert_allclose(got, image_bilinear_np(texels, p[:, list(st_of_x)])[:, :3], atol=1e-6)


def test_triplanar_in_world_space(tmp_path):
    scene = triplanar(tmp_path, space="world")
    got = emission_at(scene, n_object=[[1.0, 0.0, 0.0]], n_world=[[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(got, [[0.0, 0.0, 1.0]], atol=1e-6)


def test_a_non_affine_function_of_the_position_warns(tmp_path):
    scene = emitting(tmp_path, "C", node("P", "ND_position_vector3"),
                     node("C", "ND_power_vector3FA", in1=("float3", "</M/P.outputs:out>"), in2=("float", 2.0)))
    assert "not affine" in warnings(scene)


def test_rendered_position_colours_follow_the_hit_in_object_and_world_space(tmp_path):
    """An orthographic view of the quad (x, y in [-1, 1], moved 0.5 along x), emission = position * 0.25 + 0.5:
    each pixel shows its hit's position (a linear function: the pixel's mean is its centre's value), in world
    space, or in the quad's own space 0.5 to the left."""
    camera = """
def Camera "Cam"
{
    token projection = "orthographic"
    float horizontalAperture = 20
    float verticalAperture = 20
    double3 xformOp:translate = (0.5, 0, 4)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
"""
    moved = QUAD.format(mat="M").replace('rel material:binding', 'double3 xformOp:translate = (0.5, 0, 0)\n'
                                         '    uniform token[] xformOpOrder = ["xformOp:translate"]\n'
                                         '    rel material:binding')
    for space, shift in (("world", 0.0), ("object", 0.5)):
        p = tmp_path / f"r_{space}.usda"
        p.write_text(HEAD + camera + moved + EMIT.format(out="C", nodes="\n".join([
            node("P", "ND_position_vector3", space=("string", f'"{space}"')),
            node("H", "ND_multiply_vector3FA", in1=("float3", "</M/P.outputs:out>"), in2=("float", 0.25)),
            node("C", "ND_add_vector3FA", in1=("float3", "</M/H.outputs:out>"), in2=("float", 0.5))])))
        scene = load_scene(str(p), 0)
        prep = prepare(scene, RenderOptions(width=16, height=16, spp=32, max_depth=0, filter="box"))
        img = resolve(render_frame(prep, tile_size=16, threads=2).sums)["rgba"]
        centres = (np.arange(16) + 0.5) / 16 * 2.0 - 1.0  # the view spans [-1, 1] about the camera's x = 0.5
        x = centres + 0.5 - shift
        y = -centres  # image rows run down
        np.testing.assert_allclose(img[4:12, 4:12, 0], np.tile(x[4:12] * 0.25 + 0.5, (8, 1)), atol=2e-3)
        np.testing.assert_allclose(img[4:12, 4:12, 1], np.tile((y[4:12] * 0.25 + 0.5)[:, None], (1, 8)), atol=2e-3)
        np.testing.assert_allclose(img[4:12, 4:12, 2], 0.5, atol=2e-3)
