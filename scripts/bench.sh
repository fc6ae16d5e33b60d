#!/usr/bin/env bash
# Benchmarks (never part of the test suite): prints two tables.
#  1. Per-estimator throughput (Mpixel/s, one thread) and its ratio to the plain mean of the same run.
#  2. Wall time and peak memory of `mcstat FILE --gmon -o out.exr` against stock `oiiotool` merely
#     reading every part of the same file, median of REPS runs, as a ratio.
set -euo pipefail
cd "$(dirname "$0")/.."
REPS=${REPS:-5}
scripts/install-deps.sh
scripts/build.sh build >/dev/null
out=out/bench; mkdir -p "$out"

echo "== Estimator throughput, 256x256 pixels, single thread =="
build/tests/bench/bench_estimators --benchmark_format=csv 2>/dev/null >"$out/estimators.csv"
awk -F, 'NR > 1 {
    gsub(/"/, "", $1); n = split($1, a, "/"); key = a[2] "/" a[3]; M = a[4];
    ips = $(NF - 4) + 0;  # items_per_second column
    rate[key, M] = ips; if (!(key in seen)) { seen[key] = 1; order[++k] = key } Ms[M] = 1 }
  END {
    printf "%-18s %6s %12s %14s\n", "estimator", "M", "Mpixel/s", "time vs mean";
    for (i = 1; i <= k; ++i) for (M in Ms) if ((order[i], M) in rate)
      printf "%-18s %6d %12.2f %14.2f\n", order[i], M, rate[order[i], M] / 1e6,
             rate["mean/", M] / rate[order[i], M];
  }' "$out/estimators.csv" | sort -k1,1 -k2,2n

echo
file=$out/bench-640x480-M21.mcstat
if [ ! -f "$file" ] || [ build/render-fixture/mcstat-render -nt "$file" ]; then
  build/render-fixture/mcstat-render --scene default --res 640 480 --spp 64 --M 21 --seed 3 \
    --quiet -o "$file"
fi
size=$(du -h "$file" | cut -f1)
echo "== mcstat --gmon against stock oiiotool reading the same file ($file, $size, all threads) =="
measure() {  # measure NAME CMD...: median wall seconds and max peak RSS over REPS runs
  local name=$1; shift
  local times=() mems=()
  for _ in $(seq "$REPS"); do
    /usr/bin/time -f "%e %M" -o "$out/time.txt" "$@" >/dev/null 2>&1
    read -r t m <"$out/time.txt"; times+=("$t"); mems+=("$m")
  done
  local tmed; tmed=$(printf '%s\n' "${times[@]}" | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
  local mmax; mmax=$(printf '%s\n' "${mems[@]}" | sort -n | tail -1)
  echo "$name $tmed $mmax"
}
ref=$(measure "oiiotool" oiiotool -a "$file" -o "$out/read.null")
gmon=$(measure "mcstat" build/oiiotool-ext/mcstat "$file" --gmon -o "$out/gmon.exr")
mean=$(measure "mcstat-mean" build/oiiotool-ext/mcstat "$file" --mean -o "$out/mean.exr")
printf '%s\n%s\n%s\n' "$ref" "$gmon" "$mean" | awk -v pixels=$((640 * 480)) '
  NR == 1 { base = $2 }
  { label = $1 == "oiiotool" ? "oiiotool -a FILE -o x.null (read only)" :
            $1 == "mcstat" ? "mcstat FILE --gmon -o out.exr" : "mcstat FILE --mean -o out.exr";
    rows[NR] = sprintf("%-40s %8.3f s %8.2fx %10.1f MiB", label, $2, $2 / base, $3 / 1024) }
  END { printf "%-40s %10s %9s %14s\n", "command", "wall", "ratio", "peak RSS";
        for (i = 1; i <= NR; ++i) print rows[i] }'
