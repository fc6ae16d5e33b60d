#!/usr/bin/env bash
# scripts/trade_cycles.sh: the trade (docs/trade.md) on real renders. Blender Cycles renders the test
# suite's caustic scene (tests/aovs/cycles_caustic.py: a glass sphere's fireflies over a checker
# floor, light groups and every light-path pass) as independent seeds, as a farm would, with and
# without Cycles' own firefly clamp; mcstat --ingest turns the seeds into a statistics file (one
# sub-buffer per seed) and every method runs on it. One row per scene, method and set of seeds in
# $OUT/trade.csv, in the columns of scripts/trade.sh, then the tables (scripts/trade_tables.py).
# Not part of the tests. About 20 minutes on 2 cores with the defaults.
#
# Time of a method = Cycles' render time of the seeds it needs (Blender's own "Time:" per render,
# start-up left out, as for mcstat and oiiotool) + mcstat -v's time for the ingest and its
# commands (oiiotool: the total --runstats reports). spp in the table = samples per pixel of the
# whole set (seeds x spp per seed). The mean also runs as one render of MEAN_FACTORS times the
# set's samples: the "render longer" curve of the equal-time ratios.
#
# Environment:
#   SCENES       NAME=CHECKER_SCALE, the floor checker's Scale per scene (default "detail=160
#                caustic=8": cells 0.025 wide, about 1.5 to 3 pixels at 256 x 192, and the test
#                suite's own 0.5-wide cells); the rows' scene is cycles-NAME
#   RES          image size (default "256 192")
#   SPP          samples per pixel of each seed (default 64)
#   SEEDS        seeds per set = sub-buffers M (default 9)
#   SETS         independent sets of seeds (default 2; set k uses seeds 100 k + 1 ..)
#   CLAMP        Cycles' sample_clamp_indirect of the clamped renders (default 10, Blender's default)
#   REF          "N SPP": the reference is the mean of N renders of SPP (default "8 2048")
#   MEAN_FACTORS the mean in one render of F x SEEDS x SPP samples (default 4)
#   ONLY         comma-separated method names to run (default: all); the mean always runs
#   BUILD        build folder (default build); SKIP_BUILD=1 uses it as it is
#   OUT          output folder (default out/trade-cycles), the trade's own: a new or empty folder,
#                or one an earlier run marked (.mcstat-trade); its renders are reused
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
OUT=${OUT:-out/trade-cycles}
SCENES=${SCENES:-detail=160 caustic=8}
RES=${RES:-256 192}
SPP=${SPP:-64}
SEEDS=${SEEDS:-9}
SETS=${SETS:-2}
CLAMP=${CLAMP:-10}
REF=${REF:-8 2048}
MEAN_FACTORS=${MEAN_FACTORS:-4}
ONLY=${ONLY:-}
source scripts/trade_lib.sh
trade_begin trade_cycles
mcstat=$BUILD/oiiotool-ext/mcstat
command -v blender >/dev/null || { echo "trade_cycles: blender is missing (scripts/install-deps.sh)" >&2; exit 1; }
command -v oiiotool >/dev/null || { echo "trade_cycles: oiiotool is missing (scripts/install-deps.sh)" >&2; exit 1; }
read -r W H <<<"$RES"
read -r REF_N REF_SPP <<<"$REF"
pixels=$((W * H))

# render DIR FIRST N SPP [CLAMP]: N Cycles renders DIR/seed_FIRST.exr ... (kept when present);
# sets t_cycles = the sum of Cycles' render times, start-up left out.
render() {
  local dir=$1 first=$2 n=$3 spp=$4 clamp=${5:-0}
  if [ ! -s "$dir/done" ]; then
    run tests/aovs/render_cycles_seeds.sh -n "$n" --first "$first" --spp "$spp" --res $RES \
      --checker-scale "$checker" --clamp-indirect "$clamp" -o "$dir"
    # Blender prints " Time: MM:SS.ss (Saving: ...)" once per written file.
    awk '/^ Time: / { split($2, a, ":"); t += a[1] * 60 + a[2] } END { printf "%.4f\n", t }' \
      "$dir/render.log" >"$dir/done"
  fi
  t_cycles=$(cat "$dir/done")
}

# ingest DIR NAME: the statistics file NAME.mcstat of DIR's seeds; sets t_ingest.
ingest() {
  run "$mcstat" -v --ingest "$1/seed_*.exr" -o "$2.mcstat"
  t_ingest=$(done_seconds)
}

# Every method of a statistics file (the per-sample methods, sample delaying, the reweighting and
# RPF, need per-sample records a
# renderer does not write).
stat_methods=(
  "mean|--mean" "MoN|--mon" "G-MoN|--gmon" "G-MoN_b|--gmonb" "G-MoN keeplight|--gmon:keeplight=1"
  "TMPE|--tmpe" "myriad|--myriad" "meridian|--meridian" "MPE+MIF|--median --mif"
  "TMPE+WMIF|--tmpe --wmif" "3DMF|--3dmf" "3DWMF|--3dwmf" "3DWTMF|--3dwtmf"
)

