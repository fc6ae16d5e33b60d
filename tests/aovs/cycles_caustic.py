"""A small caustic scene for Cycles (Blender 3.2+; written against 3.4), built from factory startup.

A glass sphere on a checkered diffuse floor beside a red glossy cube and a small emissive tile.
Three light groups:
  key   a small, strong point light (radius 2 cm) above and behind the sphere: its caustic on the
        floor is found only by BSDF sampling through the glass, hence fireflies (nothing is clamped)
  fill  a large, soft area light, plus the small emissive tile (so that the Emit pass is not empty)
  sky   the world background, low strength
Film is transparent. Every light-path pass, Denoising Data, Z/Normal/Position/UV/Vector, object and
material index and a Cryptomatte object pass are written into one multilayer EXR (float32, ZIP).

  blender -b --factory-startup -noaudio --python-exit-code 1 --python cycles_caustic.py -- \
      --out seed_1.exr --seed 1 --spp 64 --res 128 96 [--key-scale 1] [--ior 1.5] [--threads 2] \
      [--checker-scale 8] [--clamp-indirect 0] [--clamp-direct 0] [--note TEXT]

--checker-scale sets the floor checker's Scale (8: cells 0.5 wide; 160: cells 0.025 wide, about 1.5
pixels across at 256 x 192, the pixel-scale detail of the trade's detail renders). --clamp-indirect
and --clamp-direct are Cycles' own firefly clamps (Light Paths > Clamping, 0 = off), the renderer
clamp users already have. --note writes TEXT as the metadata stamp note (the EXR attribute `Note`;
farm/templates/cycles_seed.py gives "seed=S ...", which mcstat --ingest reads as the file's seed).
"""

import argparse
import os
import sys
import time

import bpy


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="cycles_caustic.py", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output multilayer EXR path")
    p.add_argument("--seed", type=int, default=0, help="Cycles sampling seed")
    p.add_argument("--count", type=int, default=1,
                   help="render seeds SEED .. SEED + COUNT - 1 in this one Blender process; --out "
                        "then holds {seed}")
    p.add_argument("--spp", type=int, default=64, help="samples per pixel (adaptive sampling off)")
    p.add_argument("--res", type=int, nargs=2, default=(128, 96), metavar=("W", "H"))
    p.add_argument("--key-scale", type=float, default=1.0, help="multiplies the key light's power")
    p.add_argument("--ior", type=float, default=1.5, help="index of refraction of the glass sphere")
    p.add_argument("--threads", type=int, default=0, help="render threads (0: all cores)")
    p.add_argument("--checker-scale", type=float, default=8.0, help="the floor checker's Scale")
    p.add_argument("--clamp-indirect", type=float, default=0.0,
                   help="Cycles' sample_clamp_indirect (0: off)")
    p.add_argument("--clamp-direct", type=float, default=0.0, help="Cycles' sample_clamp_direct (0: off)")
    p.add_argument("--note", default="",
                   help="the metadata stamp note (EXR attribute Note; {seed} becomes the seed); none if empty")
    a = p.parse_args(argv)
    if a.spp < 1 or a.res[0] < 1 or a.res[1] < 1 or a.threads < 0 or a.key_scale < 0 or a.ior <= 0:
        p.error("spp, res must be >= 1; threads, key-scale >= 0; ior > 0")
    if a.checker_scale <= 0 or a.clamp_indirect < 0 or a.clamp_direct < 0:
        p.error("checker-scale must be > 0; clamp-indirect, clamp-direct >= 0")
    if a.count < 1 or (a.count > 1 and "{seed}" not in a.out):
        p.error("count must be >= 1, and --out must hold {seed} when it is more than 1")
    return a


def clear_scene():
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    for coll in (bpy.data.meshes, bpy.data.materials, bpy.data.lights, bpy.data.cameras):
        for block in list(coll):
            coll.remove(block)


def material(name, pass_index):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    m.pass_index = pass_index
    nt = m.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    return m, nt, out


