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
  "$render" --scene default --spp "$SPP" --M "$M" --seed 1 --aovs -o "$stats"
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
echo "AOVs: G-MoN's weights from the beauty applied to alpha and the six light-path AOVs (docs/aovs.md)"
# gmon.exr holds the beauty, A and every AOV; rebuild the beauty from the AOVs with stock oiiotool
# and show the parts, their sum and its relative difference from the robust beauty.
a=$OUT/aovs; mkdir -p "$a"
g=$OUT/gmon.exr
layer() { oiiotool "$g" --ch "$1.R,$1.G,$1.B" --chnames R,G,B "$g" --ch "$2.R,$2.G,$2.B" --chnames R,G,B --add -o "$3"; }
layer emission background "$a/emitted.exr"
layer diffuse_direct specular_direct "$a/direct.exr"
layer diffuse_indirect specular_indirect "$a/indirect.exr"
oiiotool "$a/emitted.exr" "$a/direct.exr" --add "$a/indirect.exr" --add -o "$a/sum.exr"
oiiotool "$g" --ch R,G,B -o "$a/beauty.exr"
oiiotool "$a/sum.exr" "$a/beauty.exr" --sub --abs "$a/beauty.exr" --addc 1e-6 --div --ch relres=R \
  --addc 1e-12 -o "$a/relres.exr"
font=/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf
tiles=()
for t in beauty:"G-MoN beauty" emitted:"emission + background" direct:"direct (diffuse + specular)" \
         indirect:"indirect (the caustic)" sum:"sum of the six AOVs"; do
  "$mcstat" "$a/${t%%:*}.exr" -o "$a/${t%%:*}.png"
  tiles+=("$a/${t%%:*}.png" --text:x=4:y=14:size=11:color=1,1,1:font=$font "${t#*:}")
done
oiiotool "${tiles[@]}" --mosaic:pad=2 5x1 -o "$OUT/aovs.png"
"$mcstat" "$a/relres.exr" --heatmap:channel=relres:log=1 -o "$OUT/aovs-residual.png"
oiiotool "$a/relres.exr" --mulc 1e9 --printstats |
  awk '/Stats Max/ { printf "  largest |sum of the AOVs - beauty| / beauty: %.2g (float rounding)\n", $3 * 1e-9 }'

echo
echo "Review pictures"
"$mcstat" "$stats" --contactsheet:estimators=mean,gmon "$ref" -o "$OUT/contactsheet.png" >/dev/null
"$mcstat" "$stats" --gmon --errormap "$ref" --heatmap -o "$OUT/heatmap-relerr.png"
"$mcstat" "$stats" --mean --errormap "$ref" --heatmap:channel=firefly -o "$OUT/heatmap-fireflies-mean.png"
"$mcstat" "$stats" --gmon:diag=1 --heatmap:channel=gini -o "$OUT/heatmap-gini.png"
"$mcstat" "$stats" --gmon:diag=1 --heatmap:channel=kept -o "$OUT/heatmap-kept.png"
"$mcstat" "$stats" --qualityplot:estimators=mean,mon,gmon:csv="$OUT/quality.csv" "$ref" \
  -o "$OUT/quality.png" >/dev/null

# Noise-aware comparison (docs/compare.md): two renders of the default scene with other seeds are
# the same image up to their noise (exit status 0); the light 2 % brighter is found (exit 2).
echo
echo "Compare: the default scene, 256 spp, M = 16: other seeds, then the light 2 % brighter"
c=$OUT/compare; mkdir -p "$c"
for v in a:default:11 b:default:12 light:render-fixture/examples/default-light-1.02.json:12; do
  IFS=: read -r name scene seed <<<"$v"
  f=$c/$name.mcstat
  if stale "$f" || [ "$scene" -nt "$f" ]; then
    "$render" --scene "$scene" --spp 256 --M 16 --seed "$seed" --quiet -o "$f"
  fi
done
"$mcstat" "$c/a.mcstat" "$c/b.mcstat" --compare:test=yuen --heatmap -o "$OUT/compare-same.png"
"$mcstat" "$c/a.mcstat" "$c/light.mcstat" --compare:test=yuen -o "$c/maps.exr" \
  --heatmap:channel=tile.z -o "$OUT/compare-light.png" || [ $? -eq 2 ]

echo
echo "demo: images in $OUT/ (mean, mon, gmonb, gmon, ingested-gmon, reference; .exr scene-linear, .png sRGB;"
echo "      contactsheet.png, heatmap-{relerr,fireflies-mean,gini,kept}.png, quality.png + quality.csv,"
echo "      aovs.png and aovs-residual.png: the robust AOVs and how closely they sum to the robust beauty;"
echo "      compare-{same,light}.png: --compare's z-score maps with their verdicts)"
