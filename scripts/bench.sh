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
printf "%-18s %6s %12s %16s\n" "estimator" "M" "Mpixel/s" "time / mean's"
awk -F, 'NR > 1 {
    gsub(/"/, "", $1); split($1, a, "/");   # estimate/NAME/MODE/M
    key = a[2] "/" a[3]; rate[key "@" a[4]] = $7; keys[key "@" a[4]] = 1 }
  END { for (k in keys) { split(k, b, "@");
          printf "%-18s %6d %12.2f %16.2f\n", b[1], b[2], rate[k] / 1e6, rate["mean/lum@" b[2]] / rate[k] } }' \
  "$out/estimators.csv" | sort -k1,1 -k2,2n

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
ref=$(measure "oiiotool" oiiotool -a --stats "$file")
gmon=$(measure "mcstat" build/oiiotool-ext/mcstat "$file" --gmon -o "$out/gmon.exr")
mean=$(measure "mcstat-mean" build/oiiotool-ext/mcstat "$file" --mean -o "$out/mean.exr")
printf "%-40s %10s %9s %14s\n" "command" "wall" "ratio" "peak RSS"
printf '%s\n%s\n%s\n' "$ref" "$gmon" "$mean" | awk '
  NR == 1 { base = $2 }
  { if ($1 == "oiiotool") label = "oiiotool -a --stats FILE (reads all parts)"
    else if ($1 == "mcstat") label = "mcstat FILE --gmon -o out.exr"
    else label = "mcstat FILE --mean -o out.exr"
    printf "%-40s %8.3f s %8.2fx %10.1f MiB\n", label, $2, $2 / base, $3 / 1024 }'

echo
# Ingest: renders of one image, one plain EXR per seed (docs/ingest.md), against stock oiiotool
# reading the same files once each.
NSEEDS=${NSEEDS:-21}
mkdir -p "$out/seeds"
for s in $(seq "$NSEEDS"); do
  f=$out/seeds/seed_$s.exr
  if [ ! -f "$f" ] || [ build/render-fixture/mcstat-render -nt "$f" ]; then
    build/render-fixture/mcstat-render --scene default --res 640 480 --spp 4 --seed "$s" \
      --reference --quiet -o "$f"
  fi
done
echo "== mcstat --ingest of $NSEEDS renders (640x480, plain float EXR) against stock oiiotool averaging them =="
# The reference: what a user without mcstat does with seed renders, their plain mean in oiiotool.
addall=("$out/seeds/seed_1.exr")
for s in $(seq 2 "$NSEEDS"); do addall+=("$out/seeds/seed_$s.exr" --add); done
meanref=$(measure "oiiotool" oiiotool "${addall[@]}" --divc "$NSEEDS" -o "$out/oiiotool-mean.exr")
ingest=$(measure "ingest" build/oiiotool-ext/mcstat --ingest "$out/seeds/seed_*.exr" -o "$out/ingested.mcstat")
ingestm=$(measure "ingest-mean" build/oiiotool-ext/mcstat --ingest "$out/seeds/seed_*.exr" --mean -o "$out/ingested-mean.exr")
ingestg=$(measure "ingest-gmon" build/oiiotool-ext/mcstat --ingest "$out/seeds/seed_*.exr" --gmon -o "$out/ingested-gmon.exr")
printf "%-48s %10s %9s %14s\n" "command" "wall" "ratio" "peak RSS"
printf '%s\n%s\n%s\n%s\n' "$meanref" "$ingest" "$ingestm" "$ingestg" | awk '
  NR == 1 { base = $2 }
  { if ($1 == "oiiotool") label = "oiiotool F1 F2 --add ... --divc N -o mean.exr"
    else if ($1 == "ingest") label = "mcstat --ingest FILES -o f.mcstat"
    else if ($1 == "ingest-mean") label = "mcstat --ingest FILES --mean -o m.exr"
    else label = "mcstat --ingest FILES --gmon -o g.exr"
    printf "%-48s %8.3f s %8.2fx %10.1f MiB\n", label, $2, $2 / base, $3 / 1024 }'
