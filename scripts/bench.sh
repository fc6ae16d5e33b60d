#!/usr/bin/env bash
# Benchmarks (never part of the test suite); prints the tables of docs/benchmarks.md. Every speed
# figure is a ratio against a reference measured in the same run: the plain mean (estimators),
# stock oiiotool reading the same file's sub-buffer part (statistics files), stock oiiotool
# reading both files' sub-buffer parts (compare), stock oiiotool averaging the same renders
# (ingest), the beauty alone and stock oiiotool reading the same parts (AOVs), M = 1 (renderer).
#
#   scripts/bench.sh                 all sections
#   SECTIONS="file height" scripts/bench.sh
#
# Environment:
#   SECTIONS  any of: estimators threads registry file height compare compact goals ingest aovs
#             render trade (default: all)
#   REPS      runs per command, alternated, medians reported (default 4)
#   BASELINE  a folder holding an older build's mcstat and mcstat.imageio.so: the file table then
#             shows its figures beside today's, measured in the same run (docs/benchmarks.md)
#   BUILD     the build folder (default build): BUILD/oiiotool-ext/mcstat, BUILD/render-fixture/
#             mcstat-render, BUILD/oiio-plugin/mcstat.imageio.so, BUILD/tests/bench/bench_estimators
#   OUT       where the inputs are rendered once and reused, and outputs written (default out/bench)
#   NSEEDS    seed renders of the ingest and aovs sections (default 21); AOVS_RES, AOVS_SPP their
#             size and spp in the aovs section (default "960 540", 4)
#   REFRESH   1: render every input again (default: reuse those in OUT)
#   REGISTRY_REPS  runs per command of the registry section's CLI tables (default 1);
#             REGISTRY_SKIP_INPROCESS=1 leaves out its in-process table
#   COMPACT_RES, COMPACT_SPP  the file of the compact section (default "1920 1080", 64; the fewer
#             samples per buffer, the more pixels keep their buffers: docs/compact.md)
set -euo pipefail
cd "$(dirname "$0")/.."
REPS=${REPS:-4}
SECTIONS=${SECTIONS:-estimators threads registry file height compare compact goals ingest aovs render trade}
BUILD=${BUILD:-build}
BASELINE=${BASELINE:-}
if [ "${SKIP_BUILD:-0}" != 1 ]; then
  scripts/install-deps.sh
  scripts/build.sh "$BUILD" >/dev/null
fi
out=${OUT:-out/bench}; mkdir -p "$out"
mcstat=$BUILD/oiiotool-ext/mcstat
render=$BUILD/render-fixture/mcstat-render
want() { [[ " $SECTIONS " == *" $1 "* ]]; }

# run_alternating NAME... : runs the commands "${cmd_NAME[@]}" REPS times each, alternately, and
# sets med_NAME (median wall s), cpu_NAME (median user+sys s) and rss_NAME (max peak RSS, MiB).
run_alternating() {
  local name rep
  for name in "$@"; do eval "t_$name=(); c_$name=(); m_$name=()"; done
  for rep in $(seq "$REPS"); do
    for name in "$@"; do
      local -n cmd="cmd_$name"
      if ! /usr/bin/time -f "%e %U %S %M" -o "$out/time.txt" "${cmd[@]}" >/dev/null 2>"$out/err.txt"; then
        echo "bench: $name failed: ${cmd[*]}" >&2; cat "$out/err.txt" >&2; exit 1
      fi
      local t u s m; read -r t u s m <"$out/time.txt"
      eval "t_$name+=($t); c_$name+=($(echo "$u + $s" | bc)); m_$name+=($m)"
    done
  done
  for name in "$@"; do
    local -n ts="t_$name" cs="c_$name" ms="m_$name"
    printf -v "med_$name" '%s' "$(printf '%s\n' "${ts[@]}" | sort -n | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}')"
    printf -v "cpu_$name" '%s' "$(printf '%s\n' "${cs[@]}" | sort -n | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}')"
    printf -v "rss_$name" '%s' "$(printf '%s\n' "${ms[@]}" | sort -n | tail -1 | awk '{printf "%.0f", $1 / 1024}')"
  done
}

# A statistics file of the default scene, rendered once and reused (REFRESH=1 renders again).
stats_file() {  # stats_file PATH WIDTH HEIGHT SPP [SEED]
  if [ ! -f "$1" ] || [ "${REFRESH:-0}" = 1 ]; then
    "$render" --scene default --res "$2" "$3" --spp "$4" --M 21 --seed "${5:-3}" --quiet -o "$1"
  fi
}

