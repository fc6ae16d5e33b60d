#!/usr/bin/env bash
# docs/compact.md's tables and picture (never part of the test suite): per scene, the bytes per
# pixel of one plain render, the full statistics file, adaptive M (grow, pilot) and the compact
# file; the fraction of pixels that keep their buffers; every per-pixel estimator's relMSE and
# firefly count from the full and the compact file against a reference; --gmon's time on both;
# and relMSE against bytes per pixel drawn by mcstat itself (--qualityplot:x=bytes).
#
#   scripts/compact_report.sh                 fixture scenes default and caustic
#   CYCLES=DIR scripts/compact_report.sh      also DIR/seed_*.exr, renders of one Cycles scene
#                                             (tests/aovs/render_cycles_seeds.sh), with CYCLES_REF
#                                             a reference EXR of it when there is one
#
# Environment: BUILD (default build), OUT (default out/compact), SPP (default 1000), M (default
# 21), REF_SPP (default 16384; rendered once, reused), SCENES (default "default caustic").
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
OUT=${OUT:-out/compact}
SPP=${SPP:-1000}
M=${M:-21}
REF_SPP=${REF_SPP:-16384}
SCENES=${SCENES:-default caustic}
mcstat=$BUILD/oiiotool-ext/mcstat
render=$BUILD/render-fixture/mcstat-render
ests=mean,mon,gmon,gmonb,tmpe,myriad,meridian
mkdir -p "$OUT"

bpp() {  # bytes per pixel of file $1 for $2 pixels
  awk -v b="$(stat -c %s "$1")" -v p="$2" 'BEGIN { printf "%.1f", b / p }'
}
seconds() {  # wall seconds of a command, median of 3
  local t=() i
  for i in 1 2 3; do
    /usr/bin/time -f "%e" -o "$OUT/time.txt" "$@" >/dev/null 2>&1
    t+=("$(cat "$OUT/time.txt")")
  done
  printf '%s\n' "${t[@]}" | sort -n | sed -n 2p
}

# report NAME FULL COMPACT REF PIXELS PLAIN [ADAPTIVE_GROW ADAPTIVE_PILOT]
report() {
  local name=$1 full=$2 small=$3 ref=$4 px=$5 plain=$6 grow=${7:-} pilot=${8:-}
  echo "== $name: $px pixels, M = $M =="
  "$mcstat" "$small" --info | sed -n 's/^  compact: \([0-9]\)/  kept: \1/p'
  printf "  bytes per pixel: one plain render %s, full %s, compact %s" \
    "$(bpp "$plain" "$px")" "$(bpp "$full" "$px")" "$(bpp "$small" "$px")"
  [ -n "$grow" ] && printf ", adaptive M grow %s, pilot %s" "$(bpp "$grow" "$px")" "$(bpp "$pilot" "$px")"
  printf "\n  compact / full: %s\n" "$(awk -v a="$(stat -c %s "$small")" -v b="$(stat -c %s "$full")" 'BEGIN { printf "%.3f", a / b }')"
  local tf ts
  tf=$(seconds "$mcstat" "$full" --gmon -o "$OUT/o.exr")
  ts=$(seconds "$mcstat" "$small" --gmon -o "$OUT/o.exr")
  echo "  --gmon wall: full $tf s, compact $ts s"
  if [ -n "$ref" ]; then
    local files=("$full" "$small")
    [ -n "$grow" ] && files+=("$grow" "$pilot")
    "$mcstat" "${files[@]}" --qualityplot:x=bytes:estimators=$ests:csv="$OUT/$name.csv" "$ref" \
      -o "$OUT/$name-trade.png" >/dev/null
    # The CSV holds one row per estimator and file, the files in the order given.
    awk -F, -v n="$(echo "$ests" | tr ',' '\n' | wc -l)" -v nf="${#files[@]}" 'NR > 1 {
        f = int((NR - 2) / n); e = $3; if (f == 0) names[++k] = e
        rel[e, f] = $4; ff[e, f] = $7 }
      END {
        split("full compact adaptive-grow adaptive-pilot", label, " ")
        printf "  %-9s |", "relMSE"; for (f = 0; f < nf; f++) printf " %14s", label[f + 1]
        printf " | fireflies:"; for (f = 0; f < nf; f++) printf " %14s", label[f + 1]; printf "\n"
        for (i = 1; i <= k; i++) { e = names[i]; printf "  %-9s |", e
          for (f = 0; f < nf; f++) printf " %14.5g", rel[e, f]
          printf " |           "; for (f = 0; f < nf; f++) printf " %14d", ff[e, f]; printf "\n" } }' \
      "$OUT/$name.csv"
    echo "  picture: $OUT/$name-trade.png"
  fi
  echo
}

for scene in $SCENES; do
  full=$OUT/$scene-${SPP}spp-M$M.mcstat
  ref=$OUT/$scene-reference-${REF_SPP}spp.exr
  [ -f "$full" ] || "$render" --scene "$scene" --spp "$SPP" --M "$M" --seed 1 --quiet -o "$full"
  [ -f "$ref" ] || "$render" --scene "$scene" --spp "$REF_SPP" --seed 4242 --reference --quiet -o "$ref"
  grow=$OUT/$scene-adaptive-grow.mcstat pilot=$OUT/$scene-adaptive-pilot.mcstat
  [ -f "$grow" ] || "$render" --scene "$scene" --spp "$SPP" --adaptive-m --m-max "$M" --seed 1 --quiet -o "$grow"
  [ -f "$pilot" ] || "$render" --scene "$scene" --spp "$SPP" --adaptive-m --m-max "$M" --m-strategy pilot --seed 1 --quiet -o "$pilot"
  small=$OUT/$scene-compact.mcstat
  "$mcstat" "$full" --compact -o "$small"
  # One plain render: the same samples as a plain EXR of the mean (float, ZIP), the file a renderer
  # would have written instead.
  plain=$OUT/$scene-plain.exr
  "$mcstat" "$full" --mean -o "$plain"
  read -r w h < <("$mcstat" "$full" --info | sed -n 's/^  size \([0-9]*\) x \([0-9]*\).*/\1 \2/p')
  report "$scene" "$full" "$small" "$ref" $((w * h)) "$plain" "$grow" "$pilot"
done

if [ -n "${CYCLES:-}" ]; then
  full=$OUT/cycles-full.mcstat small=$OUT/cycles-compact.mcstat
  "$mcstat" --ingest "$CYCLES/seed_*.exr" -o "$full"
  "$mcstat" "$full" --compact -o "$small"
  one=$(ls "$CYCLES"/seed_*.exr | head -1)
  read -r w h < <("$mcstat" "$full" --info | sed -n 's/^  size \([0-9]*\) x \([0-9]*\).*/\1 \2/p')
  report cycles "$full" "$small" "${CYCLES_REF:-}" $((w * h)) "$one"
  echo "  one seed's EXR ($one) x 2: $(( $(stat -c %s "$one") * 2 )) bytes; compact: $(stat -c %s "$small")"
fi
