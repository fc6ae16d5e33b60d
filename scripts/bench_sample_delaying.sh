#!/usr/bin/env bash
# Pajot et al. 2011 benchmark (docs/pajot.md; never part of the test suite). Prints three tables:
#  1. Render-time overhead of --online pajot:method=adr|rot|hybrid against the plain render at equal spp, medians
#     of REPS alternated runs, and peak memory (the paper: 5-10 %; our goal <= 5 %).
#  2. What the online state costs and does after 100 spp (paper Tables 1-4 in our terms): modes
#     per pixel (single, extended), bytes per pixel and image buffers (12 bytes each), samples
#     delayed.
#  3. Quality at equal spp (100, 1000, 10000) against a high-spp reference: mean, G-MoN, ADR, ROT,
#     hybrid: relMSE, SSIM, firefly pixels, energy lost (1 - sum Y / sum Y_ref).
# and draws docs/images/pajot_caustic.png (the caustic first delayed, then accepted).
# BUILD (default build) is the build directory measured; SKIP_BUILD=1 uses it as it is.
# Scenes: `default` (Cornell box, glass-sphere caustic fireflies) and `caustic` (a glass ball's
# caustic on a floor, rare early and real; section 4.3's progressiveness test).
set -euo pipefail
cd "$(dirname "$0")/.."
REPS=${REPS:-3}
QUALITY_SPP=${QUALITY_SPP:-"100 1000 10000"}
REF_SPP=${REF_SPP:-40000}
out=${OUT:-out/bench-pajot}; mkdir -p "$out"
BUILD=${BUILD:-build}
R=$BUILD/render-fixture/mcstat-render
M=$BUILD/oiiotool-ext/mcstat
if [ -z "${SKIP_BUILD:-}" ]; then
  scripts/install-deps.sh
  MCSTAT_TARGETS="mcstat mcstat-render" scripts/build.sh "$BUILD" >/dev/null
fi

# SECTIONS picks what runs (default all): 1 overhead, 2 state, 3 quality, 4 picture.
SECTIONS=${SECTIONS:-"1 2 3 4"}
want() { [[ " $SECTIONS " == *" $1 "* ]]; }

median() { sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }

if want 1; then
# BASE=DIR adds the renderer of another build (e.g. a worktree of the commit before a change),
# alternated with this one in every repetition; `render` and `write` are the renderer's own
# --timings walls (the write includes encoding the Pajot state).
BASE_R=${BASE:+$BASE/render-fixture/mcstat-render}
echo "== 1. Render-time overhead at equal spp (100 spp, M = 8, 2 threads; median of $REPS) =="
printf "%-9s %-6s %-8s %10s %10s %10s %10s %12s\n" "scene" "build" "method" "wall" "overhead" \
  "render" "write" "peak RSS"
for scene in default caustic; do
  declare -A times=() mems=() renders=() writes=()
  builds=(this); [ -n "$BASE_R" ] && builds+=(base)
  for _ in $(seq "$REPS"); do
    for b in "${builds[@]}"; do
      bin=$R; [ "$b" = base ] && bin=$BASE_R
      for method in plain adr rot hybrid; do
        args=(--scene "$scene" --spp 100 --M 8 --quiet --timings -o "$out/$scene-$method-100.mcstat")
        [ "$method" != plain ] && args+=(--online "pajot:method=$method")
        /usr/bin/time -f "%e %M" -o "$out/time.txt" "$bin" "${args[@]}" 2>"$out/timings.txt"
        read -r t m <"$out/time.txt"
        read -r rw ww < <(awk '/timings:/ { print $5, $12 }' "$out/timings.txt")
        k=$b-$method
        times[$k]+="$t "; mems[$k]=$m; renders[$k]+="$rw "; writes[$k]+="$ww "
      done
    done
  done
  for b in "${builds[@]}"; do
    base=$(printf '%s\n' ${times[$b-plain]} | median)
    for method in plain adr rot hybrid; do
      k=$b-$method
      t=$(printf '%s\n' ${times[$k]} | median)
      rw=$(printf '%s\n' ${renders[$k]} | median)
      ww=$(printf '%s\n' ${writes[$k]} | median)
      awk -v s="$scene" -v bb="$b" -v m="$method" -v t="$t" -v b="$base" -v r="${mems[$k]}" \
        -v rw="$rw" -v ww="$ww" 'BEGIN { printf "%-9s %-6s %-8s %8.3f s %+9.1f %% %8.3f s %8.3f s %8.1f MiB\n",
          s, bb, m, t, 100 * (t / b - 1), rw, ww, r / 1024 }'
    done
  done
  unset times mems renders writes
done

fi

