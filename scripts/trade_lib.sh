# scripts/trade_lib.sh: the helpers scripts/trade.sh and scripts/trade_cycles.sh share, sourced by
# both: running and timing a command, reading mcstat -v's times and --diff's metrics, writing rows
# of the trade table. They use the caller's $log (prefix of the last command's output files),
# $table (the CSV), $pixels (per image), $ONLY (methods to run, comma-separated; empty: all) and
# $start (for the progress line).

# trade_begin WHO: what both scripts do before their first render: install and build unless
# SKIP_BUILD=1 ($BUILD), claim $OUT, write the table's header. Sets table, log and start.
# $OUT is the trade's own folder: it overwrites trade.csv, its renders and pictures there by name,
# so a folder holding files without the marker $OUT/.mcstat-trade is refused (docs/compare.md,
# "Report folders"); an earlier run's folder is taken back.
trade_begin() {
  if [ -d "$OUT" ] && [ ! -e "$OUT/.mcstat-trade" ] && [ -n "$(ls -A "$OUT")" ]; then
    echo "$1: $OUT holds files and is not a trade's folder (no .mcstat-trade): give OUT a new or empty folder" >&2
    exit 1
  fi
  if [ "${SKIP_BUILD:-0}" != 1 ]; then
    scripts/install-deps.sh
    scripts/build.sh "$BUILD" >/dev/null
  fi
  mkdir -p "$OUT"
  : >"$OUT/.mcstat-trade"
  table=$OUT/trade.csv
  echo "scene,method,spp,seed,seconds,bytesPerPixel,relMSE,SSIM,PSNR,fireflies,pixels,nbias,nnoise,detail,energy" >"$table"
  log=$OUT/last
  start=$SECONDS
}

# run CMD...: runs CMD with its output in $log.out / $log.err; stops the script if it fails.
run() {
  if ! "$@" >"$log.out" 2>"$log.err"; then
    echo "trade: failed: $*" >&2
    tail -5 "$log.err" >&2
    exit 1
  fi
}
# timed VAR CMD...: run, and VAR = its wall seconds.
timed() {
  local -n _seconds=$1
  shift
  local t0=$EPOCHREALTIME
  run "$@"
  _seconds=$(awk -v a="$t0" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.4f", b - a }')
}
# oiio_timed VAR ARGS...: runs oiiotool --runstats ARGS, and VAR = the time it reports (reading,
# the command, writing; not the process start, as mcstat -v's times are not).
oiio_timed() {
  local -n _oiio_seconds=$1
  shift
  run oiiotool --runstats "$@"
  _oiio_seconds=$(awk '/Total time:/ { sub("s", "", $3); print $3 }' "$log.out")
}
bytes_pp() { awk -v b="$(stat -c %s "$1")" -v p="$pixels" 'BEGIN { printf "%.1f", b / p }'; }
add() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.4f", a + b }'; }

# segments: from mcstat -v's stderr ($log.err) and stdout ($log.out) of a run made of
# "--dup CMDS... --diff REF --pop" segments, one line per segment: "SECONDS METRICS", SECONDS the
# file's read time plus the segment's commands (all but --dup, --diff, --pop; -o too when
# $with_output is 1), METRICS the --diff line's numbers as CSV.
segments() {
  local with_output=${1:-0}
  awk -v out="$with_output" 'BEGIN { n = 0 }
    / read .* in [0-9.]+ s$/ { read += $(NF - 1) }
    /^mcstat: [^ ]+ done in / {
      c = $2
      if (c == "--pop") { n++; next }
      if (c == "--dup" || c == "--diff" || (c == "-o" && !out)) next
      t[n] += $(NF - 1)
    }
    END { for (i = 0; i <= n; i++) printf "%.4f\n", read + t[i] }' "$log.err" >"$log.times"
  metrics <"$log.out" >"$log.metrics"
  paste -d' ' "$log.times" <(cat "$log.metrics")
}
# done_seconds: the sum of the times mcstat -v reports in $log.err for its commands ("--CMD done
# in S s"), --diff's left out.
done_seconds() {
  awk '/done in [0-9.]+ s$/ && !/--diff/ { t += $(NF - 1) } END { printf "%.4f\n", t }' "$log.err"
}
# oiiotool_rows MEAN_EXR T_MEAN SPP SEED CLAMPS...: stock oiiotool on the plain mean's image, as a
# compositor would use it: a clamp per channel at C / 3 for each C (as |R| + |G| + |B|) and a 3x3
# median, each timed (--runstats) on top of T_MEAN and diffed against $ref; one row each, scene
# $scene, files ${MEAN_EXR%.exr}-oclampC.exr and -omedian.exr.
oiiotool_rows() {
  local mean=$1 t_mean=$2 spp=$3 seed=$4 c v t i
  shift 4
  local base=${mean%.exr} diffs=() names=() met=()
  for c in "$@"; do
    wanted "clamp $c (oiiotool)" || continue
    v=$(awk -v c="$c" 'BEGIN { printf "%.6g", c / 3 }')
    oiio_timed t "$mean" --clamp:max="$v" -o "$base-oclamp$c.exr"
    names+=("clamp $c (oiiotool)|$(add "$t_mean" "$t")")
    diffs+=("$base-oclamp$c.exr" --diff "$ref")
  done
  if wanted "median 3x3 (oiiotool)"; then
    oiio_timed t "$mean" --median 3x3 -o "$base-omedian.exr"
    names+=("median 3x3 (oiiotool)|$(add "$t_mean" "$t")")
    diffs+=("$base-omedian.exr" --diff "$ref")
  fi
  [ ${#names[@]} -gt 0 ] || return 0
  run "$mcstat" "${diffs[@]}"
  mapfile -t met < <(metrics <"$log.out")
  for i in "${!names[@]}"; do
    row "$scene" "${names[$i]%%|*}" "$spp" "$seed" "${names[$i]#*|}" "$(bytes_pp "$mean")" "${met[$i]}"
  done
}
# metrics: every --diff line on stdin as relMSE,SSIM,PSNR,fireflies,pixels,nbias,nnoise,detail,energy.
metrics() {
  awk '/ relMSE / {
    for (i = 1; i <= NF; i++) {
      if ($i == "relMSE") r = $(i + 1); if ($i == "SSIM") s = $(i + 1); if ($i == "PSNR") p = $(i + 1)
      if ($i == "fireflies") { f = $(i + 1); px = $(i + 3) }
      if ($i == "nbias") b = $(i + 1); if ($i == "nnoise") z = $(i + 1)
      if ($i == "detail") d = $(i + 1); if ($i == "energy") e = $(i + 1)
    }
    printf "%s,%s,%s,%s,%s,%s,%s,%s,%s\n", r, s, p, f, px, b, z, d, e }'
}
# row SCENE METHOD SPP SEED SECONDS BYTES METRICS
row() { echo "$1,$2,$3,$4,$5,$6,$7" >>"$table"; }
# wanted NAME: whether ONLY lets method NAME run.
wanted() { [ -z "$ONLY" ] || [[ ",$ONLY," == *",$1,"* ]]; }
progress() { [ -t 2 ] && printf '\rtrade: %-60s %4d s' "$1" "$((SECONDS - start))" >&2 || true; }
# keep_ran LIST: the comma-separated method names of LIST that ONLY lets run (the mean always runs).
keep_ran() {
  local out="" m
  IFS=, read -ra ms <<<"$1"
  for m in "${ms[@]}"; do
    { [ "$m" = mean ] || wanted "$m"; } && out+="${out:+,}$m"
  done
  echo "$out"
}
