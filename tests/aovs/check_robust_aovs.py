#!/usr/bin/python3
"""Check a robust estimate of Cycles seed renders against docs/aovs.md's guarantees.

  /usr/bin/python3 tests/aovs/check_robust_aovs.py SEED_DIR GMON.exr GMON_FILE.exr GMON_BEAUTY.exr \
      MEAN.exr REF.exr

SEED_DIR holds the seed renders (seed_*.exr, cycles_caustic.py), GMON.exr is `mcstat --ingest ...
--gmon` with every AOV, GMON_FILE.exr the same G-MoN computed from the statistics file the ingest
wrote, GMON_BEAUTY.exr G-MoN over the beauty alone (`--ingest:aovs=0`), MEAN.exr the plain mean,
REF.exr a high-spp render. Asserts, printing the numbers:
  a. every channel of the renders is in GMON.exr under its name, and GMON_FILE.exr holds the same
     pixels (the statistics file kept everything); the ID channels (Cryptomatte, IndexOB/MA) of
     each pixel are, together, one render's labels, never averaged;
  b. per pixel and channel, |key + fill + sky - Combined| of the robust image is within the
     largest such residual of the input renders in that pixel (the weights are convex, so it
     cannot be more) plus the float rounding of the four weighted sums (TOL below);
  c. ViewLayer.Combined.A is the image's alpha channel, and within the inputs' range per pixel;
  d. the beauty of GMON.exr is bit for bit GMON_BEAUTY.exr's, and its relMSE against REF.exr is
     at least GAIN times below the plain mean's (the key light's fireflies through the glass).
Exit status 1 with the failed checks listed. Needs numpy and OpenImageIO's Python bindings.
"""

import glob
import os
import sys

import numpy as np
import OpenImageIO as oiio

LAYER = "ViewLayer."
GROUPS = ["Combined_key", "Combined_fill", "Combined_sky"]
ALPHA = LAYER + "Combined.A"
# Each of the four robust values is rounded once to float (2^-24 relative); 8 ulps of the sum of
# their magnitudes leaves room for the weighted sums' own rounding and nothing more.
TOL = 8 * 2.0 ** -24
GAIN = 10  # "clearly better than the mean": the measured gain is about 10,000x


def read(path):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        sys.exit("check_robust_aovs: %s: %s" % (path, buf.geterror()))
    spec = buf.spec()
    px = buf.get_pixels(oiio.FLOAT)
    if px is None:
        sys.exit("check_robust_aovs: %s: cannot read pixels" % path)
    return spec, {n: px[:, :, i] for i, n in enumerate(spec.channelnames)}


def group_residual(ch, c):
    """|key + fill + sky - Combined| in channel c, and the magnitude of its terms, in double."""
    terms = [ch[LAYER + g + "." + c].astype(np.float64) for g in GROUPS]
    beauty = ch[LAYER + "Combined." + c].astype(np.float64)
    return np.abs(sum(terms) - beauty), sum(np.abs(t) for t in terms) + np.abs(beauty)


def rel_mse(x, ref):
    """Mean over pixels and R, G, B of (x - ref)^2 / (ref^2 + 0.01), as `mcstat --diff`."""
    out = 0.0
    for c in "RGB":
        a = x[LAYER + "Combined." + c].astype(np.float64)
        r = ref[LAYER + "Combined." + c].astype(np.float64)
        out += np.mean((a - r) ** 2 / (r * r + 0.01))
    return out / 3


def bits(ch, names):
    """The channels' float bits stacked on the last axis (labels compare exactly, NaN included)."""
    return np.stack([ch[n] for n in names], axis=-1).view(np.uint32)


