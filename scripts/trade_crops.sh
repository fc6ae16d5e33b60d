#!/usr/bin/env bash
# scripts/trade_crops.sh [TRADE_OUT [PNG]]: the crops of docs/trade.md's "Where users live" and of
# the README: the detail scene's floor under the glass ball, seed 1 at 64 spp of a run of
# scripts/trade.sh at 256 x 192 (TRADE_OUT, default out/trade-large: its reference, statistics
# file and plain mean), 3x enlarged (nearest pixel). Top: the reference, the plain mean, the
# renderer's clamp at 30; bottom: `oiiotool --median 3x3` of the mean, G-MoN, G-MoN with
# :keeplight=1 at the build's defaults. The clamped render is made again (trade.sh keeps none):
# the same seed and size as the trade's. PNG (default docs/images/trade-detail-crops.png) goes
# through mcstat's display view (as `-o x.png` writes it), under a temporary name, then renamed.
# Not part of the tests; about 30 seconds on 2 cores.
#
# Environment: CROP, the window as oiiotool's --cut geometry (default 112x72+96+92: the ball's
# caustic and halo on the checker), BUILD (default build).
set -euo pipefail
cd "$(dirname "$0")/.."
trade=${1:-out/trade-large}
png=${2:-docs/images/trade-detail-crops.png}
CROP=${CROP:-112x72+96+92}
BUILD=${BUILD:-build}
M=$BUILD/oiiotool-ext/mcstat
R=$BUILD/render-fixture/mcstat-render
dir=$trade/detail
for f in ref.exr s1-64.mcstat s1-64-mean.exr; do
  if [ ! -f "$dir/$f" ]; then
    echo "trade_crops: $dir/$f: missing (run scripts/trade.sh at 256 x 192 first: docs/trade.md)" >&2
    exit 1
  fi
done
for t in "$M" "$R"; do
  [ -x "$t" ] || { echo "trade_crops: $t: not built (scripts/test.sh builds it)" >&2; exit 1; }
done
[[ $CROP =~ ^([0-9]+)x([0-9]+)\+([0-9]+)\+([0-9]+)$ ]] ||
  { echo "trade_crops: CROP=$CROP: want WxH+X+Y" >&2; exit 1; }
cw=${BASH_REMATCH[1]} ch=${BASH_REMATCH[2]}
read -r width height <<<"$(oiiotool "$dir/ref.exr" --echo "{TOP.width} {TOP.height}" | tail -1)"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$R" --scene detail --res "$width" "$height" --spp 64 --M 1 --seed 1 --clamp 30 --quiet \
  -o "$work/rclamp.mcstat"
"$M" "$work/rclamp.mcstat" --mean -o "$work/rclamp.exr"
oiiotool "$dir/s1-64-mean.exr" --median 3x3 -o "$work/median.exr"
"$M" "$dir/s1-64.mcstat" --gmon -o "$work/gmon.exr"
"$M" "$dir/s1-64.mcstat" --gmon:keeplight=1 -o "$work/keeplight.exr"
tiles=()
for img in "$dir/ref.exr" "$dir/s1-64-mean.exr" "$work/rclamp.exr" "$work/median.exr" \
  "$work/gmon.exr" "$work/keeplight.exr"; do
  n=$work/tile${#tiles[@]}.exr
  # R, G, B by name; the window cut out (to the origin), then each pixel a 3 x 3 block.
  oiiotool "$img" --ch R,G,B --cut "$CROP" --resample "$((3 * cw))x$((3 * ch))" -o "$n"
  tiles+=("$n")
done
oiiotool "${tiles[@]}" --mosaic:pad=4 3x2 -o "$work/mosaic.exr"
mkdir -p "$(dirname "$png")"
tmp=$(dirname "$png")/.$(basename "$png" .png).tmp$$.png
if ! "$M" "$work/mosaic.exr" -o "$tmp"; then
  rm -f "$tmp"
  exit 1
fi
mv -f "$tmp" "$png"
echo "trade_crops: $png ($CROP of $dir, seed 1, 64 spp)"
