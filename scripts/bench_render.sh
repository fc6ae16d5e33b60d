#!/usr/bin/env bash
# Renderer benchmark (never part of the test suite). Prints two tables
# for the default scene at 640x480 (RES="W H"; RES=scene: the scene's own 160x120), seed 3:
#  1. M = 1 against M = 21 at 64 and 256 spp: whole-process wall (to the millisecond) and CPU time,
#     the render alone and the file writing alone (mcstat-render --timings), peak RSS, the file's
#     size, and the overheads of M = 21 in %.
#     The render's overhead is the online accumulation of the sub-buffers (goal <= 2 %); the
#     writing's is deflating 21 times the buffer channels, reported apart.
#  2. Thread scaling: --threads 1 against --threads 2 (goal >= 1.8x for the render).
# Every figure is the median of REPS runs (default 3); the configurations being compared are
# alternated within each repetition, so that a load change on the machine hits them alike.
# BUILD (default build) is the build directory whose render-fixture/mcstat-render is measured;
# SKIP_BUILD=1 uses it as it is. SPPS (default "64 256") and THREAD_SPP (default 64) set the spp.
# BASE=DIR adds table 1's rows of another build's renderer (e.g. a worktree of the commit before a
# change), alternated with this one in every repetition. SECTIONS (default "1 2") picks the tables;
# OUT (default out/bench-render) is where the files go.
set -euo pipefail
cd "$(dirname "$0")/.."
REPS=${REPS:-3}
BUILD=${BUILD:-build}
SPPS=${SPPS:-"64 256"}
THREAD_SPP=${THREAD_SPP:-64}
SECTIONS=${SECTIONS:-"1 2"}
RES=${RES:-"640 480"}
out=${OUT:-out/bench-render}; mkdir -p "$out"
R=$BUILD/render-fixture/mcstat-render
BASE_R=${BASE:+$BASE/render-fixture/mcstat-render}
want() { [[ " $SECTIONS " == *" $1 "* ]]; }
resArgs=(); [ "$RES" != scene ] && read -r -a resArgs <<<"--res $RES"
size=${RES/ /x}; [ "$RES" = scene ] && size="the scene's size"
if [ -z "${SKIP_BUILD:-}" ]; then
  scripts/install-deps.sh
  MCSTAT_TARGETS="mcstat-render" scripts/build.sh "$BUILD" >/dev/null
fi
[ -x "$R" ] || { echo "bench_render.sh: no renderer at $R (set BUILD)" >&2; exit 1; }

median() { sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }

# run KEY ARGS...: one render (BIN, default $R); appends "wall cpu rss renderWall renderCpu writeWall writeCpu
# fileBytes" to $out/KEY.runs (cpu = user + system of the whole process, rss in KiB).
run() {
  local key=$1; shift
  local t0 t1
  t0=$(date +%s%N)
  /usr/bin/time -f "%e %U %S %M" -o "$out/time.txt" \
    "${BIN:-$R}" --scene default "${resArgs[@]}" --seed 3 --quiet --timings "$@" \
    -o "$out/$key.mcstat" 2>"$out/timings.txt"
  t1=$(date +%s%N)
  local e u s m rw rc ww wc
  read -r e u s m <"$out/time.txt"
  e=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.4f", (b - a) / 1e9 }')  # %e has 2 decimals
  # "mcstat-render: timings: render wall X s cpu Y s, write wall Z s cpu W s"
  read -r rw rc ww wc < <(awk '/timings:/ { print $5, $8, $12, $15 }' "$out/timings.txt")
  echo "$e $(awk -v u="$u" -v s="$s" 'BEGIN { print u + s }') $m $rw $rc $ww $wc" \
    "$(stat -c %s "$out/$key.mcstat")" >>"$out/$key.runs"
}

# med KEY COLUMN: the median of one column (1-based, as in run's line) of KEY's runs.
med() { awk -v c="$2" '{ print $c }' "$out/$1.runs" | median; }

