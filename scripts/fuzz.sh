#!/usr/bin/env bash
# scripts/fuzz.sh [SECONDS] [TARGET...]: builds the libFuzzer targets (tests/fuzz/) with clang under
# ASan+UBSan in $BUILD (default build-fuzz) and runs each for SECONDS (default 60) of wall time,
# $JOBS at once (default: all of them, sharing the cores), starting from the seed corpus tests/fuzz/corpus/T
# and the inputs earlier runs kept ($BUILD/corpus/T), with the saved findings (tests/fuzz/regressions/T)
# run first with them. Any finding (crash, leak, timeout, out of
# memory, a broken contract) is saved under $BUILD/findings/T/ and makes the script fail. Each run
# appends one line to $BUILD/fuzz-ledger.tsv (date, target, wall and CPU seconds, executions,
# coverage, features, findings) and the script prints the totals: docs/fuzzing.md reports them.
# Built at -O1 -g1, as libFuzzer's documentation builds its targets (-g -O1; line tables are what
# a finding's stack needs) and as the sanitizer suite is: half the compile time of -O2 -g.
# Targets: stats_file stats_stream records scene plugin ingest (default: all). NICE=19 runs them at low
# priority (long runs next to other work); SKIP_BUILD=1 runs the targets already built.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
shift || true
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(stats_file stats_stream records scene plugin ingest)
build=${BUILD:-build-fuzz}
jobs=${JOBS:-${#targets[@]}}

command -v clang++ >/dev/null || { echo "fuzz: clang++ is missing (scripts/install-deps.sh)" >&2; exit 1; }
fuzz_names=()
for t in "${targets[@]}"; do fuzz_names+=("fuzz_$t"); done
[ -n "${SKIP_BUILD:-}" ] || CC=clang CXX=clang++ MCSTAT_TARGETS="${fuzz_names[*]}" scripts/build.sh "$build" \
  -DMCSTAT_FUZZ=ON -DMCSTAT_FUZZ_COVERAGE=all -DMCSTAT_WERROR=ON -DMCSTAT_BUILD_TESTS=OFF -DMCSTAT_BUILD_BENCHMARKS=OFF \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" >"$build.log" 2>&1 || { tail -40 "$build.log" >&2; exit 1; }

ledger="$build/fuzz-ledger.tsv"
[ -f "$ledger" ] || printf 'date\ttarget\twall_s\tcpu_s\texecutions\tcoverage\tfeatures\tfindings\n' >"$ledger"

run_one() {
  local t=$1 corpus="$build/corpus/$1" findings="$build/findings/$1" log="$build/logs/$1.log"
  mkdir -p "$corpus" "$findings" "$build/logs"
  local rc=0 before start
  # Saved findings run first with the corpus, every run (libFuzzer adds new inputs to the first
  # folder only, so these stay as they are).
  local regressions=()
  [ -d "tests/fuzz/regressions/$t" ] && regressions=("tests/fuzz/regressions/$t")
  before=$(ls "$findings" | wc -l)
  start=$(date +%s)
  ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=0 UBSAN_OPTIONS=print_stacktrace=1 \
    /usr/bin/time -o "$build/logs/$t.time" -f '%U %S' \
    nice -n "${NICE:-0}" "$build/tests/fuzz/fuzz_$t" -max_total_time="$seconds" -timeout=30 \
    -rss_limit_mb="${RSS_MB:-3072}" -malloc_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$findings/" \
    "$corpus" "tests/fuzz/corpus/$t" ${regressions[@]+"${regressions[@]}"} >"$log" 2>&1 || rc=$?
  local execs cov ft found cpu
  cpu=$(awk '/^[0-9.]+ [0-9.]+$/ { printf "%.0f", $1 + $2 }' "$build/logs/$t.time")
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  ft=$(grep -o 'ft: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  # A finding is an input saved; an interrupted run (Ctrl-C) saves none and is not one.
  found=$(($(ls "$findings" | wc -l) - before))
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$(date -u +%FT%TZ)" "$t" "$(($(date +%s) - start))" "${cpu:-0}" "${execs:-0}" \
    "${cov:-0}" "${ft:-0}" "$found" >>"$ledger"
  if [ "$found" -gt 0 ] || { [ $rc -ne 0 ] && [ $rc -ne 130 ] && [ $rc -ne 72 ]; }; then
    echo "fuzz: $t: FINDING (exit $rc); log $log, inputs in $findings/:" >&2
    grep -m5 -E 'ERROR|contract broken|SUMMARY|runtime error' "$log" >&2 || tail -5 "$log" >&2
    return 1
  fi
  echo "fuzz: $t: ${execs:-0} executions in ${seconds} s, coverage ${cov:-0}, features ${ft:-0}"
}

failed=0
pids=()
names=()
for t in "${targets[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n || true; done
  run_one "$t" &
  pids+=($!)
  names+=("$t")
done
for i in "${!pids[@]}"; do wait "${pids[$i]}" || failed=1; done

awk -F'\t' 'NR > 1 { s[$2] += $4; e[$2] += $5; f[$2] += $8 }
  END { for (t in s) printf "fuzz total: %s: %.2f CPU-hours, %d executions, %d findings\n", t, s[t] / 3600, e[t], f[t] }' \
  "$ledger" | sort
exit $failed
