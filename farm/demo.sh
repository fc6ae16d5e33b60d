#!/usr/bin/env bash
# The render farm demo (docs/farm.md), after the README's two commands, as root:
#
#   farm/demo.sh [--out DIR] [--wait SECONDS]
#
# Starts a one-node Slurm cluster in a temporary folder (farm/local-slurm.sh), submits a shot of
# the fixture renderer (3 frames x 6 seeds, 16 spp each, 96 x 72, merged in a tree of fan-in 2:
# 6 -> 3 -> 2 -> 1 files, so each frame runs 5 merge jobs on 3 levels, then a G-MoN estimate),
# waits (bounded), prints the report, then checks each frame against the single-machine result:
# its statistics file is the same bytes as `mcstat <that frame's 6 seed files> --merge:fanin=2`
# (cmp) and its G-MoN EXR has the same pixels as G-MoN of that file. Slurm is stopped at the end,
# also on failure or Ctrl-C. Exit status 0 only when every frame is done and matched.
# The shot is left in DIR/shot (default out/farm-demo/shot), the single-machine files in DIR/single.
# Binaries: MCSTAT_BIN_DIR, else the repository's build/ (scripts/demo.sh builds them).
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
farm=$repo/farm
out=$repo/out/farm-demo
wait_s=600
frames=1-3 seeds=6 fanin=2 spp=16 res=(96 72)

usage() { sed -n '4,5p' "$0" | sed 's/^# \{0,1\}//'; }
die() { echo "farm/demo.sh: $*" >&2; exit 1; }
while [[ $# -gt 0 ]]; do
  case $1 in
    --out) [[ $# -ge 2 ]] || die "--out needs a folder"; out=$2; shift 2 ;;
    --wait) [[ $# -ge 2 ]] || die "--wait needs seconds"; wait_s=$2; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) usage >&2; die "unknown argument: $1" ;;
  esac
done
# DIR is the demo's own: it replaces DIR/shot and DIR/single on each run, so a folder holding
# anything else is refused (never a user's files deleted); the marker file says a folder is one.
marker=.mcstat-farm-demo
if [[ -d $out && ! -e $out/$marker && -n $(ls -A "$out") ]]; then
  die "$out holds files and is not a farm demo's folder: give --out a new or empty folder"
fi
mkdir -p "$out"
out=$(cd "$out" && pwd)
echo "the mcstat farm demo's folder: farm/demo.sh replaces shot/ and single/ here" >"$out/$marker"

if [[ -n ${MCSTAT_BIN_DIR:-} ]]; then
  mcstat=$MCSTAT_BIN_DIR/mcstat
  [[ -x $mcstat ]] || mcstat=$MCSTAT_BIN_DIR/oiiotool-ext/mcstat
else
  mcstat=$repo/build/oiiotool-ext/mcstat
fi
[[ -x $mcstat ]] || die "mcstat not found ($mcstat): run scripts/demo.sh first, or set MCSTAT_BIN_DIR"
command -v oiiotool >/dev/null || die "oiiotool not found (scripts/install-deps.sh installs openimageio-tools)"

slurm=$(mktemp -d /tmp/mcstat-farm-demo.XXXXXX)
cleanup() {
  local rc=$?
  "$farm/local-slurm.sh" stop "$slurm" || rc=1
  rm -rf "$slurm"
  exit $rc
}
trap cleanup EXIT
# A long step runs in the background and is waited for, so that Ctrl-C or SIGTERM stops it and
# the cluster at once (bash runs a trap only after the foreground command ends).
child=""
trap '[[ -z $child ]] || kill -TERM "$child" 2>/dev/null; exit 130' INT TERM
run() { "$@" & child=$!; local rc=0; wait "$child" || rc=$?; child=""; return $rc; }

echo "== a one-node Slurm cluster in $slurm"
run "$farm/local-slurm.sh" start "$slurm" >"$slurm/start.out" || die "Slurm did not start (see above)"
start_out=$(cat "$slurm/start.out")
eval "$start_out"
export SLURM_CONF
"$farm/local-slurm.sh" status "$slurm"

shot=$out/shot
rm -rf "$shot" "$out/single"
echo "== submit: frames $frames x $seeds seeds, $spp spp, ${res[0]}x${res[1]}, merge fan-in $fanin, G-MoN per frame"
rc=0
run "$farm/mcstat-farm" submit "$shot" --name shot --frames "$frames" --seeds "$seeds" --spp "$spp" \
  --res "${res[@]}" --template-file "$farm/templates/fixture-stats.tmpl" --fanin "$fanin" \
  --estimate gmon --wait "$wait_s" || rc=$?
[[ $rc -eq 0 ]] || die "the shot did not complete (exit $rc); the report is in $shot/report.txt"

echo "== each frame against the single-machine result"
mkdir -p "$out/single"
bad=0
for f in $(python3 -c 'import json, sys; print(*json.load(open(sys.argv[1]))["frames"])' "$shot/shot.json"); do
  f4=$(printf %04d "$f")
  single=$out/single/shot.$f4.mcstat
  "$mcstat" -q "$shot"/render/f$f4/s*.mcstat --merge:fanin=$fanin -o "$single"
  "$mcstat" -q "$single" --gmon -d half -o "$out/single/shot.$f4.gmon.exr"
  if cmp -s "$single" "$shot/out/shot.$f4.mcstat"; then
    stats="statistics file: the same bytes as mcstat <6 seeds> --merge:fanin=$fanin"
  else
    stats="statistics file DIFFERS from mcstat <6 seeds> --merge:fanin=$fanin"; bad=1
  fi
  if oiiotool --fail 0 --failpercent 0 "$out/single/shot.$f4.gmon.exr" "$shot/out/shot.$f4.gmon.exr" \
      --diff >/dev/null 2>&1; then
    est="G-MoN EXR: the same pixels"
  else
    est="G-MoN EXR: pixels DIFFER"; bad=1
  fi
  echo "frame $f: $stats; $est"
done
[[ $bad -eq 0 ]] || die "a frame differs from the single-machine result"
echo "== done: every frame equals the single-machine result (shot in $shot)"