if want estimators; then
  echo "== Estimator compute: 256x256 synthetic pixels, 1% firefly buffers, one thread =="
  "$BUILD"/tests/bench/bench_estimators --benchmark_filter='^estimate/' --benchmark_format=csv \
    2>/dev/null >"$out/estimators.csv"
  printf "%-22s %4s %12s %22s %14s\n" "estimator/mode" "M" "Mpixel/s" "M pixel-buffers/s" "time / mean's"
  awk -F, 'NR > 1 {
      gsub(/"/, "", $1); split($1, a, "/");   # estimate/NAME/MODE/M
      key = a[2] "/" a[3]; rate[key "@" a[4]] = $7; keys[key "@" a[4]] = 1 }
    END { for (k in keys) { split(k, b, "@");
            printf "%-22s %4d %12.2f %22.1f %14.2f\n", b[1], b[2], rate[k] / 1e6, rate[k] * b[2] / 1e6,
                   rate["mean/lum@" b[2]] / rate[k] } }' "$out/estimators.csv" | sort -k1,1 -k2,2n
  echo
fi

if want threads; then
  echo "== Thread scaling of the estimator image loop: 1920x1080, M = 21, luminance mode =="
  "$BUILD"/tests/bench/bench_estimators --benchmark_filter='^threads/' --benchmark_format=csv \
    2>/dev/null >"$out/threads.csv"
  printf "%-12s %14s %14s %10s\n" "estimator" "1 thread ms" "2 threads ms" "speed-up"
  awk -F, 'NR > 1 { gsub(/"/, "", $1); split($1, a, "/"); t[a[2] "@" a[4]] = $3; n[a[2]] = 1 }
    END { for (e in n) if ((e "@1") in t && (e "@2") in t)
            printf "%-12s %14.1f %14.1f %9.2fx\n", e, t[e "@1"], t[e "@2"], t[e "@1"] / t[e "@2"] }' \
    "$out/threads.csv" | sort
  echo
fi

if want registry; then
  # Every operation of the registry (issue 52): in process over a synthetic 1920x1080, M = 21
  # image (bench_estimators registry/*, each row in its own process for its peak memory, the
  # synthetic input's own peak taken off), then as a user runs it, `mcstat F --OP -o o.exr` on the
  # file section's render, on all cores and with --threads 1, against stock oiiotool reading the
  # same file's sub-buffer part. The per-sample operations read records: a 160x90 render with
  # --keep-samples, against stock oiiotool reading its records part.
  bench=$BUILD/tests/bench/bench_estimators
  ops=$("$bench" --benchmark_list_tests | sed -n 's|^registry/\([^/]*\)/1080p/1/.*|\1|p')
  sample_ops=$("$bench" --benchmark_list_tests | sed -n 's|^registry-samples/\([^/]*\)/.*|\1|p')
  /usr/bin/time -f "%M" -o "$out/time.txt" "$bench" --benchmark_filter='^registry/input/' >/dev/null 2>&1
  base_kib=$(cat "$out/time.txt")
  image_ops=" $("$bench" --benchmark_list_tests | sed -n 's|^registry-image/\([^/]*\)/.*|\1|p' | tr '\n' ' ') "
  if [ "${REGISTRY_SKIP_INPROCESS:-0}" != 1 ]; then
  echo "== Every operation in process: 1920x1080 synthetic, M = 21, lum, registry defaults; medians of 3 =="
  printf "%-10s | %10s %10s %8s | %16s\n" "operation" "1 core ms" "2 cores ms" "speed-up" "peak MiB (+input)"
  for op in $ops; do
    /usr/bin/time -f "%M" -o "$out/time.txt" "$bench" --benchmark_filter="^registry/$op/1080p/" \
      --benchmark_format=csv --benchmark_report_aggregates_only=true 2>/dev/null >"$out/reg.csv"
    awk -F, -v op="$op" -v peak="$(cat "$out/time.txt")" -v base="$base_kib" '
      /_median"/ { gsub(/"/, "", $1); split($1, a, "/"); t[a[4]] = $3 }
      END { printf "%-10s | %10.0f %10.0f %7.2fx | %16.0f\n", op, t[1], t[2], t[1] / t[2], (peak - base) / 1024 }' \
      "$out/reg.csv"
  done
  echo
  fi
  zip=$out/bench-1920x1080-M21.mcstat
  stats_file "$zip" 1920 1080 64
  cmd_ref=(oiiotool "$zip" --subimage 1 --stats)
  names=(ref)
  for op in $ops; do
    # An image filter runs over the plain mean, as a user writes it: F --mean --mif.
    first=""; [[ "$image_ops" == *" $op "* ]] && first="--mean"
    eval "cmd_a_$op=(\"\$mcstat\" \"\$zip\" $first --$op -o \"\$out/o.exr\")"
    eval "cmd_1_$op=(\"\$mcstat\" --threads 1 \"\$zip\" $first --$op -o \"\$out/o.exr\")"
    names+=("a_$op" "1_$op")
  done
  REPS=${REGISTRY_REPS:-1} run_alternating "${names[@]}"
  echo "== Every operation on $zip ($(du -h "$zip" | cut -f1)), as a user runs it; medians of ${REGISTRY_REPS:-1} =="
  printf "%-28s | %8s %8s | %10s %8s | %9s\n" "command" "wall s" "/ ref" "1 core s" "/ ref" "peak MiB"
  printf "%-28s | %8.2f %7.2fx | %10s %8s | %9s\n" "oiiotool F --subimage 1 --stats" "$med_ref" 1 "" "" "$rss_ref"
  for op in $ops; do
    a=med_a_$op; o=med_1_$op; r=rss_a_$op
    first=""; [[ "$image_ops" == *" $op "* ]] && first="--mean "
    printf "%-28s | %8.2f %7.2fx | %10.2f %7.2fx | %9s\n" "mcstat F $first--$op" "${!a}" \
      "$(echo "${!a} / $med_ref" | bc -l)" "${!o}" "$(echo "${!o} / $med_ref" | bc -l)" "${!r}"
  done
  rec=$out/bench-160x90-records.mcstat
  if [ ! -f "$rec" ] || [ "${REFRESH:-0}" = 1 ]; then
    "$render" --scene default --res 160 90 --spp 16 --M 21 --seed 3 --keep-samples --quiet -o "$rec"
  fi
  cmd_ref=(oiiotool "$rec" --subimage 4 --stats)
  names=(ref)
  for op in $sample_ops; do
    eval "cmd_a_$op=(\"\$mcstat\" \"\$rec\" --$op -o \"\$out/o.exr\")"
    eval "cmd_1_$op=(\"\$mcstat\" --threads 1 \"\$rec\" --$op -o \"\$out/o.exr\")"
    names+=("a_$op" "1_$op")
  done
  REPS=${REGISTRY_REPS:-1} run_alternating "${names[@]}"
  printf "%-28s | %8.2f %7.2fx | %10s %8s | %9s\n" "oiiotool R --subimage 4 --stats" "$med_ref" 1 "" "" "$rss_ref"
  for op in $sample_ops; do
    a=med_a_$op; o=med_1_$op; r=rss_a_$op
    printf "%-28s | %8.2f %7.2fx | %10.2f %7.2fx | %9s\n" "mcstat R --$op" "${!a}" \
      "$(echo "${!a} / $med_ref" | bc -l)" "${!o}" "$(echo "${!o} / $med_ref" | bc -l)" "${!r}"
  done
  echo "(R: $rec, $(du -h "$rec" | cut -f1), 16 spp with every sample's record)"
  echo
