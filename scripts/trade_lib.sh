# scripts/trade_lib.sh: the helpers scripts/trade.sh and scripts/trade_cycles.sh share, sourced by
# both: running and timing a command, reading mcstat -v's times and --diff's metrics, writing rows
# of the trade table. They use the caller's $log (prefix of the last command's output files),
# $table (the CSV), $pixels (per image), $ONLY (methods to run, comma-separated; empty: all) and
# $start (for the progress line).

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
