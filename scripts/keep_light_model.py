#!/usr/bin/env python3
"""scripts/keep_light_model.py: a numpy model of `:keeplight=1` (docs/keep-light.md), to try scale
rules on many renders quickly. Not part of the tests, and not the implementation: the CLI's
filters/keep_light.cpp is. The model follows its rules (ICI over windows of radius 0, 1, 2,
4, ... R; the 3 x 3 support test; the cluster guide at radius 1; the albedo guide beyond; a pixel
whose neighbours' robust median lies nearer its mean keeps its light; a supported cluster's
pixel keeps 1 - (support / Z)^2 of its light and sends the rest to ICI's own radius by the light
guide; windows of radius 2 to 16 follow the bias guide; a pixel no rule keeps close keeps half
the gap between its 8 neighbours' median plain mean and its robust value in place; a residual
beyond own_z (2.5) of its own standard errors, and every gain, stays in place) with
scipy's convolutions instead of the exact block sums, and the luminance spread of the buffers as
removed_light.h defines it. Its relMSE matched the CLI's to four digits on the fixture's default
scene and within 2 % on every scene of docs/keep-light.md, "Measured" (2026-12-01).

  keep_light_model.py STATS ROBUST.exr [--gamma G] [--radius R] [--support Z] [--ref REF.exr]
                      [--check CLI.exr] [-o OUT.exr]

STATS is a statistics file (its parts "buffers" and "features" are read by channel name), ROBUST
the estimator's image of it (e.g. `mcstat STATS --gmon -o ROBUST.exr`). Prints relMSE as `--diff`
computes it and the energy against REF; with --check, the relMSE of the CLI's light-keeping image
of the same file (`mcstat STATS --gmon:keeplight=1 -o CLI.exr`, the same settings) and exit
status 1 when the two differ by more than 2 %.
"""
import argparse
import os
import sys
import warnings

import numpy as np
import OpenImageIO as oiio
from scipy.ndimage import convolve1d

LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec.709 primaries, as the fixture's files


def read_part(path, name=None):
    """The pixels (float64, H x W x C) and channel names of the part called `name` (or the
    first)."""
    inp = oiio.ImageInput.open(path)
    if inp is None:
        sys.exit(f"keep_light_model: {path}: {oiio.geterror()}")
    sub = 0
    while name is not None and inp.spec().getattribute("name") != name:
        sub += 1
        if not inp.seek_subimage(sub, 0):
            sys.exit(f"keep_light_model: {path}: no part called {name}")
    names = list(inp.spec().channelnames)
    px = np.asarray(inp.read_image(oiio.FLOAT), dtype=np.float64)
    inp.close()
    return px, names


def channels(px, names, wanted, path):
    try:
        return px[..., [names.index(n) for n in wanted]]
    except ValueError:
        sys.exit(f"keep_light_model: {path}: missing one of {wanted}")


def beauty(path):
    """An image's beauty RGB: the channels R, G, B, or the first layer's L.R, L.G, L.B (a render
    with AOVs, as the CLI writes it back: the renderer's own names)."""
    px, names = read_part(path)
    if not all(c in names for c in "RGB"):
        for n in names:
            layer = n[:-2]
            if n.endswith(".R") and f"{layer}.G" in names and f"{layer}.B" in names:
                return channels(px, names, [n, f"{layer}.G", f"{layer}.B"], path)
    return channels(px, names, ["R", "G", "B"], path)


def load(stats, robust_path):
    """Plain mean, the luminance's standard error, albedo luminance and the robust RGB."""
    buf, names = read_part(stats, "buffers")
    ids = sorted({n.split(".")[0] for n in names if n.endswith(".count")})
    rgb = np.stack([channels(buf, names, [f"{b}.R", f"{b}.G", f"{b}.B"], stats) for b in ids], 2)
    cnt = np.stack([channels(buf, names, [f"{b}.count"], stats)[..., 0] for b in ids], 2)
    n = cnt.sum(-1)
    mean = (rgb * cnt[..., None]).sum(2) / np.maximum(n, 1)[..., None]
    yb, ym = (rgb * LUMA).sum(-1), (mean * LUMA).sum(-1)
    valid = (cnt > 0).sum(-1)
    var = (cnt * (yb - ym[..., None]) ** 2).sum(-1) / np.maximum(valid - 1, 1)
    se = np.where(valid > 1, np.sqrt(var / np.maximum(n, 1)), 0.0)
    feat, fnames = read_part(stats, "features")
    albedo = (channels(feat, fnames, ["Albedo.R", "Albedo.G", "Albedo.B"], stats) * LUMA).sum(-1)
    return mean, se, albedo, beauty(robust_path)


def line_sum(a, kernel):
    """The image convolved with a separable kernel, zero outside (windows clipped)."""
    return convolve1d(convolve1d(a, kernel, axis=0, mode="constant"), kernel, axis=1,
                      mode="constant")


