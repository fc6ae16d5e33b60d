#!/usr/bin/env bash
# scripts/removed_light_table.sh [OUT_DIR]: the tables of docs/removed-light.md. Renders the
# default and caustic scenes (96 x 72, 256 spp, M = 9, and an 8192 spp reference each), runs each
# robust estimator with :removed=1 at window radius 1, 2 and 3, and prints, per scene, estimator
# and radius: the robust image's energy error against the reference, the energy it removed, the
# share of that flagged significant, the whole-image z, and how much of the light the robust image
# really misses (reference - robust) lies in flagged pixels. Takes a few minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-build/removed-light}
# OUT_DIR is the table's own folder: it writes its renders and images there by name, so a folder
# holding files that is neither marked as the table's (.mcstat-removed-light) nor an earlier
# run's (default-gmon-1.exr) is refused, as the trade's and the keep-light table's.
if [ -d "$out" ] && [ ! -e "$out/.mcstat-removed-light" ] && [ ! -e "$out/default-gmon-1.exr" ] &&
  [ -n "$(ls -A "$out")" ]; then
  echo "removed_light_table: $out holds files and is not the table's folder: give a new or empty folder" >&2
  exit 1
fi
mkdir -p "$out"
: >"$out/.mcstat-removed-light"
R=build/render-fixture/mcstat-render
M=build/oiiotool-ext/mcstat
for scene in default caustic; do
  [ -f "$out/$scene.mcstat" ] || $R --scene $scene --res 96 72 --spp 256 --M 9 --seed 1 \
    -o "$out/$scene.mcstat" 2>/dev/null
  [ -f "$out/$scene-ref.exr" ] || $R --scene $scene --res 96 72 --spp 8192 --reference --seed 99 \
    -o "$out/$scene-ref.exr" 2>/dev/null
done
echo "| scene | estimator | radius | nbias (robust) | removed | significant share | z image | missing light in flagged pixels | flagged pixels |"
echo "|---|---|---|---|---|---|---|---|---|"
for scene in default caustic; do
  for est in gmon median tmpe; do
    for r in 1 2 3; do
      $M "$out/$scene.mcstat" --$est:removed=1:removedradius=$r -o "$out/$scene-$est-$r.exr" 2>/dev/null
      PYTHONPATH= /usr/bin/python3 - "$out/$scene-$est-$r.exr" "$out/$scene-ref.exr" "$scene" "$est" "$r" <<'PY'
import sys, numpy as np, OpenImageIO as oiio
def read(p):
    b = oiio.ImageBuf(p)
    return b.spec(), b.get_pixels(oiio.FLOAT)
spec, g = read(sys.argv[1]); _, ref = read(sys.argv[2])
ix = {n: i for i, n in enumerate(spec.channelnames)}
L = np.array([0.2126, 0.7152, 0.0722])
yg, yr = (g[..., :3] * L).sum(-1), (ref[..., :3] * L).sum(-1)
sig = g[..., ix["removed.significant"]] > 0
missing = yr - yg
a = lambda k: spec.getattribute("mcstat:removed:" + k)
print("| {} | {} | {} | {:+.2f} % | {:.2f} % | {:.0f} % | {:.1f} | {:.0f} % | {:.2f} % |".format(
    sys.argv[3], sys.argv[4], sys.argv[5], 100 * (yg.sum() / yr.sum() - 1),
    100 * a("energyFraction"), 100 * a("significantFraction"), a("zImage"),
    100 * missing[sig].sum() / missing.sum(), 100 * sig.mean()))
PY
    done
  done
done
