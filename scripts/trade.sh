#!/usr/bin/env bash
# scripts/trade.sh: the speed/accuracy trade of every method family (docs/trade.md). Renders every
# fixture scene at several spp with independent seeds, runs every method on the same renders, and
# writes one row per scene, method, spp and seed to $OUT/trade.csv: wall seconds (render +
# estimate, this machine), bytes per pixel of what the method needs on disk, and the --diff
# metrics against a high-spp reference (relMSE, SSIM, PSNR, fireflies, nbias, nnoise, detail,
# energy). Then prints
# the tables of docs/trade.md (scripts/trade_tables.py) and draws relMSE against time and against
# bytes per pixel for every scene with `mcstat --tradeplot`. Not part of the tests; part of
# scripts/bench.sh (section trade). About 25 minutes on 2 cores with the defaults.
#
# Methods: the mean; the renderer's clamp (mcstat-render --clamp C, Cycles' rule) and oiiotool's
# (--clamp:max=C/3 on the mean, per channel); oiiotool's 3x3 median of the mean; MoN, G-MoN,
# G-MoN_b, G-MoN keeping its light (:keeplight=1, docs/keep-light.md); Jung's TMPE, myriad,
# meridian, MPE+MIF, TMPE+WMIF, 3DMF, 3DWMF, 3DWTMF; Pajot's
# ADR/ROT/hybrid run online by the renderer; the reweighting (Zirr et al.) run online, as the paper
# gives it and as the energy-keeping variant (kappa=1:spread=8, docs/reweighting.md); RPF from
# --keep-samples; G-MoN of a compact file. Time of a method = the wall time of the render it
# needs (process start to exit) + the time mcstat -v reports for reading the file and running
# the method's commands (for oiiotool, the total time --runstats reports, after the mean's). The
# mean is a plain render (M = 1, what a renderer writes) and also runs at MEAN_SPPS: the curve
# for equal-time comparisons.
#
# Environment:
#   SCENES     fixture scenes (default: all eight, and detail, the fireflies over pixel-scale
#              detail, which needs RES 256 192 or more to show it)
#   SPPS       samples per pixel of every method (default "16 64 256")
#   SEEDS      independent seeds per spp (default 5)
#   RES        image size (default "64 48")
#   BUFFERS    sub-buffers M of the statistics files (default 9)
#   REF_SPP    samples of each of the two references per scene (default 8192), but for the scenes
#              REF_SPP_SCENES names as SCENE=SPP (default "default=32768 caustic=65536": their
#              references are the noisiest, and their noise floors every method's relMSE)
#   RPF_SPPS   spp at which RPF runs (default 16: RPF takes 4 s at 16 spp here, on both cores)
#   MEAN_SPPS  extra spp of the mean alone (default 1024)
#   CLAMPS     clamp limits C, as |R|+|G|+|B| (default "3 30")
#   ONLY       comma-separated method names to run (default: every method; the mean always
#              runs, every other method's time is weighed against it), e.g. for large images
#              ONLY="G-MoN,G-MoN keeplight,median 3x3 (oiiotool),clamp 30 (renderer)"
#   BUILD      build folder (default build); SKIP_BUILD=1 uses it as it is
#   OUT        output folder (default out/trade), the trade's own: a new or empty folder, or one an
#              earlier run marked (.mcstat-trade); the table is written afresh
#   REUSE_REFS 1: keep the references an earlier run left in OUT, when made at the same RES and
#              spp (default 0: render them again)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
OUT=${OUT:-out/trade}
SCENES=${SCENES:-default caustic dof furnace motion texture arealight tiny detail}
SPPS=${SPPS:-16 64 256}
SEEDS=${SEEDS:-5}
RES=${RES:-64 48}
BUFFERS=${BUFFERS:-9}
REF_SPP=${REF_SPP:-8192}
REF_SPP_SCENES=${REF_SPP_SCENES-default=32768 caustic=65536}
RPF_SPPS=${RPF_SPPS:-16}
MEAN_SPPS=${MEAN_SPPS:-1024}
CLAMPS=${CLAMPS:-3 30}
ONLY=${ONLY:-}
# The helpers: trade_begin, run, timed, oiio_timed, bytes_pp, add, segments, done_seconds,
# oiiotool_rows, metrics, row, wanted, keep_ran, progress.
source scripts/trade_lib.sh
trade_begin trade
mcstat=$BUILD/oiiotool-ext/mcstat
render=$BUILD/render-fixture/mcstat-render
command -v oiiotool >/dev/null || { echo "trade: oiiotool is missing (scripts/install-deps.sh)" >&2; exit 1; }
read -r W H <<<"$RES"
pixels=$((W * H))

