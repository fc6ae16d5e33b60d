#!/usr/bin/env bash
# Random parameter filtering benchmark (Sen & Darabi 2011; never part of the test suite). For the
# scenes dof, arealight, motion and texture (256x256) it prints three sections and writes them as
# markdown to docs/rpf-results.md (generated: the command lines, machine and date of each section):
#  1. Speed and memory: wall time of an 8-spp render with --keep-samples, of `mcstat --rpf` on it
#     (default parameters, all cores; the goal is <= 30 s on a 2-core machine), RPF's peak RSS,
#     RPF's time over the render's, the records file's size. Medians of REPS runs.
#  2. Quality against a REF_SPP reference (seed 1): plain MC at 8, 64, 512, 2048 spp and RPF at
#     8 spp (all seed 7; RPF filters exactly the samples of MC 8): relMSE and SSIM; and the spp at
#     which plain MC (every power of two, 8..2048) first matches RPF's relMSE, and its SSIM.
#  3. Pictures: docs/images/rpf_SCENE.png (MC 8 spp | RPF 8 spp | reference, sRGB, clamped) and
#     docs/images/rpf_maps_SCENE.png (the first pass's dependency maps, the report's Fig. 6:
#     rpf.colorOnRandom | rpf.textureOnRandom | rpf.alpha | rpf.textureBeta, grey 0..1).
#  4. Where RPF's error is (EXPLAIN scenes, default dof; RPF with every draw, kept=0, the report's
#     rule): docs/images/rpf_error_SCENE.png (per-pixel
#     relative squared error of RPF 8 and of MC 64 against the reference, log scale, and the first
#     pass's |N|) and tables of each one's share of relMSE by |N|, by the reference's light edges
#     and by the worst pixels.
# Environment: SECTIONS (default "1 2 3 4"), EXPLAIN (scenes of section 4, default "dof"), REPS (1), REF_SPP (8192), SCENES (the four),
# BUILD (build: the binaries' build directory), SKIP_BUILD=1 (use the binaries as they are),
# REFRESH=1 (re-render the cached MC renders; references are re-rendered only when deleted).
# Cached under out/bench-rpf/: ref-SCENE-SPP.exr, mc-SCENE-SPP.exr, SCENE-8-keep.mcstat; RPF
# outputs are recomputed unless made from their input by the same mcstat binary (OUT.by).
set -Eeuo pipefail
cd "$(dirname "$0")/.."
trap 'rc=$?; echo "bench_rpf: line $LINENO failed (exit $rc): $BASH_COMMAND" >&2' ERR
die() { echo "bench_rpf: $*" >&2; exit 1; }

REPS=${REPS:-1}
REF_SPP=${REF_SPP:-8192}
SCENES=${SCENES:-"dof arealight motion texture"}
SECTIONS=${SECTIONS:-"1 2 3 4"}
EXPLAIN=${EXPLAIN:-dof}
BUILD=${BUILD:-build}
MC_SPP="8 64 512 2048"                          # the rows of section 2's tables
SWEEP="8 16 32 64 128 256 512 1024 2048"        # powers of two for "MC matches RPF at"
SEED=7 REF_SEED=1
out=out/bench-rpf; mkdir -p "$out" docs/images
R=$BUILD/render-fixture/mcstat-render
M=$BUILD/oiiotool-ext/mcstat
[[ $REPS =~ ^[1-9][0-9]*$ ]] || die "REPS must be a positive integer (got '$REPS')"
[[ $REF_SPP =~ ^[1-9][0-9]*$ ]] || die "REF_SPP must be a positive integer (got '$REF_SPP')"
for s in $SECTIONS; do [[ $s == [1234] ]] || die "SECTIONS holds 1, 2, 3 and/or 4 (got '$SECTIONS')"; done
want() { [[ " $SECTIONS " == *" $1 "* ]]; }

# Progress on stderr only when it is a terminal (the tools show their own progress lines then too).
tty=0; [ -t 2 ] && tty=1
say() { if [ "$tty" = 1 ]; then echo "  .. $*" >&2; fi; }