def box(a, r):
    return line_sum(a, np.ones(2 * r + 1)) if r else a.copy()


def tent(a, r):
    return line_sum(a, np.array([r + 1 - abs(i) for i in range(-r, r + 1)], float)) if r else a.copy()


def radii_of(max_radius):
    radii = [0]
    r = 1
    while r < max_radius:
        radii.append(r)
        r *= 2
    return radii + [max_radius] if max_radius > 0 else radii


def scales(d, se, active, gamma, radii, support_z, split=False):
    """Rule 1 (ICI) and rule 2 (the 3 x 3 support test): each pixel's index into radii. With
    split, also ICI's own index, the 3 x 3 test's Z and verdict (rule 6), and rule 7's bias (ICI's
    window mean at its own radius, at least 0) and level (the largest window's mean, at least 0),
    for every pixel."""
    lo, hi = np.full(d.shape, -np.inf), np.full(d.shape, np.inf)
    alive = np.ones(d.shape, bool)
    chosen = np.zeros(d.shape, int)
    estimate = np.zeros(d.shape)
    ones, s2 = np.ones_like(d), se * se
    for k, r in enumerate(radii):
        area = box(ones, r)
        m, s = box(d, r) / area, np.sqrt(np.maximum(box(s2, r), 0)) / area
        lo, hi = np.maximum(lo, m - gamma * s), np.minimum(hi, m + gamma * s)
        alive &= lo <= hi
        chosen[alive] = k
        estimate[alive] = m[alive]
    bias, level = np.maximum(estimate, 0), np.maximum(m, 0)
    ici = chosen.copy()
    sd, ss = box(d, 1), box(s2, 1)
    z = np.where(ss > 0, sd / np.sqrt(np.where(ss > 0, ss, 1)), 0)
    supported = (ss > 0) & (z >= support_z)
    if 1 in radii:
        chosen = np.where(supported, np.minimum(chosen, radii.index(1)), chosen)
    chosen[~active] = 0
    return (chosen, ici, z, supported, bias, level) if split else chosen


def mean_nearer_neighbours(robust_y, d):
    """Rule 5 (the edge of a bright surface): where the median of the 3 x 3 window's robust
    luminance (finite values only; beyond the image, the nearest pixel inside it) lies nearer the
    pixel's mean than its robust value, the pixel keeps its light."""
    h, w = robust_y.shape
    pad = np.pad(robust_y, 1, mode="edge")
    win = np.stack([pad[j:j + h, i:i + w] for j in range(3) for i in range(3)], -1)
    win = np.where(np.isfinite(win), win, np.nan)
    with warnings.catch_warnings():  # a window of non-finite values only: no median, no test
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(win, -1)
    ok = np.isfinite(robust_y) & np.isfinite(d)
    return ok & (np.abs(robust_y + d - med) < np.abs(robust_y - med))


