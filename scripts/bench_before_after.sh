#!/usr/bin/env bash
# scripts/bench_before_after.sh BEFORE_BUILD AFTER_BUILD [OUT]: is a change free? The estimators'
# compute and the file-level G-MoN of two builds (e.g. a git worktree of the commit before a
# refactor, built with scripts/build.sh, and this tree's build/), measured interleaved in one run
# so that the machine's drift falls on both: RUNS rounds, each runs BEFORE's then AFTER's
# bench_estimators (one thread, a 256 x 256 image, M = 21: ns per pixel as 1e9 / items_per_second)
# and `mcstat FILE --gmon -o` on a 1920 x 1080, M = 21 file (streamed read, estimate, write;
# seconds). Prints a Markdown table of medians, ratios and spreads (docs/benchmarks.md). Run it
# with nothing else on the machine. OUT (a new folder; default a fresh one under /tmp) keeps the
# file and each run's JSON.
set -euo pipefail
before=$(cd "${1:?usage: bench_before_after.sh BEFORE_BUILD AFTER_BUILD [OUT]}" && pwd)
after=$(cd "${2:?usage: bench_before_after.sh BEFORE_BUILD AFTER_BUILD [OUT]}" && pwd)
out=${3:-$(mktemp -d /tmp/bench-before-after.XXXXXX)}
[ ! -e "$out" ] || [ -z "$(ls -A "$out")" ] || { echo "bench_before_after: $out is not empty" >&2; exit 1; }
mkdir -p "$out"
runs=${RUNS:-5}
filter=${FILTER:-'^estimate/(mean|median|gmon|gmonb|tmpe|myriad|meridian)/lum/21$|^estimate/(mif|3dmf)/lum(/21)?$'}
for b in "$before" "$after"; do
  for exe in tests/bench/bench_estimators oiiotool-ext/mcstat; do
    [ -x "$b/$exe" ] || { echo "bench_before_after: no $b/$exe (build it first)" >&2; exit 1; }
  done
done
"$after/render-fixture/mcstat-render" --scene default --res 1920 1080 --spp 21 --M 21 --quiet \
  -o "$out/1080p.mcstat"
for r in $(seq "$runs"); do
  for side in before after; do
    b=$before
    [ $side = before ] || b=$after
    "$b/tests/bench/bench_estimators" --benchmark_filter="$filter" --benchmark_min_time=0.5 \
      --benchmark_format=json >"$out/$side-$r.json" 2>/dev/null
    s=$(date +%s.%N)
    "$b/oiiotool-ext/mcstat" "$out/1080p.mcstat" --gmon -o "$out/$side.exr"
    e=$(date +%s.%N)
    echo "$s $e" >"$out/$side-$r.file"
  done
  echo "bench_before_after: round $r of $runs" >&2
done
python3 - "$out" "$runs" <<'EOF'
import json, statistics, sys
out, runs = sys.argv[1], int(sys.argv[2])
rows = {}
for side in ("before", "after"):
    for r in range(1, runs + 1):
        for b in json.load(open(f"{out}/{side}-{r}.json"))["benchmarks"]:
            rows.setdefault(b["name"], {"before": [], "after": []})[side].append(1e9 / b["items_per_second"])
        s, e = map(float, open(f"{out}/{side}-{r}.file").read().split())
        rows.setdefault("mcstat FILE --gmon -o, 1080p (s)", {"before": [], "after": []})[side].append(e - s)
print("| benchmark | before | after | after / before | spread before | spread after |")
print("|---|---|---|---|---|---|")
for name, v in rows.items():
    mb, ma = statistics.median(v["before"]), statistics.median(v["after"])
    f = (lambda x: f"{x:.3f}") if "(s)" in name else (lambda x: f"{x:.4g}")
    print(f"| {name} | {f(mb)} | {f(ma)} | {ma / mb:.3f} | {f(min(v['before']))}-{f(max(v['before']))} "
          f"| {f(min(v['after']))}-{f(max(v['after']))} |")
EOF
