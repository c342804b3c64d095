"""(Copied from ../shared/bench, fixed for Blender 5.2's motion-blur settings.) Run inside the bpy venv: import a USD scene, render with Cycles CPU (2 threads, no denoise/adaptive) to an EXR.
Usage: cycles_render.py SCENE OUT.exr W H SPP SEED [motion]. Prints JSON with the render seconds.
$DRT_BLENDER_FIXUPS (JSON, from noise.py's ``blender_fixups``): what the USD import dropped, rebuilt after it.
$CYCLES_DEPTH: every bounce limit of Cycles at this number (its defaults: diffuse 4, glossy 4, total 12); 7 is
our max_depth 8 (ours counts direct lighting as depth 1, Cycles as 0 bounces)."""
import sys, time, json, bpy
scene_path, out, w, h, spp, seed = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])
motion = len(sys.argv) > 7 and sys.argv[7] == "motion"
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=scene_path)
sc = bpy.context.scene
cams = [o for o in sc.objects if o.type == "CAMERA"]
if cams: sc.camera = cams[0]
root = [o for o in sc.objects if o.parent is None and o.type == "EMPTY"]
unit = root[0].scale[0] if root else 1.0
for o in sc.objects:  # the importer does not scale a SphereLight's radius by metersPerUnit
    if o.type == "LIGHT" and o.data.type in ("POINT", "SPOT"): o.data.shadow_soft_size *= unit
import os
fx = json.loads(os.environ.get("DRT_BLENDER_FIXUPS") or "null")  # what the USD import dropped (noise.py's pxr reads)
if fx:
    for name, radius in fx["spheres"].items():  # 64 x 32 smooth UV spheres, as ours, instead of 92-vertex ones
        old = sc.objects.get(name)
        if old is None: continue
        mesh = bpy.data.meshes.new(name + "_uv")
        import bmesh
        bm = bmesh.new(); bmesh.ops.create_uvsphere(bm, u_segments=64, v_segments=32, radius=radius); bm.to_mesh(mesh); bm.free()
        for poly in mesh.polygons: poly.use_smooth = True
        old.data = mesh
    for name, m in fx["materials"].items():
        o = sc.objects.get(name)
        if o is None or o.type != "MESH" or len(o.data.materials): continue
        mat = bpy.data.materials.new(name + "_fix")
        bsdf = mat.node_tree.nodes.get("Principled BSDF")
        bsdf.inputs["Base Color"].default_value = (*m["color"], 1.0)
        bsdf.inputs["Roughness"].default_value = m["roughness"]
        bsdf.inputs["Metallic"].default_value = m["metallic"]
        o.data.materials.append(mat)
    if fx["world"] is not None:
        sc.world = bpy.data.worlds.new("dome")
        bg = sc.world.node_tree.nodes.get("Background")
        bg.inputs["Color"].default_value = (*fx["world"], 1.0); bg.inputs["Strength"].default_value = 1.0
sc.render.engine = "CYCLES"; sc.cycles.device = "CPU"; sc.render.threads_mode = "FIXED"; sc.render.threads = 2
sc.cycles.samples = spp; sc.cycles.seed = seed; sc.cycles.use_adaptive_sampling = False; sc.cycles.use_denoising = False
sc.view_settings.view_transform = "Standard"
if os.environ.get("CYCLES_DEPTH"):  # every bounce limit at this depth (ours: max_depth for all lobes; Cycles' defaults are diffuse 4, glossy 4, total 12)
    d = int(os.environ["CYCLES_DEPTH"])
    sc.cycles.max_bounces = d; sc.cycles.diffuse_bounces = d; sc.cycles.glossy_bounces = d; sc.cycles.transmission_bounces = d
if os.environ.get("CYCLES_UNBIASED"):  # no glossy filter, no indirect clamp: the same estimator as a plain path tracer
    sc.cycles.blur_glossy = 0.0; sc.cycles.sample_clamp_indirect = 0.0; sc.cycles.sample_clamp_direct = 0.0
print("defaults: blur_glossy", sc.cycles.blur_glossy, "clamp_indirect", sc.cycles.sample_clamp_indirect, "max_bounces", sc.cycles.max_bounces, file=__import__("sys").stderr)
sc.render.use_motion_blur = motion
if motion:
    sc.render.motion_blur_shutter = 1.0; sc.render.motion_blur_position = "START"  # (the shared copy also set sc.cycles.motion_blur_position, gone in 5.2)
    if fx and fx["shutter"][1] > fx["shutter"][0] and abs(sum(fx["shutter"])) < 1e-9:  # centred (the demo's)
        sc.render.motion_blur_shutter = fx["shutter"][1] - fx["shutter"][0]; sc.render.motion_blur_position = "CENTER"
    for o in sc.objects:
        if o.type == "MESH": o.cycles.motion_steps = 4
sc.frame_set(int(fx["frame"]) if fx else 0)
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = w, h, 100
sc.render.image_settings.file_format = "OPEN_EXR"; sc.render.image_settings.color_depth = "32"
sc.render.filepath = out
t = time.time(); bpy.ops.render.render(write_still=True); dt = time.time() - t
print(json.dumps({"seconds": dt}))
