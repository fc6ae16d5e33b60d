#!/usr/bin/env bash
# scripts/confidence_tables.sh [BUILD_DIR] [WORK_DIR]: regenerates the coverage tables of
# docs/confidence.md (not part of the tests; a few minutes on 2 cores):
#   1. synthetic pixels: the coverage test's whole table (tests/filters/pixel/
#      test_confidence_coverage.cpp, MCSTAT_CONFIDENCE_TABLE=1);
#   2. the fixture renderer's scenes at 64x48: per scene, M and estimator, the fraction of pixel
#      channels whose :ci=0.95 interval holds the high-spp reference (the mean the renderer
#      converges to), over 4 seeds, with the median relative width and the estimator's energy bias
#      against the reference shown separately;
#   3. the expected value's interval (citarget=expected) at cipool 0, 4, 6 on the same scenes at
#      256 spp, M = 16 (4 seeds): coverage of the reference and median relative width.
set -euo pipefail
build=${1:-build}
work=${2:-$(mktemp -d)}
render="$build/render-fixture/mcstat-render"
cli="$build/oiiotool-ext/mcstat"
refspp=${MCSTAT_CI_REFSPP:-16384}
mkdir -p "$work"

echo "## Synthetic pixels"
echo
MCSTAT_CONFIDENCE_TABLE=1 "$build/tests/filters/pixel/test_filters_pixel" \
  --gtest_filter='Distributions/ConfidenceCoverage.SyntheticPixels/*' | grep '^|'
echo

echo "## Fixture scenes (64x48, reference $refspp spp, 4 seeds, level 0.95)"
echo
for scene in default caustic; do
  [ -f "$work/$scene-ref.exr" ] ||
    "$render" --scene "$scene" --res 64 48 --spp "$refspp" --reference --seed 1000 --quiet \
      -o "$work/$scene-ref.exr"
  for cfg in "9 36" "9 144" "21 84" "21 336"; do
    set -- $cfg
    M=$1 spp=$2
    for seed in 1 2 3 4; do
      f="$work/$scene-M$M-s$spp-$seed.mcstat"
      [ -f "$f" ] || "$render" --scene "$scene" --res 64 48 --spp "$spp" --M "$M" --seed "$seed" \
        --quiet -o "$f"
      for est in mean mon gmon gmonb tmpe; do
        "$cli" "$f" --"$est":ci=0.95 -o "$work/$scene-M$M-s$spp-$seed-$est.exr" 2>/dev/null
      done
    done
  done
done
# 3. the expected value's interval: its renders (the tables print below, with the others).
for scene in default caustic; do
  for seed in 1 2 3 4; do
    f="$work/$scene-M16-s256-$seed.mcstat"
    [ -f "$f" ] || "$render" --scene "$scene" --res 64 48 --spp 256 --M 16 --seed "$seed" --quiet -o "$f"
    for pool in 0 4 6; do
      "$cli" "$f" --gmon:ci=0.95:citarget=expected:cipool=$pool -o "$work/$scene-e$pool-$seed.exr" 2>/dev/null
    done
  done
done
PYTHONPATH= /usr/bin/python3 - "$work" <<'PY'
import sys, numpy as np, OpenImageIO as oiio
work = sys.argv[1]
def read(p):
    b = oiio.ImageBuf(p)
    names = list(b.spec().channelnames)
    px = b.get_pixels(oiio.FLOAT)
    return {n: px[..., i] for i, n in enumerate(names)}
print("| scene | M | spp | estimator | pixel channels with width > 0 | covers the reference | "
      "median rel. width | energy bias (sum est / sum ref - 1) |")
print("|---|---|---|---|---|---|---|---|")
for scene in ["default", "caustic"]:
    ref = read(f"{work}/{scene}-ref.exr")
    for M, spp in [(9, 36), (9, 144), (21, 84), (21, 336)]:
        for est in ["mean", "mon", "gmon", "gmonb", "tmpe"]:
            cov = n = 0
            widths, bias = [], []
            for seed in [1, 2, 3, 4]:
                img = read(f"{work}/{scene}-M{M}-s{spp}-{seed}-{est}.exr")
                e_sum = r_sum = 0.0
                for c in "RGB":
                    lo, hi, e, r = img["ci_low." + c], img["ci_high." + c], img[c], ref[c]
                    live = hi > lo
                    n += live.sum()
                    cov += ((lo <= r) & (r <= hi) & live).sum()
                    v = np.abs(e[live])
                    widths.append(((hi - lo)[live] / np.maximum(v, 1e-12)))
                    e_sum += e.sum(); r_sum += r.sum()
                bias.append(e_sum / r_sum - 1)
            w = np.median(np.concatenate(widths))
            print(f"| {scene} | {M} | {spp} | {est} | {n} | {cov / n:.4f} | {w:.3f} | "
                  f"{np.mean(bias):+.4f} ± {np.std(bias):.4f} |")
print()
print("## The expected value's interval (citarget=expected), 64x48, 256 spp, M = 16, 4 seeds")
print()
print("| scene | cipool | covers the reference | median relative width |")
print("|---|---|---|---|")
for scene in ["default", "caustic"]:
    ref = read(f"{work}/{scene}-ref.exr")
    for pool in [0, 4, 6]:
        cov, width = [], []
        for seed in [1, 2, 3, 4]:
            img = read(f"{work}/{scene}-e{pool}-{seed}.exr")
            for c in "RGB":
                lo, hi, r = img["ci_low." + c], img["ci_high." + c], ref[c]
                live = hi > lo
                cov.append(((lo <= r) & (r <= hi))[live].mean())
                mid = (lo + hi) / 2
                width.append(np.median(((hi - lo) / np.maximum(np.abs(mid), 1e-12))[live]))
        print(f"| {scene} | {pool} | {np.mean(cov):.3f} | {np.mean(width):.2f} |")
PY