fi

if want file; then
  zip=$out/bench-1920x1080-M21.mcstat
  stats_file "$zip" 1920 1080 64
  raw=$out/bench-1920x1080-M21-none.mcstat
  if [ ! -f "$raw" ] || [ "$raw" -ot "$zip" ]; then
    oiiotool -a "$zip" --compression none -o "$out/none.exr" && mv "$out/none.exr" "$raw"
  fi
  for f in "$zip" "$raw"; do
    echo "== $f ($(du -h "$f" | cut -f1)): wall / stock oiiotool reading the sub-buffer part, 2 cores, medians of $REPS =="
    cmd_ref=(oiiotool "$f" --subimage 1 --stats)
    # file_cmds PREFIX MCSTAT PLUGIN_DIR: today's commands (PREFIX "") or the baseline's ("b").
    file_cmds() {
      local op
      for op in gmon mean mon tmpe mer myr w3d; do
        local flag=$op
        case $op in mer) flag=meridian ;; myr) flag=myriad ;; w3d) flag=3dwtmf ;; esac
        eval "cmd_$1$op=(\"\$2\" \"\$f\" --$flag -o \"\$out/o.exr\")"
        names+=("$1$op")
      done
      eval "cmd_$1plug=(env OIIO_LIBRARY_PATH=\"\$3\" oiiotool \"\$f\" --subimage 0 -o \"\$out/o.exr\")"
      names+=("$1plug")
    }
    names=(ref)
    file_cmds "" "$mcstat" "$BUILD/oiio-plugin"
    if [ -n "$BASELINE" ]; then file_cmds b "$BASELINE/mcstat" "$BASELINE"; fi
    run_alternating "${names[@]}"
    label() {
      case $1 in
        ref) echo "oiiotool F --subimage 1 --stats" ;; gmon) echo "mcstat F --gmon -o o.exr" ;;
        mean) echo "mcstat F --mean -o o.exr" ;; mon) echo "mcstat F --mon -o o.exr" ;;
        tmpe) echo "mcstat F --tmpe -o o.exr" ;; w3d) echo "mcstat F --3dwtmf -o o.exr" ;;
        mer) echo "mcstat F --meridian -o o.exr" ;; myr) echo "mcstat F --myriad -o o.exr" ;;
        plug) echo "plugin: oiiotool F --subimage 0 -o o.exr" ;;
      esac
    }
    if [ -n "$BASELINE" ]; then
      printf "%-42s | %8s %7s %9s %8s | %8s %7s %9s\n" "command" "wall s" "ratio" "peak MiB" "CPU/wall" "before s" "ratio" "peak MiB"
    else
      printf "%-42s | %8s %7s %9s %8s\n" "command" "wall s" "ratio" "peak MiB" "CPU/wall"
    fi
    for n in ref gmon mean mon tmpe mer myr w3d plug; do
      w=med_$n; c=cpu_$n; r=rss_$n
      line=$(awk -v w="${!w}" -v b="$med_ref" 'BEGIN { printf "%8.2f %6.2fx", w, w / b }')
      cw=$(awk -v w="${!w}" -v c="${!c}" 'BEGIN { printf "%8.2f", c / w }')
      if [ -n "$BASELINE" ] && [ "$n" != ref ]; then
        bw=med_b$n; br=rss_b$n
        bl=$(awk -v w="${!bw}" -v b="$med_ref" 'BEGIN { printf "%8.2f %6.2fx", w, w / b }')
        printf "%-42s | %s %9s %s | %s %9s\n" "$(label $n)" "$line" "${!r}" "$cw" "$bl" "${!br}"
      else
        printf "%-42s | %s %9s %s |\n" "$(label $n)" "$line" "${!r}" "$cw"
      fi
    done
    echo
  done
