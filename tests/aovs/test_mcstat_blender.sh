#!/usr/bin/env bash
# mcstat-blender as a user gets it (cmake --install, component blender) with the installed Blender,
# no mocks (docs/ingest.md, "Seeds"): tiny renders (32x24, 4 spp) of the caustic scene and of a
# .blend saved from Blender's factory scene (adaptive sampling, a clamp and denoising on, which
# the template turns off), each file's seed in its stamp note; --ingest records those seeds,
# agrees with the names through :seed=, and refuses a second render of one seed and a renamed file.
# Last, the fact docs/ingest.md states: Blender 3.4 writes no metadata that tells adaptive
# sampling or a clamp (the factory scene's EXR has the same attributes as the template's).
#
#   tests/aovs/test_mcstat_blender.sh MCSTAT_EXE CMAKE_EXE BUILD_DIR WORK_DIR
#
# WORK_DIR is emptied first and removed when the test passes. About 15 s on 2 cores (7 Blender runs).
set -euo pipefail
[[ $# -eq 4 ]] || { sed -n '10p' "$0" | sed 's/^# *//' >&2; exit 2; }
mcstat=$1 cmake=$2 build=$3 work=$4
fail() { echo "test_mcstat_blender: FAILED: $*" >&2; exit 1; }
# Fail, not skip (as test_cycles_ingest.sh): Blender is part of what is tested.
command -v blender >/dev/null 2>&1 ||
  fail "Blender is not installed; scripts/install-deps.sh installs it"
rm -rf "$work"
mkdir -p "$work"
cd "$work"

# 1. Installed as a user installs it: the script and its template, nothing from the source tree.
"$cmake" --install "$build" --prefix "$work/prefix" --component blender >install.log ||
  { cat install.log >&2; fail "cmake --install --component blender"; }
helper=$work/prefix/bin/mcstat-blender
[[ -x $helper ]] || fail "$helper not installed"
[[ -f $work/prefix/share/mcstat/blender/cycles_seed.py ]] || fail "the template is not installed"

# A name without {seed} is refused before Blender starts.
if "$helper" --seeds 2 --spp 4 -o 'x.exr' 2>err.txt; then fail "-o without {seed} accepted"; fi
grep -q "must hold {seed} once" err.txt || { cat err.txt >&2; fail "-o without {seed}: message"; }

# 2. The caustic scene (no .blend), seeds 1 and 2.
"$helper" --seeds 2 --spp 4 --res 32 24 -o 'caustic/seed_{seed}.exr' >caustic.log 2>&1 ||
  { cat caustic.log >&2; fail "mcstat-blender (caustic scene)"; }
ls caustic/seed_1.exr caustic/seed_2.exr >/dev/null
[[ -z $(find caustic -name '.*') ]] || fail "a temporary file was left in caustic/"
"$mcstat" --ingest 'caustic/seed_*.exr' -o caustic.mcstat
"$mcstat" caustic.mcstat --info >info.txt
grep -q "seeds 1,2$" info.txt || { cat info.txt >&2; fail "caustic: seeds 1,2 expected"; }
grep -q "M = 2 sub-buffers, spp = 8" info.txt || { cat info.txt >&2; fail "caustic: M = 2, 8 spp"; }

# 3. A .blend: Blender's factory scene saved as it is (Cycles engine set, nothing else).
blender -b --factory-startup -noaudio --python-exit-code 1 --python-expr \
  "import bpy; bpy.context.scene.render.engine = 'CYCLES'; bpy.ops.wm.save_as_mainfile(filepath='$work/scene.blend')" \
  >blend.log 2>&1 || { tail -n 20 blend.log >&2; fail "saving scene.blend"; }
"$helper" scene.blend --seeds 2 --first 3 --spp 4 --res 32 24 -o 'blend/b_{seed}.exr' >b.log 2>&1 ||
  { cat b.log >&2; fail "mcstat-blender scene.blend"; }
oiiotool --info -v blend/b_3.exr >b3.txt
grep -q 'Note: "seed=3 frame=1 cycles_seed=1003"' b3.txt || { cat b3.txt >&2; fail "b_3.exr: Note"; }
grep -q 'cycles.ViewLayer.samples: "4"' b3.txt || { cat b3.txt >&2; fail "b_3.exr: samples"; }
# The seeds from the notes, and the same through the names.
"$mcstat" --ingest 'blend/b_*.exr' --info >info.txt
grep -q "seeds 3,4$" info.txt || { cat info.txt >&2; fail "blend: seeds 3,4 expected"; }
"$mcstat" --ingest:seed='b_{seed}.exr' 'blend/b_*.exr' --info >info.txt
grep -q "seeds 3,4$" info.txt || { cat info.txt >&2; fail "blend with :seed=: seeds 3,4 expected"; }

# 4. Seed 3 again at 8 spp: other pixels, the same first 4 samples. Refused by its seed (the
# inputs in name order: again/ first).
"$helper" scene.blend --seeds 1 --first 3 --spp 8 --res 32 24 -o 'again/b_{seed}.exr' >a.log 2>&1 ||
  { cat a.log >&2; fail "mcstat-blender seed 3 again"; }
if "$mcstat" --ingest 'blend/b_3.exr,again/b_3.exr' -o dup.mcstat 2>err.txt; then
  fail "two renders of seed 3 accepted"
fi
[[ $(wc -l <err.txt) -eq 1 ]] || { cat err.txt >&2; fail "two renders of seed 3: one line expected"; }
grep -q "again/b_3.exr and blend/b_3.exr are both renders of seed 3 (by their Note stamps)" err.txt ||
  { cat err.txt >&2; fail "two renders of seed 3: message"; }
[[ ! -e dup.mcstat ]] || fail "dup.mcstat written"

# 5. A renamed file: its name and its note disagree.
mkdir -p renamed && cp blend/b_4.exr renamed/b_7.exr
if "$mcstat" --ingest:seed='b_{seed}.exr' 'blend/b_3.exr,renamed/b_7.exr' --info 2>err.txt >/dev/null; then
  fail "a renamed render accepted"
fi
grep -q "renamed/b_7.exr: its name says seed 7 (seed=b_{seed}.exr) but its Note says seed 4" err.txt ||
  { cat err.txt >&2; fail "renamed render: message"; }

# 6. What Blender 3.4 writes of adaptive sampling and clamping: nothing. The factory scene's own
# settings (adaptive sampling on, indirect clamp 10; denoising off: Debian's Blender has no OIDN)
# give the same attribute names as the template's render with both off.
blender -b scene.blend --factory-startup -noaudio --python-exit-code 1 --python-expr "
import bpy
s = bpy.context.scene
c = s.cycles
assert c.use_adaptive_sampling and c.sample_clamp_indirect == 10.0, (c.use_adaptive_sampling, c.sample_clamp_indirect)
c.use_denoising = False
c.samples = 4
r = s.render
r.resolution_x, r.resolution_y, r.resolution_percentage = 32, 24, 100
r.image_settings.file_format = 'OPEN_EXR_MULTILAYER'
r.image_settings.color_depth = '32'
r.use_file_extension = False
r.filepath = '$work/factory.exr'
bpy.ops.render.render(write_still=True)
" >factory.log 2>&1 || { tail -n 20 factory.log >&2; fail "factory render"; }
# The attribute names oiiotool shows ("    NAME: VALUE"), the note aside.
keys() { oiiotool --info -v "$1" | awk -F': ' '/^    [^ ]/ { sub(/^ +/, "", $1); print $1 }' |
         grep -v '^Note$' | sort; }
keys factory.exr >factory.keys
keys blend/b_3.exr >template.keys
grep -qx "cycles.ViewLayer.samples" factory.keys || { cat factory.keys >&2; fail "no attributes read"; }
diff factory.keys template.keys >keys.diff ||
  { cat keys.diff >&2; fail "Blender now writes attributes that differ with adaptive sampling or a clamp: docs/ingest.md says it writes none; mcstat could read them"; }
grep -qi "adaptive\|clamp" factory.keys && fail "an attribute names adaptive sampling or a clamp"

echo "test_mcstat_blender: passed in ${SECONDS} s"
cd / && rm -rf "$work"