def floor_material(checker_scale):
    m, nt, out = material("Floor", 1)
    tex = nt.nodes.new("ShaderNodeTexChecker")
    tex.inputs["Scale"].default_value = checker_scale
    tex.inputs["Color1"].default_value = (0.8, 0.8, 0.8, 1.0)
    tex.inputs["Color2"].default_value = (0.25, 0.3, 0.45, 1.0)
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return m


def glass_material(ior):
    m, nt, out = material("Glass", 2)
    g = nt.nodes.new("ShaderNodeBsdfGlass")
    g.distribution = "SHARP"
    g.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    g.inputs["IOR"].default_value = ior
    nt.links.new(g.outputs["BSDF"], out.inputs["Surface"])
    return m


def cube_material():
    # Diffuse red with a glossy coat: feeds both DiffCol and GlossCol.
    m, nt, out = material("RedGlossy", 3)
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (0.7, 0.06, 0.04, 1.0)
    g = nt.nodes.new("ShaderNodeBsdfGlossy")
    g.distribution = "GGX"
    g.inputs["Roughness"].default_value = 0.15
    mix = nt.nodes.new("ShaderNodeMixShader")
    mix.inputs["Fac"].default_value = 0.2
    nt.links.new(d.outputs["BSDF"], mix.inputs[1])
    nt.links.new(g.outputs["BSDF"], mix.inputs[2])
    nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    return m


def emissive_material():
    m, nt, out = material("Emitter", 4)
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (1.0, 0.55, 0.15, 1.0)
    e.inputs["Strength"].default_value = 4.0
    nt.links.new(e.outputs["Emission"], out.inputs["Surface"])
    return m


def add_object(op, name, pass_index, mat, **kw):
    op(**kw)
    ob = bpy.context.active_object
    ob.name = name
    ob.pass_index = pass_index
    ob.data.materials.append(mat)
    return ob