fi

if want compact; then
  # docs/compact.md: G-MoN on a compact file against the full one (goal <= 0.25x), --compact
  # against a plain rewrite of the same file (goal <= 1.5x), and --compact's peak memory against
  # the image height (flat: it streams by blocks of rows).
  read -r cw ch <<<"${COMPACT_RES:-1920 1080}"
  cspp=${COMPACT_SPP:-64}
  full=$out/bench-${cw}x${ch}-M21.mcstat
  [ "$cspp" = 64 ] || full=$out/bench-${cw}x${ch}-${cspp}spp-M21.mcstat
  stats_file "$full" "$cw" "$ch" "$cspp"
  small=${full%.mcstat}-compact.mcstat
  "$mcstat" "$full" --compact -o "$small"
  echo "== Compact: $full ($(du -h "$full" | cut -f1)) and compact ($(du -h "$small" | cut -f1)); 2 cores, medians of $REPS =="
  "$mcstat" "$small" --info | grep '^  compact: [0-9]' || true
  cmd_gfull=("$mcstat" "$full" --gmon -o "$out/o.exr")
  cmd_gsmall=("$mcstat" "$small" --gmon -o "$out/o.exr")
  cmd_copy=("$mcstat" "$full" -o "$out/copy.mcstat")
  cmd_compact=("$mcstat" "$full" --compact -o "$out/c.mcstat")
  cmd_plug=(env OIIO_LIBRARY_PATH="$BUILD/oiio-plugin" oiiotool "$small" --subimage 0 -o "$out/o.exr")
  cmd_start=("$mcstat" --version)  # the process start every row above pays (OIIO's libraries bound)
  run_alternating gfull gsmall copy compact plug start
  printf "%-52s | %8s %9s %9s\n" "command" "wall s" "ratio" "peak MiB"
  row() { local w=med_$2 r=rss_$2 b=med_$3; printf "%-52s | %8.2f %8.2fx %9s\n" "$1" "${!w}" "$(echo "${!w} / ${!b}" | bc -l)" "${!r}"; }
  row "mcstat FULL --gmon -o o.exr (reference)" gfull gfull
  row "mcstat COMPACT --gmon -o o.exr / the full file's" gsmall gfull
  row "plugin: oiiotool COMPACT -o o.exr / the full's gmon" plug gfull
  row "mcstat FULL -o copy.mcstat (reference)" copy copy
  row "mcstat FULL --compact -o c.mcstat / the copy" compact copy
  row "mcstat --version (process start) / the full's gmon" start gfull
  printf "%-52s | %17.2fx\n" "--gmon, compact / full, process start taken out" \
    "$(echo "($med_gsmall - $med_start) / ($med_gfull - $med_start)" | bc -l)"
  echo
  echo "== --compact's peak memory against image height: 1920 wide, M = 21, 8 spp =="
  printf "%8s | %9s %9s\n" "height" "wall s" "peak MiB"
  for h in 540 1080 2160; do
    stats_file "$out/height-$h.mcstat" 1920 "$h" 8
    cmd_ch=("$mcstat" "$out/height-$h.mcstat" --compact -o "$out/c.mcstat")
    run_alternating ch
    printf "%8s | %9.2f %9s\n" "$h" "$med_ch" "$rss_ch"
  done
  echo
fi

