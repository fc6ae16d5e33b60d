#!/usr/bin/env bash
# The main job: install what is missing, build, render the built-in default scene into a statistics
# file, write mean and robust images (EXR + PNG) and print their metrics against a reference; then
# the same from renderer output (one plain EXR per seed, ingested); then the review pictures.
# Idempotent: renders are redone only when the renderer was rebuilt or an output is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

SPP=${MCSTAT_DEMO_SPP:-1000}          # samples per pixel of the statistics file
M=${MCSTAT_DEMO_M:-21}                # sub-buffers (the paper finds M in 11..25 works best)
REF_SPP=${MCSTAT_DEMO_REF_SPP:-65536} # reference: mean only, independent seed
SEEDS=${MCSTAT_DEMO_SEEDS:-9}         # ingest demo: renders of one image, one plain EXR per seed
SEED_SPP=${MCSTAT_DEMO_SEED_SPP:-64}  # samples per pixel of each of them
OUT=out/demo

scripts/install-deps.sh
# Everything the README shows after this command: the tool, the renderer and the OIIO plugin.
MCSTAT_TARGETS="mcstat mcstat-render mcstat_oiio_plugin" scripts/build.sh build
render=build/render-fixture/mcstat-render
mcstat=build/oiiotool-ext/mcstat
mkdir -p "$OUT" "$OUT/seeds"

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

# Renderer output in: a handful of renders of the same image, one plain EXR per seed, as any
# renderer writes them (docs/ingest.md), become one statistics file with one command.
echo
echo "Ingest: $SEEDS renders of $SEED_SPP spp, one plain EXR per seed ($OUT/seeds/)"
for s in $(seq "$SEEDS"); do
  f=$OUT/seeds/default_s${s}_${SEED_SPP}spp.exr
  if stale "$f"; then "$render" --scene default --spp "$SEED_SPP" --seed $((100 + s)) --reference --quiet -o "$f"; fi
done
"$mcstat" --ingest "$OUT/seeds/default_s*_${SEED_SPP}spp.exr" -o "$OUT/ingested.mcstat" \
  --dup --mean --diff "$ref" --pop --gmon -o "$OUT/ingested-gmon.exr" -o "$OUT/ingested-gmon.png" \
  --diff "$ref"

# Pictures for review tools (docs/review.md): contact sheet, heatmaps, quality against spp.
echo
echo "Review pictures"
"$mcstat" "$stats" --contactsheet:estimators=mean,gmon "$ref" -o "$OUT/contactsheet.png" >/dev/null
"$mcstat" "$stats" --gmon --errormap "$ref" --heatmap -o "$OUT/heatmap-relerr.png"
"$mcstat" "$stats" --mean --errormap "$ref" --heatmap:channel=firefly -o "$OUT/heatmap-fireflies-mean.png"
"$mcstat" "$stats" --gmon:diag=1 --heatmap:channel=gini -o "$OUT/heatmap-gini.png"
"$mcstat" "$stats" --gmon:diag=1 --heatmap:channel=kept -o "$OUT/heatmap-kept.png"
"$mcstat" "$stats" --qualityplot:estimators=mean,mon,gmon:csv="$OUT/quality.csv" "$ref" \
  -o "$OUT/quality.png" >/dev/null
echo
echo "demo: images in $OUT/ (mean, mon, gmonb, gmon, ingested-gmon, reference; .exr scene-linear, .png sRGB;"
echo "      contactsheet.png, heatmap-{relerr,fireflies-mean,gini,kept}.png, quality.png + quality.csv)"