if [ "${SKIP_BUILD:-0}" = 0 ]; then
  if [ "$tty" = 1 ]; then scripts/install-deps.sh
  else scripts/install-deps.sh >"$out/install-deps.log" 2>&1 ||
         { cat "$out/install-deps.log" >&2; die "scripts/install-deps.sh failed"; }
  fi
  say "building mcstat and mcstat-render in $BUILD"
  MCSTAT_TARGETS="mcstat mcstat-render" scripts/build.sh "$BUILD" >"$out/build.log" 2>&1 ||
    { tail -n 40 "$out/build.log" >&2; die "build of $BUILD failed (full log: $out/build.log)"; }
fi
for b in "$R" "$M"; do
  [ -x "$b" ] || die "$b not found: run scripts/build.sh $BUILD first (or set BUILD=DIR, or unset SKIP_BUILD)"
done
command -v oiiotool >/dev/null || die "oiiotool not found (Debian: openimageio-tools; scripts/install-deps.sh)"
[ -x /usr/bin/time ] || die "/usr/bin/time not found (Debian: time; scripts/install-deps.sh)"

median() { sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
# timed CMD...: runs CMD under /usr/bin/time; sets T (wall seconds) and MEM (peak RSS, KiB).
timed() {
  /usr/bin/time -f "%e %M" -o "$out/time.txt" "$@"
  read -r T MEM <"$out/time.txt"
}
hms() { printf '%dm%02ds' $(($1 / 60)) $(($1 % 60)); }
mib() { awk -v b="$1" 'BEGIN { printf "%.1f", b / 1048576 }'; }

# Each section writes its markdown to $out/section-N.md; docs/rpf-results.md is assembled from the
# fragments present, so running one section keeps the others' last results.
md=/dev/null
machine="$(lscpu 2>/dev/null | sed -n 's/^Model name: *//p' | head -n1), $(nproc) cores, $(free -g | awk '/^Mem:/ {print $2}') GiB"
# What the binaries were built from: the tree's commit when this script built them; with SKIP_BUILD
# only their build time is known (the tree may have moved on since).
commit=$(git describe --always --dirty 2>/dev/null || echo unknown)
built=$(date -u -r "$M" '+%Y-%m-%d %H:%M UTC')
if [ "${SKIP_BUILD:-0}" = 0 ]; then provenance="commit $commit (built by this run)"
else provenance="binaries in $BUILD built $built (SKIP_BUILD; the tree is now at $commit)"; fi
md_begin() {  # md_begin N TITLE
  md=$out/section-$1.md
  { echo "## $2"; echo
    echo "Run $(date -u '+%Y-%m-%d %H:%M UTC') on ${machine}; ${provenance}; REPS=$REPS, REF_SPP=$REF_SPP."
    echo; } >"$md"
  echo; echo "== $2 =="
}
md_cmds() { { echo '```sh'; cat; echo '```'; echo; } >>"$md"; }
md_text() { echo "$*" >>"$md"; }
note() { echo "$*"; echo "$*" >>"$md"; echo >>"$md"; }
# A table both ways: thead/trow FMT CELL...: FMT (printf, one %s per cell) for the printed table,
# the cells as a markdown row.
md_row() { local s="|" c; for c in "$@"; do s+=" $c |"; done; echo "$s" >>"$md"; }
thead() {
  local fmt=$1 s="|" i; shift
  echo >>"$md"; printf "$fmt\n" "$@"; md_row "$@"
  for ((i = 0; i < $#; ++i)); do s+="---|"; done; echo "$s" >>"$md"
}
trow() { local fmt=$1; shift; printf "$fmt\n" "$@"; md_row "$@"; }
tend() { echo >>"$md"; }

# Cached inputs shared by the sections.
keep_file() { echo "$out/$1-8-keep.mcstat"; }
ref_file() { echo "$out/ref-$1-$REF_SPP.exr"; }
mc_file() { echo "$out/mc-$1-$2.exr"; }
ensure_keep() {
  local f; f=$(keep_file "$1")
  if [ ! -f "$f" ] || [ -n "${REFRESH:-}" ]; then
    say "$1: rendering 8 spp with --keep-samples"
    "$R" --scene "$1" --spp 8 --keep-samples --seed "$SEED" -o "$f"
  fi
}
ensure_ref() {
  local f tmp; f=$(ref_file "$1"); tmp=${f%.exr}.partial.exr
  if [ ! -f "$f" ]; then
    say "$1: rendering the ${REF_SPP}-spp reference (minutes; cached in $f)"
    "$R" --scene "$1" --spp "$REF_SPP" --seed "$REF_SEED" --reference -o "$tmp"
    mv "$tmp" "$f"
  fi
}
ensure_mc() {  # ensure_mc SCENE SPP
  local f; f=$(mc_file "$1" "$2")
  if [ ! -f "$f" ] || [ -n "${REFRESH:-}" ]; then
    say "$1: rendering plain MC at $2 spp"
    "$R" --scene "$1" --spp "$2" --seed "$SEED" --reference -o "$f"
  fi
}
# An RPF output is reused only if made from its input by this very mcstat binary (OUT.by holds the
# binary's path and mtime: another BUILD's older binary must not pass off its output).
mstamp="$(readlink -f "$M") $(stat -c %Y "$M")"
stale() { [ ! -f "$1" ] || [ "$2" -nt "$1" ] || [ "$(cat "$1.by" 2>/dev/null)" != "$mstamp" ]; }
ensure_rpf() {
  local k f; k=$(keep_file "$1"); f=$out/$1-rpf8.exr
  ensure_keep "$1"
  if stale "$f" "$k"; then say "$1: RPF"; "$M" "$k" --rpf -o "$f"; echo "$mstamp" >"$f.by"; fi
}
# ensure_maps SCENE [SUFFIX OPTIONS]: RPF with maps=1 (and OPTIONS, e.g. :kept=0) into
# SCENE-rpf8-maps[SUFFIX].exr.
ensure_maps() {
  local k f; k=$(keep_file "$1"); f=$out/$1-rpf8-maps${2:-}.exr
  ensure_keep "$1"
  if stale "$f" "$k"; then
    say "$1: RPF with maps=1${3:-}"; "$M" "$k" --rpf:maps=1${3:-} -o "$f"; echo "$mstamp" >"$f.by"
  fi
}
metrics() {  # metrics IMAGE REF: prints "relMSE SSIM"
  "$M" "$1" --diff "$2" | awk '{ for (i = 1; i <= NF; ++i) { if ($i == "relMSE") r = $(i + 1)
                                                            if ($i == "SSIM") s = $(i + 1) } }
                              END { if (r == "" || s == "") exit 1; print r, s }'
}

if want 1; then
t0=$SECONDS
load1=$(cut -d' ' -f1 /proc/loadavg)
md_begin 1 "1. Speed and memory at 8 spp (256x256, all $(nproc) cores, median of $REPS)"
md_cmds <<EOF
$R --scene SCENE --spp 8 --keep-samples --seed $SEED -o $out/SCENE-8-keep.mcstat
$M $out/SCENE-8-keep.mcstat --rpf -o $out/SCENE-rpf8.exr
$M $out/SCENE-8-keep.mcstat --rpf:kept=0 -o $out/SCENE-rpf8-full.exr   # the report's rule: every draw
# each under /usr/bin/time -f "%e %M" (wall seconds, peak RSS); the two RPF runs alternate
EOF
fmt="%-10s %12s %13s %9s %11s %14s %8s %11s %7s"
thead "$fmt" scene "render (s)" "records (MiB)" "RPF (s)" "RPF/render" "RPF peak (MiB)" "<= 30 s" "kept=0 (s)" "ratio"
for scene in $SCENES; do
  keep=$(keep_file "$scene"); rts=() pts=() fts=() peak=0
  for _ in $(seq "$REPS"); do
    say "$scene: 8 spp --keep-samples, then RPF, then RPF with kept=0"
    timed "$R" --scene "$scene" --spp 8 --keep-samples --seed "$SEED" -o "$keep"; rts+=("$T")
    timed "$M" "$keep" --rpf -o "$out/$scene-rpf8.exr"; pts+=("$T")
    echo "$mstamp" >"$out/$scene-rpf8.exr.by"
    if [ "$MEM" -gt "$peak" ]; then peak=$MEM; fi
    timed "$M" "$keep" --rpf:kept=0 -o "$out/$scene-rpf8-full.exr"; fts+=("$T")
  done
  rt=$(printf '%s\n' "${rts[@]}" | median); pt=$(printf '%s\n' "${pts[@]}" | median)
  ft=$(printf '%s\n' "${fts[@]}" | median)
  trow "$fmt" "$scene" "$rt" "$(mib "$(stat -c %s "$keep")")" "$pt" \
    "$(awk -v a="$pt" -v b="$rt" 'BEGIN { printf "%.1fx", a / b }')" "$(mib $((peak * 1024)))" \
    "$(awk -v a="$pt" 'BEGIN { print a <= 30 ? "yes" : "no" }')" "$ft" \
    "$(awk -v a="$pt" -v b="$ft" 'BEGIN { printf "%.2fx", a / b }')"
done
tend
note "RPF with the default kept = 1,536 (drawing stops once N holds that many draws) against the report's rule, every draw (kept = 0), in the same runs. Peak RSS is the largest of the REPS runs. 1-minute load average at the start: $load1 on $(nproc) cores (other jobs on the machine inflate the times). Section 1 took $(hms $((SECONDS - t0)))."
fi

if want 2; then
t0=$SECONDS
md_begin 2 "2. Quality against a ${REF_SPP}-spp reference (relMSE, SSIM)"
md_cmds <<EOF
$R --scene SCENE --spp $REF_SPP --seed $REF_SEED --reference -o $out/ref-SCENE-$REF_SPP.exr   # cached
$R --scene SCENE --spp N --seed $SEED --reference -o $out/mc-SCENE-N.exr   # N = ${SWEEP// /, }; cached
$M $out/SCENE-8-keep.mcstat --rpf -o $out/SCENE-rpf8.exr   # the samples of mc-SCENE-8.exr
$M IMAGE --diff $out/ref-SCENE-$REF_SPP.exr
EOF
declare -A rel=() ssim=() mrel=() mssim=()
for scene in $SCENES; do
  ensure_ref "$scene"; ensure_rpf "$scene"
  ref=$(ref_file "$scene")
  for spp in $SWEEP; do
    ensure_mc "$scene" "$spp"
    v=$(metrics "$(mc_file "$scene" "$spp")" "$ref"); read -r "rel[$scene-$spp]" "ssim[$scene-$spp]" <<<"$v"
  done
  v=$(metrics "$out/$scene-rpf8.exr" "$ref"); read -r "rel[$scene-rpf]" "ssim[$scene-rpf]" <<<"$v"
  echo "-- $scene"; md_text "### $scene"
  fmt="%-10s %12s %8s"
  thead "$fmt" method relMSE SSIM
  for spp in $MC_SPP; do
    trow "$fmt" "MC $spp" "$(printf '%.5f' "${rel[$scene-$spp]}")" "$(printf '%.4f' "${ssim[$scene-$spp]}")"
  done
  trow "$fmt" "RPF 8" "$(printf '%.5f' "${rel[$scene-rpf]}")" "$(printf '%.4f' "${ssim[$scene-rpf]}")"
  tend
  mrel[$scene]="> 2048"; mssim[$scene]="> 2048"
  for spp in $SWEEP; do
    if [ "${mrel[$scene]}" = "> 2048" ] &&
       awk -v a="${rel[$scene-$spp]}" -v b="${rel[$scene-rpf]}" 'BEGIN { exit !(a <= b) }'; then
      mrel[$scene]=$spp
    fi
    if [ "${mssim[$scene]}" = "> 2048" ] &&
       awk -v a="${ssim[$scene-$spp]}" -v b="${ssim[$scene-rpf]}" 'BEGIN { exit !(a >= b) }'; then
      mssim[$scene]=$spp
    fi
  done
done
echo "-- spp at which plain MC (powers of two, 8..2048) first matches RPF at 8 spp"
md_text "### spp at which plain MC (powers of two, 8..2048) first matches RPF at 8 spp"
fmt="%-10s %16s %16s"
thead "$fmt" scene "relMSE <= RPF's" "SSIM >= RPF's"
for scene in $SCENES; do trow "$fmt" "$scene" "${mrel[$scene]}" "${mssim[$scene]}"; done
tend
pct=$(awk -v r="$REF_SPP" 'BEGIN { printf "%.0f", 100 * 2048 / r }')
note "The reference is noisy too: its variance is 2048/$REF_SPP = $pct % of MC 2048's, so MC 2048's relMSE is inflated by about that much (every row, RPF's included, carries about the relMSE of MC at $REF_SPP spp from it)."
note "Section 2 took $(hms $((SECONDS - t0)))."
fi

if want 3; then
t0=$SECONDS
md_begin 3 "3. Pictures"
md_cmds <<EOF
$M $out/SCENE-8-keep.mcstat --rpf:maps=1 -o $out/SCENE-rpf8-maps.exr
oiiotool IMAGE --ch R,G,B --colorconvert linear sRGB --clamp:min=0:max=1 -d uint8 -o TILE.png
oiiotool IMAGE --ch rpf.colorOnRandom --clamp:min=0:max=1 -d uint8 -o TILE.png   # each map, grey 0..1
oiiotool TILES... --mosaic:pad=4 Nx1 -o docs/images/rpf_SCENE.png
EOF
md_text "rpf_SCENE.png: MC 8 spp (the samples RPF filters) | RPF 8 spp | ${REF_SPP}-spp reference;"
md_text "sRGB, clamped to [0, 1]. rpf_maps_SCENE.png: the first pass's dependency maps (the report's"
md_text "Fig. 6), grey 0..1: rpf.colorOnRandom (W_c^r, eq. 11) | rpf.textureOnRandom (W_f^r of the"
md_text "texture value, eq. 9) | rpf.alpha (eq. 15) | rpf.textureBeta (eq. 16)."
md_text
maps=(rpf.colorOnRandom rpf.textureOnRandom rpf.alpha rpf.textureBeta)
for scene in $SCENES; do
  ensure_ref "$scene"; ensure_mc "$scene" 8; ensure_rpf "$scene"; ensure_maps "$scene"
  tiles=()
  for img in "$(mc_file "$scene" 8)" "$out/$scene-rpf8.exr" "$(ref_file "$scene")"; do
    t=$out/tile-$scene-${#tiles[@]}.png
    oiiotool "$img" --ch R,G,B --colorconvert linear sRGB --clamp:min=0:max=1 -d uint8 -o "$t"
    tiles+=("$t")
  done
  oiiotool "${tiles[@]}" --mosaic:pad=4 3x1 -o "docs/images/rpf_$scene.png"
  tiles=()
  for c in "${maps[@]}"; do
    t=$out/tile-$scene-$c.png
    oiiotool "$out/$scene-rpf8-maps.exr" --ch "$c" --chnames Y --clamp:min=0:max=1 -d uint8 -o "$t"
    tiles+=("$t")
  done
  oiiotool "${tiles[@]}" --mosaic:pad=4 4x1 -o "docs/images/rpf_maps_$scene.png"
  for p in "docs/images/rpf_$scene.png" "docs/images/rpf_maps_$scene.png"; do
    kb=$(( $(stat -c %s "$p") / 1024 ))
    echo "$p ($kb KiB)"
    [ "$kb" -lt 400 ] || echo "bench_rpf: warning: $p is $kb KiB (>= 400)" >&2
  done
  md_text "**$scene**: MC 8 | RPF 8 | reference, then the maps"
  md_text
  md_text "![$scene](images/rpf_$scene.png)"
  md_text
  md_text "![$scene maps](images/rpf_maps_$scene.png)"
  md_text
done
note "Section 3 took $(hms $((SECONDS - t0)))."
fi

if want 4; then
t0=$SECONDS
md_begin 4 "4. Where RPF's error is (per pixel, against the ${REF_SPP}-spp reference)"
md_cmds <<EOF
$M $out/SCENE-8-keep.mcstat --rpf:maps=1:kept=0 -o $out/SCENE-rpf8-maps-full.exr   # the report's rule; R, G, B and rpf.neighbours (|N|, pass 1)
oiiotool --dumpdata IMAGE   # RPF 8, MC 64, MC 8, the reference: per-pixel values, joined by awk
# error of a pixel: (1/3) sum over R, G, B of (x - r)^2 / (r^2 + 0.01), as mcstat --diff (relMSE is its mean)
EOF
md_text "rpf_error_SCENE.png: the per-pixel error of RPF 8 | of MC 64 (log scale, inferno colours: black"
md_text "1e-4 or less, white 1 or more) | the first pass's neighbourhood size |N| (grey, black 0, white"
md_text "12,100 = the draws of the 55-pixel box at 8 spp). Light edge: a pixel whose 3x3 neighbourhood"
md_text "in the reference holds luminance both >= 1 and < 1 (the emitters have radiance 10-17, lit"
md_text "surfaces less than 1). Share: the part of the image's relMSE (sum of the pixel errors) that the"
md_text "pixels hold; mean: their mean error."
md_text "RPF here draws every neighbour (kept = 0, the report's rule), so that |N| is the report's; the"
md_text "default stops at 1,536 draws (section 1)."
md_text
dumpv() { oiiotool --dumpdata "$1" | tail -n +2 | sed 's/^.*: //'; }
for scene in $EXPLAIN; do
  ensure_ref "$scene"; ensure_mc "$scene" 8; ensure_mc "$scene" 64; ensure_maps "$scene" -full :kept=0
  maps=$out/$scene-rpf8-maps-full.exr
  # Where |N| is among the maps file's channels (in the file's order).
  nch=$(oiiotool --info -v "$maps" | sed -n 's/^ *channel list: //p' | tr -d ' ' | tr ',' '\n' |
        grep -n '^rpf.neighbours$' | cut -d: -f1)
  [ -n "$nch" ] || die "$maps has no channel rpf.neighbours"
  read -r width height < <(oiiotool --info "$maps" | sed -n 's/^[^:]*: *\([0-9]*\) x *\([0-9]*\),.*/\1 \2/p')
  dumpv "$maps" >"$out/x-rpf.txt"; dumpv "$(ref_file "$scene")" >"$out/x-ref.txt"
  dumpv "$(mc_file "$scene" 64)" >"$out/x-mc64.txt"; dumpv "$(mc_file "$scene" 8)" >"$out/x-mc8.txt"
  nrpf=$(head -n1 "$out/x-rpf.txt" | wc -w)
  # Per pixel (x-pix.txt): the errors of RPF 8, MC 64, MC 8, |N|, the light-edge flag; the tiles.
  paste -d' ' "$out/x-rpf.txt" "$out/x-ref.txt" "$out/x-mc64.txt" "$out/x-mc8.txt" |
    awk -v W="$width" -v H="$height" -v nch="$nch" -v o="$nrpf" -v out="$out" '
    function rel(a, b, c, r, g, bl) {
      return ((a - r) ^ 2 / (r * r + 0.01) + (b - g) ^ 2 / (g * g + 0.01) + (c - bl) ^ 2 / (bl * bl + 0.01)) / 3 }
    function level(e) { e = e > 1e-4 ? log(e) / log(10) + 4 : 0; if (e > 4) e = 4; return int(e / 4 * 255 + 0.5) }
    { p = NR - 1
      er[p] = rel($1, $2, $3, $(o + 1), $(o + 2), $(o + 3))
      em[p] = rel($(o + 4), $(o + 5), $(o + 6), $(o + 1), $(o + 2), $(o + 3))
      e8[p] = rel($(o + 7), $(o + 8), $(o + 9), $(o + 1), $(o + 2), $(o + 3))
      nn[p] = $nch; L[p] = 0.2126 * $(o + 1) + 0.7152 * $(o + 2) + 0.0722 * $(o + 3) }
    END {
      n = W * H
      print "P2", W, H, 255 >(out "/x-err-rpf.pgm"); print "P2", W, H, 255 >(out "/x-err-mc64.pgm")
      print "P2", W, H, 255 >(out "/x-nn.pgm")
      for (p = 0; p < n; ++p) {
        print level(er[p]) >(out "/x-err-rpf.pgm"); print level(em[p]) >(out "/x-err-mc64.pgm")
        v = int(nn[p] / 12100 * 255 + 0.5); print (v > 255 ? 255 : v) >(out "/x-nn.pgm")
        x = p % W; y = int(p / W); hi = 0; lo = 0
        for (dy = -1; dy <= 1; ++dy) for (dx = -1; dx <= 1; ++dx) {
          xx = x + dx; yy = y + dy
          if (xx < 0 || yy < 0 || xx >= W || yy >= H) continue
          if (L[yy * W + xx] >= 1) hi = 1; else lo = 1 }
        printf "%.9g %.9g %.9g %d %d\n", er[p], em[p], e8[p], nn[p], hi && lo
      }
    }' >"$out/x-pix.txt"
  n=$(wc -l <"$out/x-pix.txt")
  # Groups: by |N|, by light edge, the worst 0.1 % and 1 % of RPF's pixels (sort -g -r).
  { awk '{ if ($4 < 500) g = "a|N < 500"; else if ($4 < 2000) g = "b|500 <= N < 2,000"
           else if ($4 < 4000) g = "c|2,000 <= N < 4,000"; else if ($4 < 8000) g = "d|4,000 <= N < 8,000"
           else g = "e|N >= 8,000"
           print g, $0; print ($5 ? "f|light edge" : "g|not a light edge"), $0 }' "$out/x-pix.txt"
    sort -g -r -k1,1 "$out/x-pix.txt" >"$out/x-sorted.txt"
    sed -n "1,$((n / 1000))s/^/h|worst 0.1 % of RPF 8 pixels /p" "$out/x-sorted.txt"
    sed -n "1,$((n / 100))s/^/i|worst 1 % of RPF 8 pixels /p" "$out/x-sorted.txt"
  } | awk -v n="$n" -v tot="$out/x-total.txt" '
    { k = index($0, " "); g = $0; sub(/ [^ ]+ [^ ]+ [^ ]+ [^ ]+ [^ ]+$/, "", g)
      m = split($0, f, " "); c[g]++; r[g] += f[m - 4]; q[g] += f[m - 3]; e[g] += f[m - 2]
      if (g ~ /^[ab]/ || g ~ /^[cde]/) { R += f[m - 4]; Q += f[m - 3]; E += f[m - 2] } }
    END { printf "%.5f %.5f %.5f\n", R / n, Q / n, E / n >tot
          for (g in c) printf "%s|%.2f|%.1f %%|%.5f|%.1f %%|%.5f|%.5f\n", g, 100 * c[g] / n, 100 * r[g] / R,
                              r[g] / c[g], 100 * q[g] / Q, q[g] / c[g], e[g] / c[g] }' | sort >"$out/x-groups.txt"
  read -r rr mm m8 <"$out/x-total.txt"
  echo "-- $scene: relMSE RPF 8 $rr, MC 64 $mm, MC 8 $m8"
  md_text "### $scene"
  md_text
  md_text "relMSE over the image: RPF 8 $rr, MC 64 $mm, MC 8 $m8."
  fmt="%-30s %10s %9s %9s %11s %10s %9s"
  thead "$fmt" pixels "% of image" "RPF share" "RPF mean" "MC 64 share" "MC 64 mean" "MC 8 mean"
  while IFS='|' read -r _ g a b c2 d e f; do trow "$fmt" "$g" "$a" "$b" "$c2" "$d" "$e" "$f"; done <"$out/x-groups.txt"
  tend
  tiles=()
  for t in err-rpf err-mc64; do
    oiiotool "$out/x-$t.pgm" --colormap inferno -d uint8 -o "$out/tile-$scene-$t.png"
    tiles+=("$out/tile-$scene-$t.png")
  done
  oiiotool "$out/x-nn.pgm" --ch 0,0,0 -d uint8 -o "$out/tile-$scene-nn.png"; tiles+=("$out/tile-$scene-nn.png")
  oiiotool "${tiles[@]}" --mosaic:pad=4 3x1 -o "docs/images/rpf_error_$scene.png"
  echo "docs/images/rpf_error_$scene.png ($(( $(stat -c %s "docs/images/rpf_error_$scene.png") / 1024 )) KiB)"
  md_text "![$scene: error of RPF 8 | error of MC 64 | |N| of the first pass](images/rpf_error_$scene.png)"
  md_text
done
note "Section 4 took $(hms $((SECONDS - t0)))."
fi

# docs/rpf-results.md from every section's latest fragment.
{
  echo "# Random parameter filtering: benchmark results"
  echo
  echo "Generated by \`scripts/bench_rpf.sh\` (do not edit: re-run it; \`SECTIONS=\"2\"\` re-runs one"
  echo "section and keeps the others). Scenes: ${SCENES// /, } at 256x256; plain MC and RPF's input"
  echo "use seed $SEED, the reference seed $REF_SEED."
  echo
  for s in 1 2 3 4; do [ -f "$out/section-$s.md" ] && cat "$out/section-$s.md"; done
} >docs/rpf-results.md
echo
echo "wrote docs/rpf-results.md"
