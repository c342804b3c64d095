"""Compositing layers of real renders: light path expression layers that partition the beauty, light groups that
sum to it and match a render with only their lights on, Cryptomatte decoded by the specification's rules on an
analytic disk, the same bits in any tiling, and the command line's errors."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, Kind, Sdf, Usd, UsdGeom, UsdLux, UsdShade

import stages
from cli_runs import assert_one_line_error, drt
from renderer.film import cryptomatte as cm
from renderer.settings.options import RenderOptions
from renderer.render import frame_image, prepare, render_frame
from renderer.usd.importer import load_scene

# first event after the camera: none (lights and emitters seen), reflection D / G / S, transmission, volume
BY_FIRST_EVENT = {"seen": "C[LO]", "diffuse": "C<RD>.*[LO]", "glossy": "C<RG>.*[LO]", "mirror": "C<RS>.*[LO]",
                  "transmit": "C<T.>.*[LO]", "volume": "CV.*[LO]"}
BY_DEPTH = {"seen": "C[LO]", "direct": "C.[LO]", "indirect": "C..+[LO]"}


def rect_light(stage, path, *, intensity, size, translate, rotate_x=-90.0):
    """A RectLight (emitting along its -Z: straight down with the default rotation)."""
    light = UsdLux.RectLight.Define(stage, path)
    light.CreateIntensityAttr(intensity)
    light.CreateWidthAttr(size[0])
    light.CreateHeightAttr(size[1])
    xf = UsdGeom.Xformable(light)
    xf.AddTranslateOp().Set(Gf.Vec3d(*translate))
    xf.AddRotateXOp().Set(rotate_x)
    return light


def room(path, *, panel=6.0, bulb=3.0, rim=4.0, glow=(4.0, 2.0, 1.0), glow2=(0.5, 1.0, 3.0)):
    """Floor (diffuse and glossy) and wall (diffuse) with a glossy metal ball, a mirror ball, a clear glass ball and a
    ball of fog (an invisible boundary around a scattering medium); lit by a RectLight seen by the camera
    (group ``key`` by ``karma:light:lpetag``), a SphereLight (``key`` by ``ri:light:lightGroup``), a second RectLight
    named Rim (no attribute: its prim's name) and two emissive quads, Glow (no group) and Glow2 (``Rim`` by
    ``primvars:arnold:aov``). The keywords are the lights' intensities (nits) and the quads' emission."""
    st = stages.new_stage(path)
    stages.camera(st, translate=(0, 1.0, 4.0), rotate_x=-8.0, focal_mm=30.0)
    floor = stages.preview_surface(st, "Floor", diffuseColor=(0.6, 0.6, 0.6), roughness=0.35)
    wall = stages.material(st, "Wall", diffuse=(0.5, 0.6, 0.7))
    gloss = stages.preview_surface(st, "Gloss", diffuseColor=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.35)
    mirror = stages.preview_surface(st, "Mirror", diffuseColor=(0.9, 0.9, 0.9), metallic=1.0, roughness=0.0)
    glass = stages.preview_surface(st, "Glass", opacity=0.0, ior=1.5, roughness=0.0)
    fog = stages.preview_surface(st, "Fog", opacity=0.0, ior=1.0)
    fog_shader = UsdShade.Shader(st.GetPrimAtPath("/World/Looks/Fog/Surface"))
    fog_shader.CreateInput("drt:scatterColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(1.5, 1.5, 1.5))
    fog_shader.CreateInput("drt:scatterDistance", Sdf.ValueTypeNames.Float).Set(1.0)
    stages.rect_xz(st, "/World/Floor", -3, 3, -3, 3, 0.0, floor)
    stages.rect_xy(st, "/World/Wall", -3, 3, 0, 3, -1.5, wall)
    stages.sphere(st, "/World/GlossBall", 0.35, (-1.1, 0.35, 0.0), gloss)
    stages.sphere(st, "/World/MirrorBall", 0.35, (-0.35, 0.35, -0.4), mirror)
    stages.sphere(st, "/World/GlassBall", 0.35, (0.4, 0.35, 0.3), glass)
    stages.sphere(st, "/World/FogBall", 0.35, (1.15, 0.35, -0.2), fog)
    stages.rect_xy(st, "/World/Glow", 0.6, 1.6, 0.9, 1.5, -1.45, stages.material(st, "Emit", emissive=glow))
    g2 = stages.rect_xy(st, "/World/Glow2", -1.8, -1.0, 1.0, 1.4, -1.45, stages.material(st, "Emit2", emissive=glow2))
    g2.GetPrim().CreateAttribute("primvars:arnold:aov", Sdf.ValueTypeNames.String).Set("Rim")
    p = rect_light(st, "/World/Panel", intensity=panel, size=(1.2, 0.5), translate=(-0.3, 1.55, 0.6))
    p.GetPrim().CreateAttribute("karma:light:lpetag", Sdf.ValueTypeNames.String).Set("key")
    bulb_light = UsdLux.SphereLight.Define(st, "/World/Bulb")
    bulb_light.CreateIntensityAttr(bulb)
    bulb_light.CreateRadiusAttr(0.1)
    UsdGeom.Xformable(bulb_light).AddTranslateOp().Set(Gf.Vec3d(1.2, 1.2, 0.8))
    bulb_light.GetPrim().CreateAttribute("ri:light:lightGroup", Sdf.ValueTypeNames.String).Set("key")
    rect_light(st, "/World/Rim", intensity=rim, size=(0.6, 0.6), translate=(0.0, 1.6, -1.2), rotate_x=-60.0)
    st.Save()
    return path


def render(path, width=64, height=48, spp=32, tile=32, threads=2, **options):
    prep = prepare(load_scene(path), RenderOptions(width=width, height=height, spp=spp, **options))
    return frame_image(prep, render_frame(prep, tile_size=tile, threads=threads).sums)


def layer(channels, name):
    return np.stack([channels[f"{name}.{c}"] for c in "RGB"], -1).astype(np.float64)


def beauty(channels):
    return np.stack([channels[c] for c in "RGB"], -1).astype(np.float64)


def assert_sums_to_beauty(channels, names, rel=1e-5, minus=()):
    want = beauty(channels) - sum((layer(channels, n) for n in minus), np.zeros(beauty(channels).shape))
    got = sum(layer(channels, n) for n in names)
    tol = rel * np.abs(beauty(channels)).max()
    assert np.abs(got - want).max() <= tol, (np.abs(got - want).max(), tol)


@pytest.fixture(scope="module")
def room_file(tmp_path_factory):
    return room(tmp_path_factory.mktemp("aov") / "room.usda")


@pytest.fixture(scope="module")
def room_layers(room_file):
    lpe = tuple(f"{k}={v}" for k, v in {**BY_FIRST_EVENT, **BY_DEPTH}.items()) + (
        "emission=C.*O", "rim_emission=C.*<O.'Rim'>", "rim_seen=C<O.'Rim'>")
    return render(room_file, lpe=lpe, light_groups=True).channels


def test_every_layer_is_finite_and_every_event_type_shows(room_layers):
    for name, values in room_layers.items():
        assert np.isfinite(values).all(), name
    # the scene has something of every kind, so that the partitions below are no sums of zeros
    for name in (*BY_FIRST_EVENT, *BY_DEPTH, "RGBA_key", "RGBA_Rim"):
        assert layer(room_layers, name).max() > 1e-3, name
        assert layer(room_layers, name).min() >= 0.0, name


@pytest.mark.parametrize("names", [list(BY_FIRST_EVENT), list(BY_DEPTH)], ids=["by_first_event", "by_depth"])
def test_disjoint_expressions_partition_the_beauty_per_pixel(room_layers, names):
    assert_sums_to_beauty(room_layers, names)


def test_light_groups_of_all_lights_sum_to_the_beauty_minus_ungrouped_emitters(room_layers):
    """A group is ``C.*[<L.'g'><O.'g'>]``: every path that ends at a light or an emitter of group g, seen directly
    (``CL``, ``CO``) or after any bounces. Emissive geometry is in a group only where its prim names one (Glow2 is in
    Rim, Glow in none), so the groups sum to the beauty minus the paths that end at Glow's emission, ``C.*O`` minus
    ``C.*<O.'Rim'>`` (not minus all emission seen directly: Glow2 seen directly is in Rim). UsdLux area lights are
    not seen by camera rays (docs/rendering.md), so ``CL`` is empty here; they are seen through the glass."""
    groups = sorted(c[:-2] for c in room_layers if c.startswith("RGBA_") and c.endswith(".R"))
    assert groups == ["RGBA_Rim", "RGBA_key"]  # Panel and Bulb by their attributes, Rim by its name
    assert layer(room_layers, "rim_seen").max() > 0.1
    assert layer(room_layers, "rim_emission").max() > 1e-3  # Glow2 lights the room through its group
    ungrouped = layer(room_layers, "emission") - layer(room_layers, "rim_emission")
    assert ungrouped.max() > 0.1
    want = beauty(room_layers) - ungrouped
    got = layer(room_layers, "RGBA_key") + layer(room_layers, "RGBA_Rim")
    assert np.abs(got - want).max() <= 1e-5 * beauty(room_layers).max()


# -- a light group against a render with only its lights on ------------------------------------------------------

# each group's lights alone: the others' intensities and emission 0 (Glow: the emitter in no group)
ALONE = {"key": dict(rim=0.0, glow=(0, 0, 0), glow2=(0, 0, 0)),
         "Rim": dict(panel=0.0, bulb=0.0, glow=(0, 0, 0)),
         "Glow": dict(panel=0.0, bulb=0.0, rim=0.0, glow2=(0, 0, 0))}
SPP_ALONE = 64
BLOCK = 8  # pixels a side of the blocks compared (the blur)


def blocks(image):
    h, w, c = image.shape
    return image.reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK, c).mean((1, 3))


@pytest.fixture(scope="module")
def alone(tmp_path_factory):
    """Unbiased renders (no clamp, whose share depends on which lights are on) of the whole room with its light
    groups, and of each group's lights alone at seeds 0 and 1."""
    d = tmp_path_factory.mktemp("alone")
    out = {"all": render(room(d / "all.usda"), spp=SPP_ALONE, unbiased=True, light_groups=True).channels}
    for group, intensities in ALONE.items():
        path = room(d / f"{group}.usda", **intensities)
        out[group] = [beauty(render(path, spp=SPP_ALONE, unbiased=True, seed=seed).channels) for seed in (0, 1)]
    return out