# plain_mean: the plain render of $scene at $spp, $seed (M = 1, as a renderer writes its beauty)
# and its mean, $f-mean.exr: the baseline's row; sets t_mean.
plain_mean() {
  local t_r t met mean_bytes
  timed t_r "$render" --scene "$scene" --res $RES --spp "$spp" --M 1 --seed "$seed" --quiet -o "$f-plain.mcstat"
  run "$mcstat" -v "$f-plain.mcstat" --dup --mean -o "$f-mean.exr" --diff "$ref" --pop
  read -r t met < <(segments)
  t_mean=$(add "$t_r" "$t")
  mean_bytes=$(bytes_pp "$f-mean.exr")
  row "$scene" mean "$spp" "$seed" "$t_mean" "$mean_bytes" "$met"
  rm -f "$f-plain.mcstat"
}

# The statistics-file methods, "NAME|COMMANDS", each run as --dup COMMANDS --diff REF --pop.
stat_methods=(
  "MoN|--mon" "G-MoN|--gmon" "G-MoN_b|--gmonb" "G-MoN keeplight|--gmon:keeplight=1"
  "TMPE|--tmpe" "myriad|--myriad"
  "meridian|--meridian" "MPE+MIF|--median --mif" "TMPE+WMIF|--tmpe --wmif" "3DMF|--3dmf"
  "3DWMF|--3dwmf" "3DWTMF|--3dwtmf"
)
all_stat_methods=("${stat_methods[@]}")
stat_methods=()
for m in "${all_stat_methods[@]}"; do wanted "${m%%|*}" && stat_methods+=("$m"); done

