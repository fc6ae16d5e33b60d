#!/usr/bin/env bash
# Real Cycles renders through mcstat, no mocks (docs/aovs.md, "Real Cycles renders"): 21 seed
# renders of cycles_caustic.py (light groups key/fill/sky, every light-path pass, Cryptomatte,
# IndexOB/MA, transparent film) become one statistics file with one --ingest; G-MoN then writes one
# EXR with every input channel, and check_robust_aovs.py asserts docs/aovs.md's guarantees on it,
# against a reference render.
#
#   tests/aovs/test_cycles_ingest.sh MCSTAT_EXE WORK_DIR
#
# WORK_DIR is emptied first and removed when the test passes (kept for a look when it fails).
# Small on purpose (64x48, 16 spp per seed, a 2,048-spp reference): about 15 s on 2 cores. The
# 21 seeds render in one Blender process (--batch): started once per seed, Blender's start-up
# was most of the test (50 s).
set -euo pipefail
[[ $# -eq 2 ]] || { sed -n '8p' "$0" | sed 's/^# *//' >&2; exit 2; }
mcstat=$1 work=$2
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# Fail, not skip: a suite that silently skips its only real-renderer test proves nothing.
if ! command -v blender >/dev/null 2>&1; then
  echo "test_cycles_ingest: FAILED: Blender is not installed; scripts/install-deps.sh installs it" >&2
  exit 1
fi
rm -rf "$work"
mkdir -p "$work"
cd "$work"
"$here/render_cycles_seeds.sh" --batch -n 21 -o seeds --spp 16 --res 64 48 >/dev/null
# The reference: another seed, 128x the samples of one render, so its own noise is small.
blender -b --factory-startup -noaudio --python-exit-code 1 --python "$here/cycles_caustic.py" -- \
  --out ref.exr --seed 1000 --spp 2048 --res 64 48 >ref.log 2>&1 ||
  { tail -n 20 ref.log >&2; exit 1; }
"$mcstat" --ingest 'seeds/seed_*.exr' -o shot.mcstat --dup --gmon -o gmon.exr --pop --mean -o mean.exr
"$mcstat" shot.mcstat --gmon -o gmon-file.exr  # the statistics file alone must give the same image
# The beauty alone (mcstat warns that it leaves 78 channels out: asked for).
"$mcstat" --ingest:aovs=0 'seeds/seed_*.exr' --gmon -o gmon-beauty.exr
/usr/bin/python3 "$here/check_robust_aovs.py" seeds gmon.exr gmon-file.exr gmon-beauty.exr mean.exr ref.exr
# Compact (docs/compact.md), straight from the renders: G-MoN bit for bit the full file's, every
# channel; the same image by --compare; smaller.
"$mcstat" --ingest 'seeds/seed_*.exr' --compact -o small.mcstat --gmon -o gmon-small.exr
idiff -fail 0 -warn 0 gmon-file.exr gmon-small.exr >idiff.log ||
  { cat idiff.log >&2; echo "test_cycles_ingest: G-MoN of the compact file differs" >&2; exit 1; }
"$mcstat" shot.mcstat small.mcstat --compare >compare.log ||
  { cat compare.log >&2; echo "test_cycles_ingest: --compare full vs compact failed" >&2; exit 1; }
full=$(stat -c %s shot.mcstat) small=$(stat -c %s small.mcstat)
# At 16 spp per seed 22 % of these pixels keep their buffers (docs/compact.md: 5 % at 64 spp).
(( small * 2 < full )) ||
  { echo "test_cycles_ingest: compact file $small bytes, full $full: not half" >&2; exit 1; }
echo "test_cycles_ingest: passed in ${SECONDS} s"
cd / && rm -rf "$work"