rm -f "$out"/*.runs
builds=(this); [ -n "$BASE_R" ] && builds+=(base)
if want 1; then
echo "== 1. Sub-buffer overhead: M = 1 against M = 21 (default scene, $size, all threads;" \
  "median of $REPS) =="
for spp in $SPPS; do
  for _ in $(seq "$REPS"); do
    for b in "${builds[@]}"; do
      bin=$R; [ "$b" = base ] && bin=$BASE_R
      for M in 1 21; do BIN=$bin run "$b-spp$spp-M$M" --spp "$spp" --M "$M"; done
    done
  done
done
printf "%-6s %5s %4s %9s %9s %11s %11s %11s %11s %10s %9s\n" "build" "spp" "M" "wall" "CPU" \
  "render wall" "render CPU" "write wall" "write CPU" "peak RSS" "file"
for b in "${builds[@]}"; do
  for spp in $SPPS; do
    for M in 1 21; do
      k=$b-spp$spp-M$M
      printf "%-6s %5d %4d %7.3f s %7.2f s %9.3f s %9.2f s %9.3f s %9.3f s %6.1f MiB %5.2f MB\n" \
        "$b" "$spp" "$M" "$(med "$k" 1)" "$(med "$k" 2)" "$(med "$k" 4)" "$(med "$k" 5)" \
        "$(med "$k" 6)" "$(med "$k" 7)" "$(awk -v m="$(med "$k" 3)" 'BEGIN { print m / 1024 }')" \
        "$(awk -v m="$(med "$k" 8)" 'BEGIN { print m / 1e6 }')"
    done
  done
done
echo
echo "Overhead of M = 21 over M = 1 (ratios of the medians):"
printf "%-6s %5s %10s %10s %13s %13s %14s\n" "build" "spp" "wall" "CPU" "render wall" \
  "render CPU" "write / render"
for b in "${builds[@]}"; do
  for spp in $SPPS; do
    a=$b-spp$spp-M1 c=$b-spp$spp-M21
    awk -v w1="$(med "$a" 1)" -v w2="$(med "$c" 1)" -v c1="$(med "$a" 2)" -v c2="$(med "$c" 2)" \
      -v rw1="$(med "$a" 4)" -v rw2="$(med "$c" 4)" -v rc1="$(med "$a" 5)" -v rc2="$(med "$c" 5)" \
      -v ww2="$(med "$c" 6)" -v spp="$spp" -v b="$b" 'BEGIN {
        printf "%-6s %5d %+8.1f %% %+8.1f %% %+11.1f %% %+11.1f %% %12.1f %%\n", b, spp,
          100 * (w2 / w1 - 1), 100 * (c2 / c1 - 1), 100 * (rw2 / rw1 - 1), 100 * (rc2 / rc1 - 1),
          100 * ww2 / rw2 }'
  done
done
fi

want 2 || exit 0
echo
echo "== 2. Thread scaling (default scene, $size, $THREAD_SPP spp; median of $REPS) =="
for _ in $(seq "$REPS"); do
  for M in 1 21; do
    for t in 1 2; do run "threads$t-M$M" --spp "$THREAD_SPP" --M "$M" --threads "$t"; done
  done
done
printf "%4s %8s %9s %11s %11s %9s %15s\n" "M" "threads" "wall" "render wall" "write wall" \
  "speedup" "render speedup"
for M in 1 21; do
  for t in 1 2; do
    k=threads$t-M$M one=threads1-M$M
    awk -v M="$M" -v t="$t" -v w="$(med "$k" 1)" -v rw="$(med "$k" 4)" -v ww="$(med "$k" 6)" \
      -v w1="$(med "$one" 1)" -v rw1="$(med "$one" 4)" 'BEGIN {
        printf "%4d %8d %7.2f s %9.2f s %9.3f s %8.2fx %14.2fx\n", M, t, w, rw, ww, w1 / w,
          rw1 / rw }'
  done
done
