#!/usr/bin/env bash
# The main job: install what is missing, build, render the built-in default scene into a statistics
# file, write mean and robust images (EXR + PNG) and print their metrics against a reference.
# Idempotent: renders are redone only when the renderer was rebuilt or an output is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

SPP=${MCSTAT_DEMO_SPP:-1000}          # samples per pixel of the statistics file
M=${MCSTAT_DEMO_M:-21}                # sub-buffers (the paper finds M in 11..25 works best)
REF_SPP=${MCSTAT_DEMO_REF_SPP:-65536} # reference: mean only, independent seed
OUT=out/demo

scripts/install-deps.sh
MCSTAT_TARGETS="mcstat mcstat-render" scripts/build.sh build
render=build/render-fixture/mcstat-render
mcstat=build/oiiotool-ext/mcstat
mkdir -p "$OUT"

# stale FILE: true when FILE is missing or older than the renderer binary
stale() { [ ! -f "$1" ] || [ "$render" -nt "$1" ]; }

stats=$OUT/default-${SPP}spp-M${M}.mcstat
ref=$OUT/reference-${REF_SPP}spp.exr
if stale "$stats"; then
  echo "demo: rendering the default scene, $SPP spp, M = $M"
  "$render" --scene default --spp "$SPP" --M "$M" --seed 1 -o "$stats"
fi
if stale "$ref"; then
  echo "demo: rendering the reference, $REF_SPP spp (once; later runs reuse it)"
  "$render" --scene default --spp "$REF_SPP" --seed 4242 --reference -o "$ref"
fi
"$mcstat" "$ref" -o "$OUT/reference.png"

echo
"$mcstat" "$stats" --info
echo
echo "Against the reference ($REF_SPP spp). Firefly pixel: luminance > 2x the reference and > 0.1 (a tenth of display white) above it."
args=()
for est in mean mon gmonb gmon; do
  args+=(--dup "--$est" -o "$OUT/$est.exr" -o "$OUT/$est.png" --diff "$ref" --pop)
done
"$mcstat" "$stats" "${args[@]}"
echo
echo "demo: images in $OUT/ (mean, mon, gmonb, gmon, reference; .exr scene-linear, .png sRGB)"
