#!/usr/bin/env bash
# Real Cycles renders through mcstat (docs/aovs.md, "Done when"): 21 seed renders of
# cycles_caustic.py (light groups key/fill/sky, every light-path pass, Cryptomatte, IndexOB/MA,
# transparent film) become one statistics file with one --ingest; G-MoN then writes one EXR with
# every input channel, and check_robust_aovs.py asserts its guarantees against a reference.
#
#   tests/aovs/test_cycles_ingest.sh MCSTAT_EXE WORK_DIR
#
# Small on purpose (64x48, 16 spp per seed, a 2,048-spp reference): about 30 s on 2 cores.
set -euo pipefail
mcstat=$1 work=$2
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
if ! command -v blender >/dev/null 2>&1; then
  echo "test_cycles_ingest: Blender is not installed; scripts/install-deps.sh installs it" >&2
  exit 1
fi
rm -rf "$work"
mkdir -p "$work"
cd "$work"
"$here/render_cycles_seeds.sh" -n 21 -o seeds --spp 16 --res 64 48 >/dev/null
blender -b --factory-startup -noaudio --python-exit-code 1 --python "$here/cycles_caustic.py" -- \
  --out ref.exr --seed 1000 --spp 2048 --res 64 48 >ref.log 2>&1 ||
  { tail -n 20 ref.log >&2; exit 1; }
"$mcstat" --ingest 'seeds/seed_*.exr' -o shot.mcstat --dup --gmon -o gmon.exr --pop --mean -o mean.exr
"$mcstat" --ingest:aovs=0 'seeds/seed_*.exr' --gmon -o gmon-beauty.exr 2>/dev/null
/usr/bin/python3 "$here/check_robust_aovs.py" seeds gmon.exr gmon-beauty.exr mean.exr ref.exr
cd / && rm -rf "$work"