for scene in $SCENES; do
  dir=$OUT/$scene
  mkdir -p "$dir"
  ref=$dir/ref.exr
  # Two references with seeds no method uses: the second measures the first's own noise
  # (E relMSE(ref2 vs ref) = 2 x the reference's share of any method's relMSE).
  ref_spp=$REF_SPP
  for s in $REF_SPP_SCENES; do [ "${s%%=*}" = "$scene" ] && ref_spp=${s#*=}; done
  progress "$scene: references"
  # REUSE_REFS=1 keeps the references of an earlier run into the same OUT with the same RES and
  # REF_SPP (they take most of a large run's time); the sidecar says what they were made with.
  refs_made="$scene $RES $ref_spp"
  if [ "${REUSE_REFS:-0}" != 1 ] || [ "$(cat "$dir/refs.txt" 2>/dev/null)" != "$refs_made" ]; then
    rm -f "$dir/refs.txt"
    run "$render" --scene "$scene" --res $RES --spp "$ref_spp" --seed 1000001 --reference --quiet -o "$ref"
    run "$render" --scene "$scene" --res $RES --spp "$ref_spp" --seed 1000002 --reference --quiet -o "$dir/ref2.exr"
    echo "$refs_made" >"$dir/refs.txt"
  fi
  run "$mcstat" "$dir/ref2.exr" --diff "$ref"
  IFS=, read -r rel rest < <(metrics <"$log.out")
  row "$scene" reference "$ref_spp" 0 0 0 "$(awk -v r="$rel" 'BEGIN { printf "%.6g", r / 2 }'),$rest"

  for seed in $(seq "$SEEDS"); do
    for spp in $SPPS; do
      progress "$scene seed $seed spp $spp"
      f=$dir/s$seed-$spp
      plain_mean
      # The statistics file (M sub-buffers) and every method over it, in one mcstat -v run.
      timed t_render "$render" --scene "$scene" --res $RES --spp "$spp" --M "$BUFFERS" --seed "$seed" --quiet -o "$f.mcstat"
      stats_bytes=$(bytes_pp "$f.mcstat")
      if [ ${#stat_methods[@]} -gt 0 ]; then
        args=(-v "$f.mcstat")
        for m in "${stat_methods[@]}"; do args+=(--dup ${m#*|} --diff "$ref" --pop); done
        run "$mcstat" "${args[@]}"
        mapfile -t seg < <(segments)
        for i in "${!stat_methods[@]}"; do
          read -r t met <<<"${seg[$i]}"
          row "$scene" "${stat_methods[$i]%%|*}" "$spp" "$seed" "$(add "$t_render" "$t")" "$stats_bytes" "$met"
        done
      fi

      # oiiotool on the mean image: clamp per channel, 3x3 median.
      oiiotool_rows "$f-mean.exr" "$t_mean" "$spp" "$seed" $CLAMPS

      # G-MoN of the compact file (the compaction runs when -o writes it).
      if wanted "G-MoN (compact)"; then
        run "$mcstat" -v "$f.mcstat" --dup --compact -o "$f-compact.mcstat" --pop
        t_compact=$(segments 1 | head -1 | cut -d' ' -f1)
        run "$mcstat" -v "$f-compact.mcstat" --dup --gmon --diff "$ref" --pop
        read -r t met < <(segments)
        row "$scene" "G-MoN (compact)" "$spp" "$seed" "$(add "$(add "$t_render" "$t_compact")" "$t")" \
          "$(bytes_pp "$f-compact.mcstat")" "$met"
      fi

      # The renderer's clamp: another render, its mean.
      for c in $CLAMPS; do
        wanted "clamp $c (renderer)" || continue
        timed t_r "$render" --scene "$scene" --res $RES --spp "$spp" --M 1 --seed "$seed" --clamp "$c" --quiet -o "$f-rclamp.mcstat"
        run "$mcstat" -v "$f-rclamp.mcstat" --dup --mean -o "$f-rclamp.exr" --diff "$ref" --pop
        read -r t met < <(segments)
        row "$scene" "clamp $c (renderer)" "$spp" "$seed" "$(add "$t_r" "$t")" "$(bytes_pp "$f-rclamp.exr")" "$met"
      done

      # Online per-sample methods: Pajot's three, the reweighting.
      for online in "Pajot ADR|--online pajot:method=adr|--pajot" \
        "Pajot ROT|--online pajot:method=rot|--pajot" \
        "Pajot hybrid|--online pajot:method=hybrid|--pajot" "reweight|--online reweight|--reweight"; do
        IFS='|' read -r name flags cmd <<<"$online"
        wanted "$name" || { [ "$cmd" = --reweight ] && wanted "reweight kappa=1 spread=8"; } || continue
        timed t_r "$render" --scene "$scene" --res $RES --spp "$spp" --M 1 --seed "$seed" $flags --quiet -o "$f-online.mcstat"
        # The reweighting's cascades also give the energy-keeping variant (docs/reweighting.md).
        variant=()
        [ "$cmd" = --reweight ] && variant=(--dup --reweight:kappa=1:spread=8 --diff "$ref" --pop)
        run "$mcstat" -v "$f-online.mcstat" --dup $cmd --diff "$ref" --pop ${variant[@]+"${variant[@]}"}
        mapfile -t seg < <(segments)
        read -r t met <<<"${seg[0]}"
        row "$scene" "$name" "$spp" "$seed" "$(add "$t_r" "$t")" "$(bytes_pp "$f-online.mcstat")" "$met"
        if [ ${#variant[@]} -gt 0 ]; then
          read -r t met <<<"${seg[1]}"
          row "$scene" "reweight kappa=1 spread=8" "$spp" "$seed" "$(add "$t_r" "$t")" "$(bytes_pp "$f-online.mcstat")" "$met"
        fi
      done

      # RPF from the per-sample records.
      if [[ " $RPF_SPPS " == *" $spp "* ]] && wanted RPF; then
        timed t_r "$render" --scene "$scene" --res $RES --spp "$spp" --M 1 --seed "$seed" --keep-samples --quiet -o "$f-samples.mcstat"
        run "$mcstat" -v "$f-samples.mcstat" --dup --rpf --diff "$ref" --pop
        read -r t met < <(segments)
        row "$scene" RPF "$spp" "$seed" "$(add "$t_r" "$t")" "$(bytes_pp "$f-samples.mcstat")" "$met"
        rm -f "$f-samples.mcstat"
      fi
      rm -f "$f-online.mcstat" "$f-rclamp.mcstat" "$f-rclamp.exr" "$f"-mean-oclamp*.exr "$f-mean-omedian.exr"
    done
    # The mean alone at more samples: the curve every method's time is weighed against.
    for spp in $MEAN_SPPS; do
      progress "$scene seed $seed mean at spp $spp"
      f=$dir/s$seed-$spp
      plain_mean
    done
  done
done
[ -t 2 ] && echo >&2
echo "trade: $(($(wc -l <"$table") - 1)) rows in $table, measured in $((SECONDS - start)) s"

# The pictures: relMSE against time and against bytes per pixel, per scene, for a method of each
# family (every method is in the tables; PLOT_METHODS, PLOT_METHODS_BYTES choose others).
PLOT_METHODS=${PLOT_METHODS:-mean,clamp 3 (renderer),clamp 3 (oiiotool),median 3x3 (oiiotool),MoN,G-MoN,G-MoN keeplight,TMPE+WMIF,3DWTMF,Pajot ROT,reweight,reweight kappa=1 spread=8,RPF}
PLOT_METHODS_BYTES=${PLOT_METHODS_BYTES:-mean,clamp 3 (renderer),G-MoN,G-MoN (compact),Pajot ROT,reweight,RPF}
PLOT_METHODS=$(keep_ran "$PLOT_METHODS")
PLOT_METHODS_BYTES=$(keep_ran "$PLOT_METHODS_BYTES")
for scene in $SCENES; do
  "$mcstat" "--tradeplot:scene=$scene:x=seconds:methods=$PLOT_METHODS" "$table" -o "$OUT/trade-$scene-time.png"
  "$mcstat" "--tradeplot:scene=$scene:x=bytes:methods=$PLOT_METHODS_BYTES" "$table" -o "$OUT/trade-$scene-bytes.png"
done
PYTHONPATH= /usr/bin/python3 scripts/trade_tables.py "$table"