if want height; then
  echo "== Peak memory against image height: 1920 wide, M = 21, 8 spp (ZIP), medians of $REPS =="
  for h in 540 1080 2160; do
    stats_file "$out/height-$h.mcstat" 1920 "$h" 8
    stats_file "$out/height-$h-seed4.mcstat" 1920 "$h" 8 4  # the second render merged
  done
  printf "%-44s %10s %10s %10s\n" "command (peak RSS MiB / wall s)" "540 rows" "1080 rows" "2160 rows"
  for op in gmon gmon:keeplight=1 3dwtmf plugin merge; do
    names=()
    for h in 540 1080 2160; do
      f=$out/height-$h.mcstat
      case $op in
        plugin) eval "cmd_h$h=(env OIIO_LIBRARY_PATH=$BUILD/oiio-plugin oiiotool $f --subimage 0 -o $out/o.exr)" ;;
        merge) eval "cmd_h$h=($mcstat $f ${f%.mcstat}-seed4.mcstat --merge -o $out/merged.mcstat)" ;;
        *) eval "cmd_h$h=($mcstat $f --$op -o $out/o.exr)" ;;
      esac
      names+=("h$h")
    done
    run_alternating "${names[@]}"
    case $op in
      plugin) label="plugin: oiiotool F --subimage 0 -o o.exr" ;;
      merge) label="mcstat F G --merge -o m.mcstat" ;;
      *) label="mcstat F --$op -o o.exr" ;;
    esac
    printf "%-44s %10s %10s %10s\n" "$label" "$rss_h540 / $med_h540" "$rss_h1080 / $med_h1080" "$rss_h2160 / $med_h2160"
  done
  echo
fi

if want compare; then
  # mcstat --compare (docs/compare.md) of two renders of one image with different seeds: the file
  # section's render (seed 3) and the same with seed 4, against stock oiiotool reading both files'
  # sub-buffer parts (subimage 1, "buffers", as in the file section), one after the other in one
  # measured command (its peak RSS is the larger of the two processes'). --compare exits 2 when
  # the two differ: a verdict, not a failure, so the timed commands accept it.
  cmpa=$out/bench-1920x1080-M21.mcstat cmpb=$out/bench-1920x1080-M21-seed4.mcstat
  stats_file "$cmpa" 1920 1080 64
  stats_file "$cmpb" 1920 1080 64 4
  verdict_ok=(sh -c '"$@"; s=$?; [ "$s" = 0 ] || [ "$s" = 2 ]' sh)
  echo "== mcstat A B --compare: two 1920x1080 renders, 64 spp, M = 21, seeds 3 and 4 (ZIP, $(du -h "$cmpa" | cut -f1) and $(du -h "$cmpb" | cut -f1)) against stock oiiotool reading both files' sub-buffer parts, 2 cores, medians of $REPS =="
  for op in --compare --compare:test=yuen; do  # the verdicts, once, outside the table
    s=0; "$mcstat" "$cmpa" "$cmpb" "$op" >"$out/compare.txt" 2>"$out/err.txt" || s=$?
    if [ "$s" != 0 ] && [ "$s" != 2 ]; then
      echo "bench: $mcstat $cmpa $cmpb $op failed" >&2; cat "$out/err.txt" >&2; exit 1
    fi
    echo "   $op (exit $s): $(head -1 "$out/compare.txt" | sed 's/^.* vs [^ ]*: //')"
  done
  cmd_ref=(env -u OIIO_LIBRARY_PATH sh -c 'oiiotool "$1" --subimage 1 --stats && oiiotool "$2" --subimage 1 --stats' sh "$cmpa" "$cmpb")
  cmd_cw=("${verdict_ok[@]}" "$mcstat" "$cmpa" "$cmpb" --compare)
  cmd_cy=("${verdict_ok[@]}" "$mcstat" "$cmpa" "$cmpb" --compare:test=yuen)
  run_alternating ref cw cy
  printf "%-58s | %8s %7s %8s %7s %9s %8s\n" "command" "wall s" "ratio" "CPU s" "ratio" "peak MiB" "CPU/wall"
  for n in ref cw cy; do
    case $n in
      ref) l="oiiotool A --subimage 1 --stats; the same for B" ;;
      cw) l="mcstat A B --compare" ;; cy) l="mcstat A B --compare:test=yuen" ;;
    esac
    w=med_$n c=cpu_$n r=rss_$n
    awk -v l="$l" -v w="${!w}" -v c="${!c}" -v bw="$med_ref" -v bc="$cpu_ref" -v r="${!r}" \
      'BEGIN { printf "%-58s | %8.2f %6.2fx %8.2f %6.2fx %9s %8.2f\n", l, w, w / bw, c, c / bc, r, c / w }'
  done
  echo

  # Peak memory against the height: the height section's twins (8 spp, seeds 3 and 4), 540 and
  # 1080 rows. Both sides are read by blocks of rows; what grows with the image is per pixel: the
  # tests' p, z, effect, first side's estimate (4 floats) and a flag, then the maps p, z,
  # effect, differs, tile.p, tile.z, tile.differs (7 floats) built while those are still held.
  echo "== mcstat A B --compare: peak memory against image height: 1920 wide, M = 21, 8 spp (ZIP), seeds 3 and 4, medians of $REPS =="
  for h in 540 1080; do
    stats_file "$out/height-$h.mcstat" 1920 "$h" 8
    stats_file "$out/height-$h-seed4.mcstat" 1920 "$h" 8 4
    eval "cmd_c$h=(\"\${verdict_ok[@]}\" \"\$mcstat\" \"\$out/height-$h.mcstat\" \"\$out/height-$h-seed4.mcstat\" --compare)"
  done
  run_alternating c540 c1080
  printf "%-44s %18s %18s %14s\n" "command (peak RSS MiB / wall s)" "540 rows" "1080 rows" "bytes/pixel"
  awk -v a="$rss_c540" -v b="$rss_c1080" -v ta="$med_c540" -v tb="$med_c1080" 'BEGIN {
    printf "%-44s %18s %18s %14.1f\n", "mcstat A B --compare", a " / " ta, b " / " tb,
      (b - a) * 1048576 / (1920 * 540) }'
  echo "(bytes/pixel: the growth in peak RSS from 540 to 1080 rows over the 1920x540 pixels added. Per pixel, for"
  echo " the default luminance test, --compare keeps the pixel tests' p, z, effect, A's estimate (4 floats)"
  echo " and a flag, and builds the maps (7 floats) while it holds them: 45 bytes; the sub-buffers are read by blocks)"
  echo