@pytest.mark.parametrize("group", ["key", "Rim"])
def test_a_light_group_matches_a_render_with_only_its_lights_on(alone, group):
    """Light selection differs between the two renders, so their noise does: the tolerance is the noise measured
    between two seeds of the lone render, per block of 8 x 8 pixels and on the image's mean. A group layer that held
    another group's light, or a group's emitter that took another's hits, is off by many times that."""
    layer_ = layer(alone["all"], f"RGBA_{group}")
    lone, lone_other_seed = alone[group]
    noise = blocks(lone_other_seed) - blocks(lone)  # the difference of two independent estimates
    rms_noise = np.sqrt(np.mean(noise ** 2))
    assert rms_noise > 0.0
    diff = blocks(layer_) - blocks(lone)
    assert np.sqrt(np.mean(diff ** 2)) <= 1.5 * rms_noise
    assert np.abs(diff).max() <= 6.0 * rms_noise
    sigma_mean = noise.reshape(-1, 3).std(0) / math.sqrt(noise.shape[0] * noise.shape[1])
    assert np.all(np.abs(diff.reshape(-1, 3).mean(0)) <= 4.0 * sigma_mean + 1e-7)
    # the comparison has the power to tell: the whole beauty is far from the lone render
    assert np.sqrt(np.mean((blocks(beauty(alone["all"])) - blocks(lone)) ** 2)) > 20.0 * rms_noise


