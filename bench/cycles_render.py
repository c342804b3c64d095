"""(Copied from ../shared/bench, fixed for Blender 5.2's motion-blur settings.) Run inside the bpy venv: import a USD scene, render with Cycles CPU (2 threads, no denoise/adaptive) to an EXR.
Usage: cycles_render.py SCENE OUT.exr W H SPP SEED [motion]. Prints JSON with the render seconds."""
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
sc.render.engine = "CYCLES"; sc.cycles.device = "CPU"; sc.render.threads_mode = "FIXED"; sc.render.threads = 2
sc.cycles.samples = spp; sc.cycles.seed = seed; sc.cycles.use_adaptive_sampling = False; sc.cycles.use_denoising = False
sc.view_settings.view_transform = "Standard"
import os
if os.environ.get("CYCLES_UNBIASED"):  # no glossy filter, no indirect clamp: the same estimator as a plain path tracer
    sc.cycles.blur_glossy = 0.0; sc.cycles.sample_clamp_indirect = 0.0; sc.cycles.sample_clamp_direct = 0.0
print("defaults: blur_glossy", sc.cycles.blur_glossy, "clamp_indirect", sc.cycles.sample_clamp_indirect, "max_bounces", sc.cycles.max_bounces, file=__import__("sys").stderr)
sc.render.use_motion_blur = motion
if motion:
    sc.render.motion_blur_shutter = 1.0; sc.render.motion_blur_position = "START"  # (the shared copy also set sc.cycles.motion_blur_position, gone in 5.2)
    for o in sc.objects:
        if o.type == "MESH": o.cycles.motion_steps = 4
sc.frame_set(0)
sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = w, h, 100
sc.render.image_settings.file_format = "OPEN_EXR"; sc.render.image_settings.color_depth = "32"
sc.render.filepath = out
t = time.time(); bpy.ops.render.render(write_still=True); dt = time.time() - t
print(json.dumps({"seconds": dt}))