fi

# NSEEDS renders of one image (640x480, 4 spp), one plain EXR per seed (docs/ingest.md), in
# $out/seeds, rendered once and reused.
NSEEDS=${NSEEDS:-21}
seed_renders() {
  mkdir -p "$out/seeds"
  local s f
  for s in $(seq "$NSEEDS"); do
    f=$out/seeds/seed_$s.exr
    if [ ! -f "$f" ] || [ "${REFRESH:-0}" = 1 ]; then
      "$render" --scene default --res 640 480 --spp 4 --seed "$s" --reference --quiet -o "$f"
    fi
  done
}

if want goals; then
  # Issue 24's goals, each command against its reference, all alternated in one run.
  zip=$out/bench-1920x1080-M21.mcstat
  stats_file "$zip" 1920 1080 64
  f540=$out/bench-1920x540-M21.mcstat  # the 1080-row file's twin: half the rows, the same spp
  stats_file "$f540" 1920 540 64
  seed_renders
  echo "== The speed goals in one run: each command / its reference, 2 cores, medians of $REPS alternated =="
  cmd_gref=(oiiotool "$zip" --subimage 1 --stats)
  cmd_ggmon=("$mcstat" "$zip" --gmon -o "$out/o.exr")
  cmd_wref=(oiiotool -a "$f540" --compression zip -o "$out/rewrite.exr")
  cmd_wmc=("$mcstat" "$f540" -o "$out/rewrite.mcstat")
  cmd_iref=("$mcstat" --ingest "$out/seeds/seed_*.exr" --mean -o "$out/ingested-mean.exr")
  cmd_ifile=("$mcstat" --ingest "$out/seeds/seed_*.exr" -o "$out/ingested.mcstat")
  run_alternating gref ggmon wref wmc iref ifile
  printf "%-58s | %7s %7s %6s %7s %8s\n" "command" "wall s" "ratio" "goal" "CPU s" "peak MiB"
  goal_row() {  # goal_row NAME REF GOAL LABEL
    local w=med_$1 c=cpu_$1 r=rss_$1 b=med_$2
    printf "%-58s | %7.2f %6.2fx %6s %7.2f %8s\n" "$4" "${!w}" "$(awk -v w="${!w}" -v b="${!b}" 'BEGIN { print w / b }')" "$3" "${!c}" "${!r}"
  }
  goal_row gref gref "" "oiiotool F --subimage 1 --stats (F: 1920x1080, M = 21)"
  goal_row ggmon gref 0.6 "mcstat F --gmon -o o.exr"
  goal_row wref wref "" "oiiotool -a F --compression zip -o G.exr (1920x540)"
  goal_row wmc wref 0.5 "mcstat F -o G.mcstat"
  goal_row iref iref "" "mcstat --ingest 'seed_*.exr' --mean -o m.exr ($NSEEDS)"
  goal_row ifile iref 1.5 "mcstat --ingest 'seed_*.exr' -o f.mcstat"
  echo "(ingest memory against height: SECTIONS=ingest; the renderer's M = 21 overhead: SECTIONS=render)"
  echo
fi