def test_the_beauty_is_the_sum_of_renders_of_each_groups_lights(alone):
    """Light adds: the room's beauty is the sum of its lights' lone renders, within the noise of the means (the two
    emissive quads are merged into one mesh by default, where each must still be lit, weighted and labelled as
    itself)."""
    parts = [alone[g][0] for g in ALONE]
    noise = [blocks(alone[g][1]) - blocks(alone[g][0]) for g in ALONE]
    n = noise[0].shape[0] * noise[0].shape[1]
    sigma = np.sqrt(sum(x.reshape(-1, 3).var(0) / 2 for x in noise) / n)  # of the sum of the parts' means
    total = beauty(alone["all"]).mean((0, 1))
    assert np.all(np.abs(sum(p.mean((0, 1)) for p in parts) - total) <= 5.0 * sigma * math.sqrt(2) + 1e-7)


# -- Cryptomatte on an analytic disk -----------------------------------------------------------------------------

PIXEL = 0.025  # metres a pixel: the orthographic camera sees 2.4 x 1.6 m on 96 x 64 pixels
DISK = (0.013, -0.021, 0.5)  # the ball's centre x, y and radius, metres
CARD = (0.7, 1.1, -0.5, 0.3)  # x0, x1, y0, y1 of the card, metres: on pixel edges
SPP_CRYPTO = 32