def neighbours_level(robust_y, d):
    """Rule 8's level: the median of the 8 neighbours' plain-mean luminance (finite values only;
    beyond the image, the nearest pixel inside it); NaN where none is finite."""
    h, w = robust_y.shape
    pad = np.pad(robust_y + d, 1, mode="edge")
    nb = np.stack([pad[j:j + h, i:i + w] for j in range(3) for i in range(3) if (i, j) != (1, 1)], -1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(np.where(np.isfinite(nb), nb, np.nan), -1)


def cluster_guide(d, light):
    """Rule 3's guide: c sqrt(m + c), c the 3 x 3 tent's mean of the positive residual, m the
    light guide (light_guide's)."""
    k = np.array([1.0, 2.0, 1.0])
    c = line_sum(np.maximum(d, 0), k) / line_sum(np.ones_like(d), k)
    return c * np.sqrt(light + c)


def light_guide(robust_y, d):
    """Rule 6's guide: the plain mean's luminance (0 where negative or not finite), at most the
    brightest of its 8 neighbours' inside the image."""
    h, w = d.shape
    m = robust_y + d
    m = np.where(np.isfinite(m) & (m > 0), m, 0.0)
    pad = np.pad(m, 1, mode="constant")
    nb = np.stack([pad[j:j + h, i:i + w] for j in range(3) for i in range(3) if (i, j) != (1, 1)])
    return np.minimum(m, nb.max(0))


def send(out, resid, part, senders, r, guides):
    """Adds resid x part of the senders at radius r, by the first guide whose window sum is not 0."""
    left = senders
    for guide in guides:
        norm = tent(guide, r)
        these = left & (norm > 0)
        left = left & ~these
        if not these.any():
            continue
        share = np.where(these, part / np.where(norm > 0, norm, 1.0), 0.0)
        for c in range(3):
            out[..., c] += guide * tent(resid[..., c] * share, r)


def bias_guide(bias, level, albedo, floor=4.0):
    """Rule 7's guide: the bias where a surface was hit, plus floor x albedo x level."""
    g = np.where(np.isfinite(albedo) & (albedo > 0), albedo, 0.0)
    return np.where(g > 0, bias + floor * g * level, 0.0)


def keep_light(mean, se, albedo, robust, gamma=4.0, max_radius=64, support_z=2.0,
               bias_radius=16, bias_floor=4.0, neighbour_share=0.5, own_z=2.5):
    resid = mean - robust
    resid[~np.isfinite(resid)] = 0.0
    d = (resid * LUMA).sum(-1)
    active = np.abs(resid).max(-1) > 0
    radii = radii_of(max_radius)
    chosen, ici, z, supported, bias, level = scales(d, se, active, gamma, radii, support_z,
                                                     split=True)
    robust_y = (robust * LUMA).sum(-1)
    chosen = np.where(mean_nearer_neighbours(robust_y, d), 0, chosen)
    # Rule 9: a gain, and a loss beyond own_z of its own standard errors, stay in place.
    with np.errstate(invalid="ignore"):
        beyond = np.isfinite(d) & np.isfinite(se) & ((d < 0) | (d > own_z * np.maximum(se, 0)))
    chosen = np.where(beyond, 0, chosen)
    # Rule 6: a pixel the support test capped at radius 1 where ICI chose wider keeps the share
    # 1 - (support / Z)^2 there and sends the rest at ICI's own radius by the light guide.
    split = active & supported & (chosen == 1) & (ici > 1)
    keep = np.where(split, np.clip(1 - (support_z / np.where(z > 0, z, 1)) ** 2, 0, 1), 1.0)
    # Rule 8: a pixel no rule keeps close keeps min(d, share x (level - robust)) in place.
    with np.errstate(invalid="ignore"):
        gap = neighbours_level(robust_y, d) - robust_y
        own = active & ~supported & (chosen != 0) & (d > 0) & np.isfinite(robust_y) & (gap > 0)
    kept = np.where(own, np.minimum(d, neighbour_share * np.where(own, gap, 0)) / np.where(own, d, 1), 0)
    keep = np.where(own, 1 - kept, keep)
    rest_at = np.where(split, ici, 0)
    light, ones = light_guide(robust_y, d), np.ones_like(d)
    cluster = cluster_guide(d, light)
    by_bias = bias_guide(bias, level, albedo, bias_floor)
    out = robust.copy()
    for k, r in enumerate(radii):
        # Rule 3 at radius 1, rule 7 at radii 2 to bias_radius, else rule 4 (the albedo), else
        # the tent alone: the first whose weights over the window are not all 0.
        senders = active & (chosen == k)
        if senders.any():
            first = [cluster] if r == 1 else [by_bias] if 2 <= r <= bias_radius else []
            send(out, resid, keep, senders, r, first + [albedo, ones])
        rest = (split | own) & (rest_at == k) & (keep < 1)
        if rest.any():
            send(out, resid, 1 - keep, rest, r, [light, ones])
    return out


def rel_mse(img, ref):
    return float(((img - ref) ** 2 / (ref ** 2 + 0.01)).mean())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("stats")
    ap.add_argument("robust")
    ap.add_argument("--gamma", type=float, default=4.0)
    ap.add_argument("--radius", type=int, default=64)
    ap.add_argument("--support", type=float, default=2.0)
    ap.add_argument("--ref")
    ap.add_argument("--check")
    ap.add_argument("-o", dest="out")
    a = ap.parse_args()
    mean, se, albedo, robust = load(a.stats, a.robust)
    img = keep_light(mean, se, albedo, robust, a.gamma, a.radius, a.support)
    if a.out:
        spec = oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.FLOAT)
        spec.channelnames = ("R", "G", "B")
        # Written under a temporary name in the same folder, then renamed: never half a file.
        base, ext = os.path.splitext(a.out)
        tmp = f"{base}.tmp{os.getpid()}{ext}"
        out = oiio.ImageOutput.create(tmp)
        ok = out is not None and out.open(tmp, spec) and out.write_image(img.astype(np.float32))
        if out is not None:
            ok = out.close() and ok
        if not ok:
            if os.path.exists(tmp):
                os.remove(tmp)
            sys.exit(f"keep_light_model: {a.out}: {oiio.geterror() or 'cannot write it'}")
        os.replace(tmp, a.out)
    if not a.ref:
        return 0
    ref = beauty(a.ref)
    energy = (img * LUMA).sum() / (ref * LUMA).sum() - 1
    model = rel_mse(img, ref)
    print(f"model relMSE {model:.6g} energy {100 * energy:+.2f} % (robust {rel_mse(robust, ref):.6g})")
    if a.check:
        cli = rel_mse(beauty(a.check), ref)
        print(f"CLI   relMSE {cli:.6g}")
        if abs(model - cli) > 0.02 * cli:
            print("keep_light_model: the model and the CLI differ by more than 2 %", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
