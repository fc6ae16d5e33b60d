#!/usr/bin/env bash
# Render N seeds of the Cycles caustic scene (cycles_caustic.py), one multilayer EXR per seed:
#   OUTDIR/seed_<s>.exr for s = FIRST .. FIRST+N-1
#
#   tests/aovs/render_cycles_seeds.sh [-n N] [-o OUTDIR] [--first S] [--spp N] [--res W H]
#                                     [--key-scale F] [--ior F] [--threads N] [--blender PATH]
#                                     [--checker-scale F] [--clamp-indirect C] [--batch]
# Defaults: 21 seeds from 1, 64 spp, 128x96, key x1, IOR 1.5, all cores, into ./cycles_seeds,
# checker scale 8, no clamp (cycles_caustic.py says what the two last ones do), one Blender
# process per seed (--batch: one for all of them, as the test suite renders them).
# Needs Blender 3.2 or newer (light groups); on Debian 12: apt-get install -y blender (3.4).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
scene_py="$here/cycles_caustic.py"
n=21 first=1 spp=64 w=128 h=96 key=1 ior=1.5 threads=0 out=cycles_seeds checker=8 clamp=0 batch=0
blender=${BLENDER:-blender}

usage() { sed -n '2,11p' "$0" | sed 's/^# \{0,1\}//'; }
die() { echo "render_cycles_seeds.sh: $*" >&2; exit 2; }
need() { [[ $# -ge 2 && -n $2 ]] || die "option $1 needs a value"; }

while [[ $# -gt 0 ]]; do
  case $1 in
    -n|--seeds) need "$@"; n=$2; shift 2 ;;
    -o|--out) need "$@"; out=$2; shift 2 ;;
    --first) need "$@"; first=$2; shift 2 ;;
    --spp) need "$@"; spp=$2; shift 2 ;;
    --res) [[ $# -ge 3 ]] || die "--res needs W H"; w=$2; h=$3; shift 3 ;;
    --key-scale) need "$@"; key=$2; shift 2 ;;
    --ior) need "$@"; ior=$2; shift 2 ;;
    --threads) need "$@"; threads=$2; shift 2 ;;
    --checker-scale) need "$@"; checker=$2; shift 2 ;;
    --clamp-indirect) need "$@"; clamp=$2; shift 2 ;;
    --blender) need "$@"; blender=$2; shift 2 ;;
    --batch) batch=1; shift ;;
    -h|--help) usage; exit 0 ;;
    *) usage >&2; die "unknown argument: $1" ;;
  esac
done

for v in n first spp w h threads; do
  [[ ${!v} =~ ^[0-9]+$ ]] || die "$v must be a non-negative integer, got '${!v}'"
done
(( n >= 1 && spp >= 1 && w >= 1 && h >= 1 )) || die "seeds, spp and resolution must be >= 1"

if ! command -v "$blender" >/dev/null 2>&1; then
  cat >&2 <<EOF
render_cycles_seeds.sh: Blender not found ('$blender' is not on PATH).
  Install it (Debian 12: apt-get install -y blender, Blender 3.4) or pass --blender PATH / BLENDER=PATH.
  Blender 3.2 or newer is needed (Cycles light groups).
EOF
  exit 127
fi
[[ -f $scene_py ]] || die "scene script missing: $scene_py"

mkdir -p "$out"
log="$out/render.log"
: >"$log"
echo "rendering $n seeds ($first..$((first + n - 1))), ${spp} spp, ${w}x${h}, key x$key, IOR $ior, checker $checker, clamp $clamp -> $out/"
t0=$(date +%s.%N)
if [[ $batch == 1 ]]; then
  # --batch: one Blender process renders every seed (cycles_caustic.py --count), so its start-up
  # and the scene's construction, about 1.5 s, are paid once instead of once per seed. The files
  # are what separate processes write (Cycles' own thread-order noise, below 1e-6, aside); Blender's
  # render times after the first leave out its first-render warm-up, so the trade's time column
  # (scripts/trade_cycles.sh) keeps one process per seed, as a farm runs them.
  if ! "$blender" -b --factory-startup -noaudio --python-exit-code 1 --python "$scene_py" -- \
      --out "$out/seed_{seed}.exr" --seed "$first" --count "$n" --spp "$spp" --res "$w" "$h" \
      --key-scale "$key" --ior "$ior" --threads "$threads" --checker-scale "$checker" \
      --clamp-indirect "$clamp" >>"$log" 2>&1; then
    echo "render_cycles_seeds.sh: Blender failed; last lines of $log:" >&2
    tail -n 20 "$log" >&2
    exit 1
  fi
  for ((s = first; s < first + n; s++)); do
    f="$out/seed_$s.exr"
    [[ -s $f ]] || die "seed $s: $f was not written (see $log)"
    t=$(grep -F "cycles_caustic: wrote $f (" "$log" | sed -n 's/.* in \([0-9.]*\) s$/\1/p')
    echo "  $f  ${t:-?} s"
  done
else
  for ((s = first; s < first + n; s++)); do
    f="$out/seed_$s.exr"
    ts=$(date +%s.%N)
    if ! "$blender" -b --factory-startup -noaudio --python-exit-code 1 --python "$scene_py" -- \
        --out "$f" --seed "$s" --spp "$spp" --res "$w" "$h" --key-scale "$key" --ior "$ior" \
        --threads "$threads" --checker-scale "$checker" --clamp-indirect "$clamp" >>"$log" 2>&1; then
      echo "render_cycles_seeds.sh: Blender failed on seed $s; last lines of $log:" >&2
      tail -n 20 "$log" >&2
      exit 1
    fi
    [[ -s $f ]] || die "seed $s: $f was not written (see $log)"
    te=$(date +%s.%N)
    awk -v f="$f" -v a="$ts" -v b="$te" 'BEGIN { printf "  %s  %.2f s\n", f, b - a }'
  done
fi
t1=$(date +%s.%N)
awk -v n="$n" -v a="$t0" -v b="$t1" 'BEGIN {
  printf "done: %d files in %.1f s (%.2f s per render, Blender start-up included)\n", n, b - a, (b - a) / n }'