def disk_stage(path):
    """An orthographic camera on +Z looking at a ball (a disk of radius 0.5 m in the image; in the component
    /World/Prop, material Red) and a card (component /World/Board, material Blue), over nothing."""
    st = stages.new_stage(path)
    stages.camera(st, ortho=True, h_ap_mm=24.0, v_ap_mm=16.0, translate=(0, 0, 5.0))  # apertures in tenths of a m
    for name in ("Prop", "Board"):
        Usd.ModelAPI(UsdGeom.Xform.Define(st, f"/World/{name}").GetPrim()).SetKind(Kind.Tokens.component)
    x, y, r = DISK
    stages.sphere(st, "/World/Prop/Ball", r, (x, y, -0.5), stages.material(st, "Red", diffuse=(0.8, 0.1, 0.1)))
    stages.rect_xy(st, "/World/Board/Card", *CARD, 0.0, stages.material(st, "Blue", diffuse=(0.1, 0.1, 0.8)))
    st.Save()
    return path


def spec_decode(channels, attributes, layer_name):
    """Every manifest name's matte, by the specification 1.2 alone: the layer's metadata key is found by its name,
    ranks are the channels ``<layer>NN.R/G/B/A`` holding (id, coverage) pairs in rank order, and a name's matte is
    the sum of the coverage of every rank whose id is its manifest id (8 hex digits of the float32's bits)."""
    import json
    import struct

    prefix = next(k[: -len("name")] for k, v in attributes.items() if k.endswith("/name") and v == layer_name)
    assert attributes[prefix + "hash"] == "MurmurHash3_32"
    assert attributes[prefix + "conversion"] == "uint32_to_float32"
    manifest = json.loads(attributes[prefix + "manifest"])
    pairs = []
    for k in range(100):
        if f"{layer_name}{k:02d}.R" not in channels:
            break
        ch = [channels[f"{layer_name}{k:02d}.{c}"] for c in "RGBA"]
        pairs += [(ch[0], ch[1]), (ch[2], ch[3])]
    out = {}
    for name, hex_id in manifest.items():
        value = np.float32(struct.unpack(">f", bytes.fromhex(hex_id))[0])
        out[name] = sum(np.where(ids == value, cov, 0).astype(np.float64) for ids, cov in pairs)
    return out, len(pairs)


@pytest.fixture(scope="module")
def disk_frame(tmp_path_factory):
    path = disk_stage(tmp_path_factory.mktemp("crypto") / "disk.usda")
    return render(path, width=96, height=64, spp=SPP_CRYPTO, tile=32, cryptomatte=("object", "material", "asset"))


def pixel_distance_to_centre(shape):
    h, w = shape
    x, y, _ = DISK
    px = (x + 1.2) / PIXEL  # the image's left edge is at x = -1.2 m, its top at y = 0.8 m
    py = (0.8 - y) / PIXEL
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    return np.hypot(xx - px, yy - py)


def test_cryptomatte_decodes_to_the_disks_coverage_and_mattes_sum_to_alpha(disk_frame):
    channels, attributes = disk_frame.channels, disk_frame.attributes
    mattes, ranks = spec_decode(channels, attributes, "CryptoObject")
    assert ranks == 6  # the default
    ball, card = mattes["/World/Prop/Ball"], mattes["/World/Board/Card"]
    # the renderer's own decoder agrees with the specification's rule
    ours = cm.decode(channels, attributes, "CryptoObject")
    assert set(ours) == {"/World/Prop/Ball", "/World/Board/Card"}
    for name, matte in ours.items():
        np.testing.assert_allclose(matte, mattes[name], atol=1e-6)
    # coverage: the disk's area in pixels. Only pixels on its edge (about its perimeter in pixels) are estimates,
    # each of a fraction from SPP_CRYPTO samples: a standard deviation below 0.5 / sqrt(spp) per pixel
    radius_px = DISK[2] / PIXEL
    sigma = 0.5 / math.sqrt(SPP_CRYPTO) * math.sqrt(2 * math.pi * radius_px)
    assert abs(ball.sum() - math.pi * radius_px ** 2) <= 4 * sigma
    card_px = (CARD[1] - CARD[0]) * (CARD[3] - CARD[2]) / PIXEL ** 2
    assert abs(card.sum() - card_px) <= 4 * 0.5 / math.sqrt(SPP_CRYPTO) * math.sqrt(2 * (CARD[1] - CARD[0] + CARD[3]
                                                                                          - CARD[2]) / PIXEL)
    # per pixel: mattes in [0, 1], of all names summing to alpha; 1 inside the disk, 0 far outside it
    for matte in mattes.values():
        assert matte.min() >= 0.0 and matte.max() <= 1.0 + 1e-6
    np.testing.assert_allclose(sum(mattes.values()), channels["A"], atol=1e-5)
    r = pixel_distance_to_centre(ball.shape)
    reach = 1.5 + 0.75  # the Gaussian filter's radius and half a pixel's diagonal, pixels
    assert np.all(np.abs(ball[r < radius_px - reach] - 1.0) <= 1e-6) and (r < radius_px - reach).sum() > 900
    far = r > radius_px + reach
    assert np.all(ball[far] == 0.0)
    assert np.all(channels["A"][far & (card == 0)] == 0.0) and (far & (card == 0)).sum() > 3000


