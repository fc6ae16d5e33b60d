"""One Blender/Cycles render of one (frame, seed) of a shot, as a farm task: a multilayer EXR.

  blender -b [SCENE.blend] --factory-startup -noaudio --python-exit-code 1 \
      -P farm/templates/cycles_seed.py -- --frame F --seed S --spp N --out PATH \
      [--res W H] [--threads N] [--seed-stride K]

With a .blend: that file's scene, camera, passes and light groups, at frame F (its animation).
Without one: the caustic test scene of tests/aovs/cycles_caustic.py (every light-path and data
pass, light groups, Cryptomatte; static, so frames differ by seed only).

The Cycles seed is F * K + S (K = --seed-stride, default 1000): every (frame, seed) of the shot
gets its own, and the seeds of one frame keep their order. Animated seed is off, adaptive sampling
and denoising are off, nothing is clamped, no stamp is burnt into the pixels (the statistics need
the raw samples). The output is one multilayer EXR, float32, ZIP, with Cycles' samples count in its
metadata and the stamp note "seed=S frame=F cycles_seed=C" (Blender writes it as the EXR attribute
`Note`; a note the .blend already has is kept before it), both of which `mcstat --ingest` reads: one
sub-buffer per file, recorded under seed S, and two files of one seed refused (docs/ingest.md).
farm/mcstat-blender runs this once per seed.
"""

import argparse
import os
import re
import runpy
import sys

import bpy

HERE = os.path.dirname(os.path.realpath(__file__))
# Installed (cmake --install): beside this file; in the source tree: the test suite's.
CAUSTIC = next((p for p in (os.path.join(HERE, "cycles_caustic.py"),
                            os.path.join(HERE, "..", "..", "tests", "aovs", "cycles_caustic.py"))
                if os.path.isfile(p)), os.path.join(HERE, "cycles_caustic.py"))


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="cycles_seed.py", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frame", type=int, required=True)
    p.add_argument("--seed", type=int, required=True, help="the shot's seed number of this task")
    p.add_argument("--spp", type=int, required=True, help="samples per pixel")
    p.add_argument("--out", required=True, help="output multilayer EXR")
    p.add_argument("--res", type=int, nargs=2, metavar=("W", "H"), help="override the image size")
    p.add_argument("--threads", type=int, default=0, help="render threads (0: all cores)")
    p.add_argument("--seed-stride", type=int, default=1000, help="Cycles seed = frame * K + seed")
    a = p.parse_args(argv)
    if a.spp < 1 or a.threads < 0 or a.seed < 0 or a.frame < 0 or a.seed_stride < 1:
        p.error("spp >= 1; frame, seed, threads >= 0; seed-stride >= 1")
    if a.seed >= a.seed_stride:
        p.error("--seed must be below --seed-stride (%d)" % a.seed_stride)
    return a


def seed_note(old, a, cycles_seed):
    """The stamp note: the .blend's own note without seed=, frame= or cycles_seed= tokens, then
    ours (mcstat --ingest refuses a note naming two seeds)."""
    kept = re.sub(r"(^|[\s,;])(seed|frame|cycles_seed)=\d+(?=$|[\s,;])", r"\1", old or "")
    kept = " ".join(kept.split())
    ours = "seed=%d frame=%d cycles_seed=%d" % (a.seed, a.frame, cycles_seed)
    return (kept + " " + ours) if kept else ours


def main():
    a = parse_args()
    cycles_seed = a.frame * a.seed_stride + a.seed
    out = os.path.abspath(a.out)
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    if not bpy.data.filepath:
        # No .blend given: the caustic scene, built and rendered by the test suite's script.
        res = a.res or (128, 96)
        sys.argv = [sys.argv[0], "--", "--out", out, "--seed", str(cycles_seed), "--spp", str(a.spp),
                    "--res", str(res[0]), str(res[1]), "--threads", str(a.threads),
                    "--note", seed_note("", a, cycles_seed)]
        runpy.run_path(CAUSTIC, run_name="__main__")
    else:
        scene = bpy.context.scene
        scene.frame_set(a.frame)
        r = scene.render
        r.engine = "CYCLES"
        if a.res:
            r.resolution_x, r.resolution_y = a.res
            r.resolution_percentage = 100
        r.threads_mode = "FIXED" if a.threads > 0 else "AUTO"
        if a.threads > 0:
            r.threads = a.threads
        c = scene.cycles
        c.samples = a.spp
        c.seed = cycles_seed
        c.use_animated_seed = False
        c.use_adaptive_sampling = False
        c.use_denoising = False
        c.sample_clamp_direct = 0.0
        c.sample_clamp_indirect = 0.0
        # The seed in the metadata (the EXR's `Note`), never burnt into the pixels.
        r.use_stamp = False
        r.stamp_note_text = seed_note(r.stamp_note_text if r.use_stamp_note else "", a, cycles_seed)
        r.use_stamp_note = True
        im = r.image_settings
        im.file_format = "OPEN_EXR_MULTILAYER"
        im.color_depth = "32"
        im.exr_codec = "ZIP"
        r.use_file_extension = False
        r.use_overwrite = True
        r.filepath = out
        bpy.ops.render.render(write_still=True)
    if not os.path.isfile(out):
        raise RuntimeError("Cycles did not write " + out)
    print("cycles_seed: frame %d, seed %d (Cycles seed %d), %d spp -> %s"
          % (a.frame, a.seed, cycles_seed, a.spp, out))


main()