for entry in $SCENES; do
  name=${entry%%=*} checker=${entry#*=}
  scene=cycles-$name
  dir=$OUT/$scene
  mkdir -p "$dir"
  ref=$dir/ref.exr
  progress "$scene: reference, $REF_N x $REF_SPP spp"
  render "$dir/ref" 1000001 "$REF_N" "$REF_SPP"
  run "$mcstat" --ingest "$dir/ref/seed_*.exr" --mean -o "$ref"
  # The reference's own noise: its two halves against each other (relMSE of two halves is 4 x
  # the whole's share: 2 x for the difference of two, 2 x for half the samples).
  half=$((REF_N / 2))
  if [ "$half" -ge 1 ] && [ $((2 * half)) -eq "$REF_N" ]; then
    mkdir -p "$dir/ref-a" "$dir/ref-b"
    for ((i = 0; i < REF_N; i++)); do
      [ "$i" -lt "$half" ] && h=a || h=b
      ln -sf "../ref/seed_$((1000001 + i)).exr" "$dir/ref-$h/seed_$((1000001 + i)).exr"
    done
    run "$mcstat" --ingest "$dir/ref-a/seed_*.exr" --mean -o "$dir/ref-a.exr"
    run "$mcstat" --ingest "$dir/ref-b/seed_*.exr" --mean --diff "$dir/ref-a.exr"
    IFS=, read -r rel rest < <(metrics <"$log.out")
    row "$scene" reference "$((REF_N * REF_SPP))" 0 0 0 "$(awk -v r="$rel" 'BEGIN { printf "%.6g", r / 4 }'),$rest"
  fi

  for set in $(seq "$SETS"); do
    first=$((100 * set + 1))
    total=$((SEEDS * SPP))
    f=$dir/set$set
    # The seeds (M = SEEDS sub-buffers) and every statistics-file method over them.
    progress "$scene set $set: $SEEDS seeds"
    render "$f-seeds" "$first" "$SEEDS" "$SPP"
    t_seeds=$t_cycles
    ingest "$f-seeds" "$f"
    t_make=$(add "$t_seeds" "$t_ingest")
    stats_bytes=$(bytes_pp "$f.mcstat")
    args=(-v "$f.mcstat")
    names=()
    for m in "${stat_methods[@]}"; do
      { [ "${m%%|*}" = mean ] || wanted "${m%%|*}"; } || continue
      names+=("${m%%|*}")
      args+=(--dup ${m#*|} --diff "$ref" --pop)
    done
    run "$mcstat" "${args[@]}" --mean -o "$f-mean.exr"
    mapfile -t seg < <(segments)
    for i in "${!names[@]}"; do
      read -r t met <<<"${seg[$i]}"
      bytes=$stats_bytes
      if [ "${names[$i]}" = mean ]; then
        # The mean keeps no statistics file: one EXR of the seeds' average.
        t_mean=$(add "$t_make" "$t")
        bytes=$(bytes_pp "$f-mean.exr")
      fi
      row "$scene" "${names[$i]}" "$total" "$set" "$(add "$t_make" "$t")" "$bytes" "$met"
    done

    # oiiotool on the mean image: a clamp per channel at 30 / 3, a 3x3 median.
    oiiotool_rows "$f-mean.exr" "$t_mean" "$total" "$set" 30

    # Cycles' own clamp: the same seeds rendered clamped, their mean.
    if wanted "clamp $CLAMP (Cycles)"; then
      progress "$scene set $set: $SEEDS clamped seeds"
      render "$f-clamped" "$first" "$SEEDS" "$SPP" "$CLAMP"
      run "$mcstat" -v --ingest "$f-clamped/seed_*.exr" --mean -o "$f-clamped.exr" --diff "$ref"
      t=$(done_seconds)
      row "$scene" "clamp $CLAMP (Cycles)" "$total" "$set" "$(add "$t_cycles" "$t")" \
        "$(bytes_pp "$f-clamped.exr")" "$(metrics <"$log.out")"
    fi

    # The mean rendered longer, one render per factor.
    for k in $MEAN_FACTORS; do
      progress "$scene set $set: mean at $k x"
      render "$f-mean$k" "$first" 1 "$((k * total))"
      run "$mcstat" -v --ingest "$f-mean$k/seed_*.exr" --mean --diff "$ref"
      t=$(done_seconds)
      row "$scene" mean "$((k * total))" "$set" "$(add "$t_cycles" "$t")" \
        "$(bytes_pp "$f-mean.exr")" "$(metrics <"$log.out")"
    done
  done
done
[ -t 2 ] && echo >&2
echo "trade_cycles: $(($(wc -l <"$table") - 1)) rows in $table, measured in $((SECONDS - start)) s"
PYTHONPATH= /usr/bin/python3 scripts/trade_tables.py "$table" "$((SEEDS * SPP))"