def test_cryptomatte_material_and_asset_layers_name_the_materials_and_components(disk_frame):
    channels, attributes = disk_frame.channels, disk_frame.attributes
    objects, _ = spec_decode(channels, attributes, "CryptoObject")
    materials, _ = spec_decode(channels, attributes, "CryptoMaterial")
    assets, _ = spec_decode(channels, attributes, "CryptoAsset")
    assert {"/World/Looks/Red", "/World/Looks/Blue"} <= set(materials)
    assert {"/World/Prop", "/World/Board"} <= set(assets)
    for obj, mat, asset in (("/World/Prop/Ball", "/World/Looks/Red", "/World/Prop"),
                            ("/World/Board/Card", "/World/Looks/Blue", "/World/Board")):
        np.testing.assert_allclose(materials[mat], objects[obj], atol=1e-6)
        np.testing.assert_allclose(assets[asset], objects[obj], atol=1e-6)
    for layer_name in ("CryptoMaterial", "CryptoAsset"):
        np.testing.assert_allclose(sum(cm.decode(channels, attributes, layer_name).values()), channels["A"], atol=1e-5)


# -- tiling ------------------------------------------------------------------------------------------------------


def test_lpe_light_group_and_cryptomatte_layers_have_the_same_bits_in_any_tiling(room_file):
    options = dict(width=48, height=32, spp=16, lpe=("diffuse=C<RD>.*[LO]", "indirect=C..+[LO]"), light_groups=True,
                   cryptomatte=("object", "material", "asset"))
    a = render(room_file, tile=16, threads=1, **options)
    b = render(room_file, tile=64, threads=2, **options)
    assert set(a.channels) == set(b.channels)
    aovs = [c for c in a.channels if c.split(".")[0] in ("diffuse", "indirect", "RGBA_key", "RGBA_Rim")
            or c.startswith("Crypto")]
    assert len(aovs) == 4 * 3 + 3 * 3 * 4  # four RGB layers, three Cryptomatte layers of three RGBA channels
    for c in aovs:
        assert a.channels[c].tobytes() == b.channels[c].tobytes(), c
    assert layer(a.channels, "diffuse").max() > 0.0
    manifests = {k: v for k, v in a.attributes.items() if k.startswith("cryptomatte/")}
    assert len(manifests) == 3 * 4 and manifests == {k: b.attributes[k] for k in manifests}


def test_asking_for_layers_leaves_the_beauty_bits_as_they_are(room_file):
    """Layers are rendered by a kernel variant of their own (``renderer.integrator.layers``): the beauty, depth,
    normal and albedo it writes must be those of the plain kernel, bit for bit."""
    options = dict(width=48, height=32, spp=16)
    plain = render(room_file, **options)
    layered = render(room_file, lpe=("diffuse=C<RD>.*[LO]",), light_groups=True, cryptomatte=("object",),
                     **options)
    assert len(layered.channels) > len(plain.channels)
    for c in plain.channels:
        assert plain.channels[c].tobytes() == layered.channels[c].tobytes(), c
    assert beauty(plain.channels).max() > 0.0


# -- command line ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("args,needles", [
    (("--lpe", "bad=C<RD"), ("--lpe", "C<RD", "'>'")),
    (("--lpe", "C<RD>L"), ("--lpe", "NAME=EXPRESSION")),
    (("--cryptomatte", "bogus"), ("--cryptomatte", "bogus")),
])
def test_the_command_line_rejects_bad_lpes_and_cryptomatte_kinds_in_one_line(room_file, tmp_path, args, needles):
    out = tmp_path / "out.exr"
    r = drt("render", room_file, "-o", out, "--width", 16, "--height", 16, "--spp", 1, *args)
    assert_one_line_error(r, "drt: error:", *needles)
    assert r.returncode == 2 and r.stderr.startswith("drt: error:")
    assert not out.exists()