if want ingest; then
  # Renders of one image, one plain EXR per seed (docs/ingest.md), against stock oiiotool
  # averaging the same files.
  seed_renders
  echo "== mcstat --ingest of $NSEEDS renders (640x480, plain float EXR) against stock oiiotool averaging them =="
  cmd_ref=(oiiotool "$out/seeds/seed_1.exr")
  for s in $(seq 2 "$NSEEDS"); do cmd_ref+=("$out/seeds/seed_$s.exr" --add); done
  cmd_ref+=(--divc "$NSEEDS" -o "$out/oiiotool-mean.exr")
  cmd_ing=("$mcstat" --ingest "$out/seeds/seed_*.exr" -o "$out/ingested.mcstat")
  cmd_ingm=("$mcstat" --ingest "$out/seeds/seed_*.exr" --mean -o "$out/ingested-mean.exr")
  cmd_ingg=("$mcstat" --ingest "$out/seeds/seed_*.exr" --gmon -o "$out/ingested-gmon.exr")
  run_alternating ref ing ingm ingg
  printf "%-48s %10s %9s %14s\n" "command" "wall" "ratio" "peak RSS"
  for n in ref ing ingm ingg; do
    case $n in
      ref) l="oiiotool F1 F2 --add ... --divc N -o mean.exr" ;; ing) l="mcstat --ingest FILES -o f.mcstat" ;;
      ingm) l="mcstat --ingest FILES --mean -o m.exr" ;; ingg) l="mcstat --ingest FILES --gmon -o g.exr" ;;
    esac
    w=med_$n; r=rss_$n
    awk -v l="$l" -v w="${!w}" -v b="$med_ref" -v r="${!r}" 'BEGIN { printf "%-48s %8.3f s %8.2fx %10s MiB\n", l, w, w / b, r }'
  done
  awk -v a="$med_ing" -v b="$med_ingm" 'BEGIN { printf "(-o f.mcstat over --mean: %.2fx)\n", a / b }'
  # Memory against height: the renders are read by blocks of rows (IngestSource), so the peak
  # should not follow the image's height. NSEEDS renders at 1920x540 and 1920x1080, 2 spp.
  mkdir -p "$out/hseeds"
  for h in 540 1080; do
    for s in $(seq "$NSEEDS"); do
      f=$out/hseeds/h${h}_s$s.exr
      if [ ! -f "$f" ] || [ "${REFRESH:-0}" = 1 ]; then
        "$render" --scene default --res 1920 "$h" --spp 2 --seed "$s" --reference --quiet -o "$f"
      fi
    done
  done
  cmd_h540=("$mcstat" --ingest "$out/hseeds/h540_s*.exr" -o "$out/ingested-h540.mcstat")
  cmd_h1080=("$mcstat" --ingest "$out/hseeds/h1080_s*.exr" -o "$out/ingested-h1080.mcstat")
  cmd_g540=("$mcstat" --ingest "$out/hseeds/h540_s*.exr" --gmon -o "$out/ingested-g540.exr")
  cmd_g1080=("$mcstat" --ingest "$out/hseeds/h1080_s*.exr" --gmon -o "$out/ingested-g1080.exr")
  run_alternating h540 h1080 g540 g1080
  printf "%-48s %12s %12s %8s\n" "command ($NSEEDS renders, 1920 wide)" "540 rows" "1080 rows" "ratio"
  awk -v a="$rss_h540" -v b="$rss_h1080" 'BEGIN { printf "%-48s %8s MiB %8s MiB %7.2fx\n", "mcstat --ingest FILES -o f.mcstat", a, b, b / a }'
  awk -v a="$rss_g540" -v b="$rss_g1080" 'BEGIN { printf "%-48s %8s MiB %8s MiB %7.2fx\n", "mcstat --ingest FILES --gmon -o g.exr", a, b, b / a }'
  echo "(peak RSS; the goal: 1080 rows within 1.25x of 540)"
  echo
fi