if want 2; then
echo
echo "== 2. The online state after 100 spp (N = 50, dubious list 64; hybrid T = 2, delta = 0) =="
for scene in default caustic; do
  for method in adr rot hybrid; do
    echo "-- $scene, $method"
    "$M" "$out/$scene-$method-100.mcstat" --info | grep 'pajot'
  done
done

fi

if want 3; then
echo
echo "== 3. Quality at equal spp against a ${REF_SPP}-spp reference =="
# Energy lost: 1 - sum of luminance / the reference's (Rec.709 weights, as the built-in config).
energy() {  # energy FILE REF
  local a b
  a=$(oiiotool "$1" --ch R,G,B --printstats 2>/dev/null | awk '/Stats Avg/ {print 0.2126*$3+0.7152*$4+0.0722*$5}')
  b=$(oiiotool "$2" --ch R,G,B --printstats 2>/dev/null | awk '/Stats Avg/ {print 0.2126*$3+0.7152*$4+0.0722*$5}')
  awk -v a="$a" -v b="$b" 'BEGIN { printf "%+.4f", 1 - a / b }'
}
for scene in caustic default; do
  res=(); [ "$scene" = default ] && res=(--res 80 60)
  ref=$out/$scene-ref-$REF_SPP.exr
  if [ ! -f "$ref" ] || [ "$R" -nt "$ref" ]; then
    "$R" --scene "$scene" "${res[@]}" --spp "$REF_SPP" --seed 99 --reference --quiet -o "$ref"
  fi
  echo "-- $scene ${res[*]:+(${res[*]})}"
  printf "%-7s %-8s %10s %8s %10s %9s\n" "spp" "method" "relMSE" "SSIM" "fireflies" "energy"
  for spp in $QUALITY_SPP; do
    for method in adr rot hybrid; do
      f=$out/$scene-q$spp-$method.mcstat
      if [ ! -f "$f" ] || [ "$R" -nt "$f" ]; then
        "$R" --scene "$scene" "${res[@]}" --spp "$spp" --M 8 --online "pajot:method=$method" --quiet -o "$f"
      fi
    done
    for method in mean gmon adr rot hybrid; do
      img=$out/$scene-q$spp-$method.exr
      case $method in
        mean|gmon) "$M" "$out/$scene-q$spp-hybrid.mcstat" --"$method" -o "$img" ;;
        *) "$M" "$out/$scene-q$spp-$method.mcstat" --pajot -o "$img" ;;
      esac
      "$M" "$img" --diff "$ref" | awk -v s="$spp" -v m="$method" -v e="$(energy "$img" "$ref")" '
        { for (i = 1; i <= NF; ++i) { if ($i == "relMSE") r = $(i+1); if ($i == "SSIM") q = $(i+1);
                                       if ($i == "fireflies") f = $(i+1) }
          printf "%-7s %-8s %10.5f %8.4f %10s %9s\n", s, m, r, q, f, e }'
    done
  done
done

fi

if want 4; then
echo
echo "== The caustic first delayed, then accepted: docs/images/pajot_caustic.png =="
# Columns: 64, 256, 1024, 4096 spp. Rows: the mean, the hybrid's estimate, and the samples still
# delayed per pixel (grey: sqrt(count) / 4, white from 16 on).
tiles=()
for spp in 64 256 1024 4096; do
  f=$out/caustic-p$spp.mcstat
  [ -f "$f" ] && [ "$f" -nt "$R" ] || "$R" --scene caustic --spp "$spp" --M 8 --online pajot:method=hybrid --quiet -o "$f"
  "$M" "$f" --mean -o "$out/caustic-p$spp-mean.exr"
  "$M" "$f" --pajot -o "$out/caustic-p$spp-pajot.exr"
  oiiotool "$out/caustic-p$spp-pajot.exr" --ch delayed --chnames Y -o "$out/caustic-p$spp-delayed.exr"
done
for row in mean pajot; do
  for spp in 64 256 1024 4096; do
    oiiotool "$out/caustic-p$spp-$row.exr" --ch R,G,B --mulc 0.25 --powc 0.4545 --clamp:min=0:max=1 \
      --resize 256x192 -o "$out/tile-$row-$spp.png"
    tiles+=("$out/tile-$row-$spp.png")
  done
done
for spp in 64 256 1024 4096; do
  oiiotool "$out/caustic-p$spp-delayed.exr" --powc 0.5 --divc 4 --clamp:min=0:max=1 \
    --ch Y,Y,Y --chnames R,G,B --resize 256x192 -o "$out/tile-delayed-$spp.png"
  tiles+=("$out/tile-delayed-$spp.png")
done
oiiotool "${tiles[@]}" --mosaic:pad=4 4x3 -o docs/images/pajot_caustic.png
for spp in 64 256 1024 4096; do
  "$M" "$out/caustic-p$spp.mcstat" --info | grep 'samples delayed' | sed "s/^/  $spp spp: /"
done
fi
