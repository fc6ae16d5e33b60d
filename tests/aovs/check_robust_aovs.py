#!/usr/bin/python3
"""Check a robust estimate of Cycles seed renders against docs/aovs.md's guarantees.

  /usr/bin/python3 tests/aovs/check_robust_aovs.py SEED_DIR GMON.exr GMON_BEAUTY.exr MEAN.exr REF.exr

SEED_DIR holds the seed renders (seed_*.exr, cycles_caustic.py), GMON.exr is `mcstat --ingest ...
--gmon` with every AOV, GMON_BEAUTY.exr the same G-MoN over the beauty alone (`--ingest:aovs=0`),
MEAN.exr the plain mean, REF.exr a high-spp render. Asserts, printing the numbers:
  1. every channel of the renders is in GMON.exr under its name;
  2. per pixel and channel, |key + fill + sky - Combined| of the robust image is within the
     largest such residual of the input renders (the weights are convex, so it cannot be more)
     plus the float rounding of the four weighted sums;
  3. ViewLayer.Combined.A is there and is the image's alpha channel;
  4. the beauty of GMON.exr is bit for bit GMON_BEAUTY.exr's, and its relMSE against REF.exr is
     below the plain mean's (the key light's fireflies through the glass are gone).
Exit status 1 with the failed checks listed. Needs numpy and OpenImageIO's Python bindings.
"""

import glob
import os
import sys

import numpy as np
import OpenImageIO as oiio

LAYER = "ViewLayer."
GROUPS = ["Combined_key", "Combined_fill", "Combined_sky"]


def read(path):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        sys.exit("check_robust_aovs: %s: %s" % (path, buf.geterror()))
    spec = buf.spec()
    px = buf.get_pixels(oiio.FLOAT)
    if px is None:
        sys.exit("check_robust_aovs: %s: cannot read pixels" % path)
    names = list(spec.channelnames)
    return spec, {n: px[:, :, i] for i, n in enumerate(names)}


def group_residual(ch, c):
    """|key + fill + sky - Combined| in channel c, and the magnitude of its terms, in double."""
    terms = [ch[LAYER + g + "." + c].astype(np.float64) for g in GROUPS]
    beauty = ch[LAYER + "Combined." + c].astype(np.float64)
    return np.abs(sum(terms) - beauty), sum(np.abs(t) for t in terms) + np.abs(beauty)


def rel_mse(x, ref):
    """Mean over pixels and R, G, B of (x - ref)^2 / (ref^2 + 0.01)."""
    out = 0.0
    for c in "RGB":
        a = x[LAYER + "Combined." + c].astype(np.float64)
        r = ref[LAYER + "Combined." + c].astype(np.float64)
        out += np.mean((a - r) ** 2 / (r * r + 0.01))
    return out / 3


def main():
    if len(sys.argv) != 6:
        sys.exit(__doc__)
    seed_dir, gmon_path, beauty_path, mean_path, ref_path = sys.argv[1:]
    seeds = sorted(glob.glob(os.path.join(seed_dir, "seed_*.exr")))
    if not seeds:
        sys.exit("check_robust_aovs: no seed_*.exr in " + seed_dir)
    failures = []
    gspec, g = read(gmon_path)

    # 1. Every channel of the renders, under its name.
    in_names = set()
    inputs = []
    for s in seeds:
        spec, ch = read(s)
        in_names |= set(spec.channelnames)
        inputs.append(ch)
    missing = sorted(in_names - set(g))
    print("channels: %d in the renders, %d in the result, %d missing %s"
          % (len(in_names), len(g), len(missing), missing[:5]))
    if missing:
        failures.append("%d input channels missing from %s" % (len(missing), gmon_path))

    # 2. Light groups against the beauty: never further apart than in the worst input render.
    violations, worst_in, worst_out = 0, 0.0, 0.0
    for c in "RGB":
        band = np.max([group_residual(ch, c)[0] for ch in inputs], axis=0)
        res, scale = group_residual(g, c)
        tol = 8 * 6e-8 * scale + 1e-30  # rounding of the robust sums, each rounded once to float
        violations += int(np.count_nonzero(res > band + tol))
        worst_in = max(worst_in, float(np.max(band)))
        worst_out = max(worst_out, float(np.max(res)))
    pixels = g[LAYER + "Combined.R"].size
    print("light groups: %d of %d pixel-channels outside the inputs' band; largest input "
          "residual %.3g, largest robust residual %.3g" % (violations, 3 * pixels, worst_in, worst_out))
    if violations:
        failures.append("%d pixel-channels where the robust light groups leave the inputs' band"
                        % violations)

    # 3. Alpha.
    alpha = gspec.channelnames[gspec.alpha_channel] if gspec.alpha_channel >= 0 else None
    print("alpha channel: %s" % alpha)
    if alpha != LAYER + "Combined.A":
        failures.append("alpha channel is %s, not %sCombined.A" % (alpha, LAYER))

    # 4. The beauty is the beauty-alone G-MoN, bit for bit, and beats the mean.
    _, b = read(beauty_path)
    same = all(np.array_equal(g[LAYER + "Combined." + c], b[LAYER + "Combined." + c],
                              equal_nan=True) for c in "RGB")
    _, m = read(mean_path)
    _, ref = read(ref_path)
    e_gmon, e_mean = rel_mse(g, ref), rel_mse(m, ref)
    print("beauty identical to G-MoN of the beauty alone: %s; relMSE against the reference: "
          "mean %.4g, G-MoN %.4g (%.2fx)" % (same, e_mean, e_gmon, e_mean / max(e_gmon, 1e-30)))
    if not same:
        failures.append("the beauty differs from G-MoN of the beauty alone")
    if not e_gmon < e_mean:
        failures.append("G-MoN's relMSE %.4g is not below the mean's %.4g" % (e_gmon, e_mean))

    for f in failures:
        print("check_robust_aovs: FAILED: " + f, file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