if want aovs; then
  # G-MoN with 10 light-group layers against the beauty alone (docs/aovs.md): the estimator ranks
  # the beauty once per pixel and each AOV costs one weighted sum, so the time should grow at most
  # as the data read. NSEEDS plain renders of AOVS_RES at AOVS_SPP spp, each given alpha A = 1 and
  # 10 Arnold-style light groups RGBA_<g> = beauty * i/55 (i = 1..10: they sum to the beauty), made
  # once with stock oiiotool and ingested twice: with the AOVs and with :aovs=0 (beauty alone).
  NSEEDS=${NSEEDS:-21}
  read -r aw ah <<<"${AOVS_RES:-960 540}"
  aspp=${AOVS_SPP:-4}
  ad=$out/aovs-${aw}x${ah}
  mkdir -p "$ad/plain" "$ad/layers"
  groups=(key fill rim kick bounce sky sun practical window env)
  made=0
  for s in $(seq "$NSEEDS"); do
    f=$ad/plain/seed_$s.exr g=$ad/layers/seed_$s.exr
    if [ ! -f "$f" ] || [ "${REFRESH:-0}" = 1 ]; then
      "$render" --scene default --res "$aw" "$ah" --spp "$aspp" --seed "$s" --reference --quiet -o "$f"
    fi
    if [ ! -f "$g" ] || [ "$f" -nt "$g" ]; then
      layers=() i=0
      for grp in "${groups[@]}"; do
        i=$((i + 1))
        layers+=("$f" --ch R,G,B --mulc "$(echo "scale=8; $i / 55" | bc)"
          --chnames "RGBA_$grp.R,RGBA_$grp.G,RGBA_$grp.B" --chappend)
      done
      oiiotool "$f" --ch R,G,B,A=1.0 "${layers[@]}" -o "$g"
      made=1
    fi
  done
  fa=$ad/aovs.mcstat fb=$ad/beauty.mcstat
  if [ "$made" = 1 ] || [ ! -f "$fa" ] || [ ! -f "$fb" ]; then
    # Timed once, outside the table (ingest has its own section).
    /usr/bin/time -f "%e %M" -o "$out/time.txt" "$mcstat" --ingest "$ad/layers/seed_*.exr" -o "$fa" 2>/dev/null
    read -r ia iam <"$out/time.txt"
    /usr/bin/time -f "%e %M" -o "$out/time.txt" "$mcstat" --ingest:aovs=0 "$ad/layers/seed_*.exr" -o "$fb" 2>/dev/null
    read -r ib ibm <"$out/time.txt"
    awk -v a="$ia" -v b="$ib" -v am="$iam" -v bm="$ibm" 'BEGIN { printf "(ingest, once: with the AOVs %.2f s, %.0f MiB; :aovs=0 %.2f s, %.0f MiB; %.2fx)\n", a, am / 1024, b, bm / 1024, a / b }'
  fi
  # Decoded bytes each --gmon reads: part buffers (4 M float channels) and part aovs (A M), from
  # the headers as stock oiiotool sees them (subimages 1 and 4, the plugin not loaded).
  nch() { env -u OIIO_LIBRARY_PATH oiiotool --info -a "$1" | awk -v s="$2" '$1 == "subimage" && $2 == s ":" { print $6 }'; }
  cb=$(nch "$fb" 1) ca=$(nch "$fa" 4)
  mib() { awk -v c="$1" -v w="$aw" -v h="$ah" 'BEGIN { printf "%.0f MiB", c * w * h * 4 / 1048576 }'; }
  echo "== mcstat --gmon with 10 light-group layers + alpha: $NSEEDS seeds of ${aw}x${ah} at $aspp spp (M = $NSEEDS), 2 cores, medians of $REPS =="
  echo "   aovs.mcstat $(du -h "$fa" | cut -f1) (parts buffers $cb + aovs $ca float channels, $(mib $((cb + ca))) decoded);" \
    "beauty.mcstat $(du -h "$fb" | cut -f1) (buffers $cb channels, $(mib "$cb") decoded)"
  cmd_refb=(env -u OIIO_LIBRARY_PATH oiiotool "$fb" --subimage buffers --printstats)
  cmd_refa=(env -u OIIO_LIBRARY_PATH oiiotool "$fa" --subimage buffers --printstats
    "$fa" --subimage aovs --printstats)
  cmd_gb=("$mcstat" "$fb" --gmon -o "$out/o.exr")
  cmd_ga=("$mcstat" "$fa" --gmon -o "$out/o.exr")
  run_alternating refb refa gb ga
  printf "%-60s | %8s %8s %10s %9s %8s\n" "command" "wall s" "/ beauty" "/ oiiotool" "peak MiB" "CPU/wall"
  for n in refb refa gb ga; do
    case $n in
      refb) l="oiiotool beauty.mcstat --subimage buffers --printstats" b=$med_refb o=$med_refb ;;
      refa) l="oiiotool aovs.mcstat (subimages buffers, aovs) --printstats" b=$med_refb o=$med_refa ;;
      gb) l="mcstat beauty.mcstat --gmon -o o.exr" b=$med_gb o=$med_refb ;;
      ga) l="mcstat aovs.mcstat --gmon -o o.exr" b=$med_gb o=$med_refa ;;
    esac
    w=med_$n c=cpu_$n r=rss_$n
    awk -v l="$l" -v w="${!w}" -v c="${!c}" -v b="$b" -v o="$o" -v r="${!r}" \
      'BEGIN { printf "%-60s | %8.2f %7.2fx %9.2fx %9s %8.2f\n", l, w, w / b, w / o, r, c / w }'
  done
  awk -v a="$ca" -v b="$cb" -v g="$med_ga" -v gb="$med_gb" 'BEGIN {
    printf "time with the AOVs / beauty alone: %.2fx; data read: %.2fx (goal: the time ratio at most the data ratio: %s)\n",
      g / gb, (a + b) / b, (g / gb <= (a + b) / b) ? "met" : "not met" }'
  echo
fi

if want render; then
  # bench_render.sh has sections of its own: this one's SECTIONS (from the environment) is not them.
  if [ -x scripts/bench_render.sh ]; then SKIP_BUILD=1 BUILD="$BUILD" REPS="$REPS" SECTIONS="1 2" scripts/bench_render.sh; fi
fi

if want trade; then
  # The speed/accuracy trade of every method family on every fixture scene (docs/trade.md);
  # about 25 minutes, its own environment (SCENES, SPPS, SEEDS, ...: scripts/trade.sh).
  SKIP_BUILD=1 BUILD="$BUILD" OUT="$out/trade" scripts/trade.sh
fi