def build(a):
    scene = bpy.context.scene
    clear_scene()

    floor = add_object(bpy.ops.mesh.primitive_plane_add, "Floor", 1, floor_material(a.checker_scale),
                       size=8.0, location=(0.0, 0.0, 0.0))
    sphere = add_object(bpy.ops.mesh.primitive_uv_sphere_add, "GlassSphere", 2, glass_material(a.ior),
                        segments=64, ring_count=32, radius=0.6, location=(0.0, 0.0, 0.6))
    bpy.ops.object.shade_smooth()
    add_object(bpy.ops.mesh.primitive_cube_add, "RedCube", 3, cube_material(),
               size=0.7, location=(1.25, 0.75, 0.35), rotation=(0.0, 0.0, 0.5))
    tile = add_object(bpy.ops.mesh.primitive_plane_add, "EmitterTile", 4, emissive_material(),
                      size=0.3, location=(-1.2, 0.9, 0.01))
    del floor, sphere

    # Lights. Cycles' point light "power" is in watts.
    key_data = bpy.data.lights.new("Key", type="POINT")
    key_data.energy = 400.0 * a.key_scale
    key_data.shadow_soft_size = 0.02
    key_data.color = (1.0, 0.95, 0.85)
    key = bpy.data.objects.new("Key", key_data)
    key.location = (-0.9, -0.4, 2.4)
    scene.collection.objects.link(key)

    fill_data = bpy.data.lights.new("Fill", type="AREA")
    fill_data.energy = 60.0
    fill_data.size = 2.5
    fill_data.color = (0.85, 0.9, 1.0)
    fill = bpy.data.objects.new("Fill", fill_data)
    fill.location = (2.5, -2.5, 3.0)
    fill.rotation_euler = (0.75, 0.0, 0.78)
    scene.collection.objects.link(fill)

    world = bpy.data.worlds.new("Sky") if scene.world is None else scene.world
    scene.world = world
    world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.45, 0.6, 0.9, 1.0)
    bg.inputs["Strength"].default_value = 0.25

    # Camera.
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens = 40.0
    cam = bpy.data.objects.new("Camera", cam_data)
    cam.location = (0.0, -4.6, 2.3)
    cam.rotation_euler = (1.17, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam

    # Light groups (Cycles 3.2+).
    vl = scene.view_layers[0]
    for name in ("key", "fill", "sky"):
        vl.lightgroups.add(name=name)
    key.lightgroup = "key"
    fill.lightgroup = "fill"
    tile.lightgroup = "fill"
    world.lightgroup = "sky"

    # Render settings.
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y = a.res
    r.resolution_percentage = 100
    r.film_transparent = True
    r.use_border = False
    r.threads_mode = "FIXED" if a.threads > 0 else "AUTO"
    if a.threads > 0:
        r.threads = a.threads
    r.use_persistent_data = False

    c = scene.cycles
    c.device = "CPU"
    c.samples = a.spp
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.seed = a.seed
    c.use_animated_seed = False
    c.sample_clamp_direct = a.clamp_direct      # 0 (the default): no clamping, keep the fireflies
    c.sample_clamp_indirect = a.clamp_indirect
    c.caustics_reflective = True
    c.caustics_refractive = True
    c.blur_glossy = 0.0             # "Filter Glossy" off
    c.max_bounces = 12
    c.diffuse_bounces = 4
    c.glossy_bounces = 6
    c.transmission_bounces = 12
    c.transparent_max_bounces = 8
    c.volume_bounces = 0
    if hasattr(c, "film_transparent_glass"):
        c.film_transparent_glass = False
    if hasattr(c, "use_light_tree"):  # 3.5+
        c.use_light_tree = False

    # Passes.
    vl.use_pass_combined = True
    vl.use_pass_z = True
    vl.use_pass_mist = False
    vl.use_pass_normal = True
    vl.use_pass_position = True
    vl.use_pass_uv = True
    vl.use_pass_vector = True       # static scene: zero, but the channels exist
    vl.use_pass_object_index = True
    vl.use_pass_material_index = True
    for kind in ("diffuse", "glossy", "transmission"):
        for part in ("direct", "indirect", "color"):
            setattr(vl, "use_pass_%s_%s" % (kind, part), True)
    vl.use_pass_emit = True
    vl.use_pass_environment = True
    vl.use_pass_ambient_occlusion = False
    vl.cycles.denoising_store_passes = True
    vl.use_pass_cryptomatte_object = True
    vl.use_pass_cryptomatte_material = False
    vl.use_pass_cryptomatte_asset = False
    vl.pass_cryptomatte_depth = 6

    # Output: one multilayer EXR, float32, ZIP.
    im = r.image_settings
    im.file_format = "OPEN_EXR_MULTILAYER"
    im.color_depth = "32"
    im.exr_codec = "ZIP"
    im.color_mode = "RGBA"
    r.use_file_extension = False
    r.use_overwrite = True
    r.use_stamp = False             # no burnt-in stamp; metadata only
    r.use_stamp_note = bool(a.note)
    r.stamp_note_text = a.note
    r.filepath = os.path.abspath(a.out)
    scene.frame_current = 1


def main():
    a = parse_args()
    out = a.out
    a.out = out.replace("{seed}", str(a.seed))
    build(a)
    scene = bpy.context.scene
    # Seeds after the first re-render the built scene with another seed: Blender's start-up and
    # the scene's construction (about 1.5 s) are paid once, and each file is what a process of
    # its own writes (the scene does not depend on the seed).
    for seed in range(a.seed, a.seed + a.count):
        path = out.replace("{seed}", str(seed))
        scene.cycles.seed = seed
        scene.render.filepath = os.path.abspath(path)
        scene.render.stamp_note_text = a.note.replace("{seed}", str(seed))
        os.makedirs(os.path.dirname(os.path.abspath(path)) or ".", exist_ok=True)
        t0 = time.monotonic()
        bpy.ops.render.render(write_still=True)
        if not os.path.isfile(os.path.abspath(path)):
            raise RuntimeError("Cycles did not write " + path)
        print("cycles_caustic: wrote %s (seed %d, %d spp, %dx%d, key x%g, ior %g, checker %g, "
              "clamp %g/%g) in %.2f s"
              % (path, seed, a.spp, a.res[0], a.res[1], a.key_scale, a.ior, a.checker_scale,
                 a.clamp_direct, a.clamp_indirect, time.monotonic() - t0))


main()