def main():
    if len(sys.argv) != 7:
        sys.exit(__doc__)
    seed_dir, gmon_path, file_path, beauty_path, mean_path, ref_path = sys.argv[1:]
    seeds = sorted(glob.glob(os.path.join(seed_dir, "seed_*.exr")))
    if not seeds:
        sys.exit("check_robust_aovs: no seed_*.exr in " + seed_dir)
    failures = []
    gspec, g = read(gmon_path)
    inputs = [read(s)[1] for s in seeds]

    # a. Every channel of the renders, under its name; the same from the statistics file; labels whole.
    in_names = set().union(*inputs)
    missing = sorted(in_names - set(g))
    print("a. channels: %d in the %d renders, %d in the result, missing: %s"
          % (len(in_names), len(inputs), len(g), ", ".join(missing) or "none"))
    if missing:
        failures.append("%d input channels missing from %s" % (len(missing), gmon_path))
    names = sorted(set(g))
    _, f = read(file_path)
    same_file = sorted(f) == names and np.array_equal(bits(g, names), bits(f, names))
    print("   G-MoN from the statistics file identical in every channel: %s" % same_file)
    if not same_file:
        failures.append("G-MoN from the statistics file differs from G-MoN after --ingest")
    renderer = gspec.getattribute("mcstat.renderer")
    print("   mcstat.renderer: %s" % renderer)
    if renderer != "Blender/Cycles via mcstat --ingest":
        failures.append("mcstat.renderer is %s, not Blender/Cycles via mcstat --ingest" % renderer)
    # Cycles' own sample count says the result's samples, every render together.
    key = "cycles.ViewLayer.samples"
    seed_spp = oiio.ImageInput.open(seeds[0]).spec().getattribute(key)
    want = str(int(seed_spp) * len(seeds)) if seed_spp else None
    print("   %s: %s (renders: %s each, %d renders)" % (key, gspec.getattribute(key), seed_spp,
                                                       len(seeds)))
    if want is None or gspec.getattribute(key) != want:
        failures.append("%s is %s, not %s" % (key, gspec.getattribute(key), want))
    ids = [n for n in names if n in in_names and any(k in n for k in ("Crypto", "IndexOB", "IndexMA"))]
    mixed = 0
    if ids:
        out_ids = bits(g, ids)
        one_render = np.any([np.all(bits(ch, ids) == out_ids, axis=-1) for ch in inputs], axis=0)
        mixed = int(np.count_nonzero(~one_render))
    print("   %d ID channels; pixels whose labels are not one render's: %d of %d"
          % (len(ids), mixed, g[LAYER + "Combined.R"].size))
    if len(ids) != 14 or mixed:
        failures.append("%d of the 14 ID channels, %d pixels with mixed or averaged labels"
                        % (len(ids), mixed))

    # b. Light groups against the beauty: never further apart than in the worst input render.
    violations, worst_in, worst_out, worst_excess = 0, 0.0, 0.0, -np.inf
    for c in "RGB":
        band = np.max([group_residual(ch, c)[0] for ch in inputs], axis=0)
        res, scale = group_residual(g, c)
        limit = band + TOL * scale
        violations += int(np.count_nonzero(~(res <= limit)))  # NaN counts as a violation
        worst_in = max(worst_in, float(np.max(band)))
        worst_out = max(worst_out, float(np.max(res)))
        worst_excess = max(worst_excess, float(np.max(res - band)))
    pixels = g[LAYER + "Combined.R"].size
    print("b. light groups: %d of %d pixel-channels outside the inputs' band + %.3g x (|key| + "
          "|fill| + |sky| + |Combined|); largest input residual %.3g, largest robust residual %.3g, "
          "largest robust residual minus its pixel's band %.3g"
          % (violations, 3 * pixels, TOL, worst_in, worst_out, worst_excess))
    if violations:
        failures.append("%d pixel-channels where the robust light groups leave the inputs' band"
                        % violations)

    # c. Alpha: the image's alpha channel, a convex combination of the renders' alphas.
    alpha = gspec.channelnames[gspec.alpha_channel] if gspec.alpha_channel >= 0 else None
    a_in = np.stack([ch[ALPHA] for ch in inputs])
    a = g.get(ALPHA, np.full(a_in.shape[1:], np.nan, np.float32))
    outside = int(np.count_nonzero(~((a >= a_in.min(0) - 1e-6) & (a <= a_in.max(0) + 1e-6))))
    print("c. alpha channel: %s; pixels outside the renders' alpha range: %d; alpha 0 / between / 1: "
          "%d / %d / %d" % (alpha, outside, np.sum(a == 0), np.sum((a > 0) & (a < 1)), np.sum(a == 1)))
    if alpha != ALPHA or outside:
        failures.append("alpha channel is %s (%s expected), %d pixels outside the renders' range"
                        % (alpha, ALPHA, outside))

    # d. The beauty is the beauty-alone G-MoN, bit for bit, and clearly beats the mean.
    _, b = read(beauty_path)
    rgb = [LAYER + "Combined." + c for c in "RGB"]
    same = np.array_equal(bits(g, rgb), bits(b, rgb))
    _, m = read(mean_path)
    _, ref = read(ref_path)
    e_gmon, e_mean = rel_mse(g, ref), rel_mse(m, ref)
    print("d. beauty bit for bit G-MoN of the beauty alone: %s; relMSE against the reference: "
          "mean %.4g, G-MoN %.4g (%.0fx lower; at least %dx asked)"
          % (same, e_mean, e_gmon, e_mean / max(e_gmon, 1e-30), GAIN))
    if not same:
        failures.append("the beauty differs from G-MoN of the beauty alone")
    if not e_gmon * GAIN < e_mean:
        failures.append("G-MoN's relMSE %.4g is not %dx below the mean's %.4g" % (e_gmon, GAIN, e_mean))

    for msg in failures:
        print("check_robust_aovs: FAILED: " + msg, file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
