#!/usr/bin/env bash
# docs/benchmarks.md, "Robust at both ends" (issue 38; never part of the test suite): on every
# fixture scene, each estimator whose default changed, old default against new (myriad and
# meridian: scale=rel, the thesis' 0.05 x range, against scale=hampel; G-MoN and G-MoN_b:
# gini=shift against gini=abs): relMSE, firefly pixels and nbias from `mcstat --diff` against a
# reference render. Quality only, no timing. Then negative lobes (LOBES=0 skips): M seed renders of
# the caustic scene, each upscaled 2x with a Lanczos-3 filter (oiiotool --resize), which rings
# below zero around every firefly as a Mitchell or Lanczos pixel filter does, ingested into one
# statistics file and compared with the reference upscaled the same way.
#
# Environment: BUILD (default build), OUT (default out/extremes), RES (default "64 48"),
# CONFIGS (default "256:8 1024:21", spp:M pairs), REF_SPP (default 8192; rendered once, reused),
# SCENES (default: every built-in scene; empty: none, e.g. for the negative lobes alone).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
OUT=${OUT:-out/extremes}
RES=${RES:-64 48}
CONFIGS=${CONFIGS:-256:8 1024:21}
REF_SPP=${REF_SPP:-8192}
SCENES=${SCENES-arealight caustic default dof furnace motion texture tiny}
LOBES=${LOBES:-1}
mcstat=$BUILD/oiiotool-ext/mcstat
render=$BUILD/render-fixture/mcstat-render
mkdir -p "$OUT"
read -r W H <<<"$RES"

# metrics FILE OP REF: "relMSE fireflies nbias" of --OP against REF
metrics() {
  "$mcstat" "$1" "--$2" --diff "$3" |
    awk '{ for (i = 1; i < NF; i++) { if ($i == "relMSE") r = $(i + 1); if ($i == "fireflies") f = $(i + 1)
           if ($i == "nbias") b = $(i + 1) } } END { printf "%s %s %s", r, f, b }'
}

printf "%-9s %-8s %-9s | %-28s | %-28s\n" scene spp/M estimator "old: relMSE fireflies nbias" \
  "new: relMSE fireflies nbias"
for scene in $SCENES; do
  ref=$OUT/$scene-${W}x$H-reference-${REF_SPP}spp.exr
  [ -f "$ref" ] || "$render" --scene "$scene" --res "$W" "$H" --spp "$REF_SPP" --seed 4242 \
    --reference --quiet -o "$ref"
  for cfg in $CONFIGS; do
    spp=${cfg%%:*} M=${cfg##*:}
    f=$OUT/$scene-${W}x$H-${spp}spp-M$M.mcstat
    [ -f "$f" ] || "$render" --scene "$scene" --res "$W" "$H" --spp "$spp" --M "$M" --seed 1 \
      --quiet -o "$f"
    for pair in myriad:scale=rel,myriad meridian:scale=rel,meridian gmon:gini=shift,gmon \
      gmonb:gini=shift,gmonb; do
      old=${pair%%,*} new=${pair##*,}
      printf "%-9s %-8s %-9s | %-28s | %-28s\n" "$scene" "$spp/$M" "$new" \
        "$(metrics "$f" "$old" "$ref")" "$(metrics "$f" "$new" "$ref")"
    done
  done
done

[ "$LOBES" = 0 ] && exit 0
# Negative lobes: M = 8 seeds of 32 spp each (256 spp), Lanczos-3 2x.
ref=$OUT/caustic-${W}x$H-reference-${REF_SPP}spp.exr
[ -f "$ref" ] || "$render" --scene caustic --res "$W" "$H" --spp "$REF_SPP" --seed 4242 \
  --reference --quiet -o "$ref"
lz=$OUT/lanczos
mkdir -p "$lz"
oiiotool "$ref" --resize:filter=lanczos3 "$((2 * W))x$((2 * H))" -o "$lz/reference.exr"
for s in 1 2 3 4 5 6 7 8; do
  "$render" --scene caustic --res "$W" "$H" --spp 32 --seed "$s" --reference --quiet -o "$lz/render.exr"
  oiiotool "$lz/render.exr" --resize:filter=lanczos3 "$((2 * W))x$((2 * H))" -o "$lz/seed_$s.exr"
done
"$mcstat" --ingest "$lz/seed_*.exr" -o "$lz/lanczos.mcstat"
echo
echo "== negative lobes: caustic, 8 seeds x 32 spp, each Lanczos-3 upscaled to $((2 * W))x$((2 * H)), ingested (M = 8) =="
echo "   buffers below zero: $(oiiotool "$lz/seed_1.exr" --printstats 2>&1 | grep 'Stats Min' | sed 's/ *Stats //')"
for pair in gmon:gini=shift,gmon gmonb:gini=shift,gmonb myriad:scale=rel,myriad meridian:scale=rel,meridian \
  mon,mon mean,mean; do
  old=${pair%%,*} new=${pair##*,}
  printf "%-9s %-8s %-9s | %-28s | %-28s\n" lanczos "256/8" "$new" \
    "$(metrics "$lz/lanczos.mcstat" "$old" "$lz/reference.exr")" \
    "$(metrics "$lz/lanczos.mcstat" "$new" "$lz/reference.exr")"
done
