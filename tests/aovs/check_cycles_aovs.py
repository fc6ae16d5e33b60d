#!/usr/bin/python3
"""Measure what a Cycles multilayer EXR (cycles_caustic.py) holds and how its passes add up.

  /usr/bin/python3 tests/aovs/check_cycles_aovs.py FILE.exr [MORE.exr ...] [--ref REF.exr]

For each file: parts, channel names, header attributes, data/display window, then
  1. light groups:  Combined_key + Combined_fill + Combined_sky  vs  Combined.RGB,
     split by alpha (== 1, strictly between 0 and 1, == 0)
     and  key + fill + sky - Env  vs  Combined.RGB
  2. light paths:   (DiffDir+DiffInd)*DiffCol + (GlossDir+GlossInd)*GlossCol
                    + (TransDir+TransInd)*TransCol + Emit + Env  vs  Combined.RGB
  3. labels: IndexOB / IndexMA values, Cryptomatte ranks decoded against the manifest.
With several files, the worst residual over all of them; with --ref, the RMSE of the mean of the
files' Combined against the reference (and of each file alone, for scale).
Needs numpy and OpenImageIO's Python bindings (Debian: python3-numpy python3-openimageio).
"""

import argparse
import json
import struct
import sys

import numpy as np
import OpenImageIO as oiio


def read(path):
    inp = oiio.ImageInput.open(path)
    if inp is None:
        sys.exit("cannot open %s: %s" % (path, oiio.geterror()))
    parts = []
    sub = 0
    while inp.seek_subimage(sub, 0):
        spec = inp.spec()
        px = inp.read_image(sub, 0, 0, spec.nchannels, "float")
        parts.append((spec, np.asarray(px, dtype=np.float32)))
        sub += 1
    inp.close()
    return parts


def channels(spec, px):
    return {name: px[..., i] for i, name in enumerate(spec.channelnames)}


def rgb(ch, layer):
    return np.stack([ch["%s.%s" % (layer, c)] for c in "RGB"], axis=-1)


def fmt(x):
    return "%.3g" % x


def describe(path, spec_list):
    print("== %s" % path)
    print("parts: %d" % len(spec_list))
    for i, spec in enumerate(spec_list):
        print("part %d: %dx%d, %d channels, data window (%d,%d)-(%d,%d), display window (%d,%d)-(%d,%d)"
              % (i, spec.width, spec.height, spec.nchannels,
                 spec.x, spec.y, spec.x + spec.width - 1, spec.y + spec.height - 1,
                 spec.full_x, spec.full_y, spec.full_x + spec.full_width - 1,
                 spec.full_y + spec.full_height - 1))
        same = (spec.x, spec.y, spec.width, spec.height) == (
            spec.full_x, spec.full_y, spec.full_width, spec.full_height)
        print("  data window == display window: %s" % same)
        print("  channel formats: %s" % sorted({str(f) for f in spec.channelformats} or {str(spec.format)}))
        print("  channels: %s" % ", ".join(spec.channelnames))
        print("  attributes:")
        for a in spec.extra_attribs:
            v = a.value
            s = json.dumps(v) if isinstance(v, str) else str(v)
            if len(s) > 140:
                s = s[:140] + "..."
            print("    %s (%s) = %s" % (a.name, a.type, s))


def residual_stats(name, est, ref, masks):
    d = np.abs(est - ref).max(axis=-1)
    scale = np.maximum(np.abs(ref).max(axis=-1), 1e-3)
    out = {}
    for mname, m in masks.items():
        if not m.any():
            out[mname] = None
            continue
        out[mname] = (int(m.sum()), float(d[m].max()), float((d / scale)[m].max()),
                      float(np.abs(ref).max(axis=-1)[m].max()))
    return out


def analyse(path, verbose):
    parts = read(path)
    if verbose:
        describe(path, [s for s, _ in parts])
    spec, px = parts[0]
    ch = channels(spec, px)
    layer = next(n[:-len(".Combined.R")] for n in ch if n.endswith(".Combined.R"))
    L = lambda p: layer + "." + p
    comb = rgb(ch, L("Combined"))
    alpha = ch[L("Combined.A")]
    masks = {"alpha==1": alpha >= 1.0 - 1e-6,
             "0<alpha<1": (alpha > 1e-6) & (alpha < 1.0 - 1e-6),
             "alpha==0": alpha <= 1e-6}
    res = {"alpha counts": {k: int(m.sum()) for k, m in masks.items()}}

    groups = sorted(n[len(L("Combined_")):-2] for n in ch if n.startswith(L("Combined_")) and n.endswith(".R"))
    gsum = sum(rgb(ch, L("Combined_" + g)) for g in groups)
    res["groups"] = groups
    res["lightgroups"] = residual_stats("groups", gsum, comb, masks)
    # premultiplied: what is the groups' sum in the transparent pixels?
    res["groups_sum_max_alpha0"] = float(gsum[masks["alpha==0"]].max()) if masks["alpha==0"].any() else None
    res["lightgroups_minus_env"] = residual_stats("groups-env", gsum - rgb(ch, L("Env")), comb, masks)

    def term(k):
        col = rgb(ch, L(k + "Col"))
        return (rgb(ch, L(k + "Dir")) + rgb(ch, L(k + "Ind"))) * col
    lp = term("Diff") + term("Gloss") + term("Trans") + rgb(ch, L("Emit")) + rgb(ch, L("Env"))
    res["lightpaths"] = residual_stats("paths", lp, comb, masks)
    lp_noenv = lp - rgb(ch, L("Env"))
    res["lightpaths_without_env"] = residual_stats("paths", lp_noenv, comb, masks)
    res["env_max_alpha0"] = float(rgb(ch, L("Env"))[masks["alpha==0"]].max()) if masks["alpha==0"].any() else None
    res["env_max_alpha1"] = float(rgb(ch, L("Env"))[masks["alpha==1"]].max())

    # labels
    labels = {}
    for k in ("IndexOB.X", "IndexMA.X"):
        v = ch[L(k)]
        u = np.unique(v)
        labels[k] = (u[:12].tolist(), bool(np.all(u == np.round(u))))
    res["labels"] = labels
    res["depth"] = {k: (float(ch[L(k)].min()), float(ch[L(k)].max()))
                    for k in ("Depth.Z", "Denoising Depth.Z") if L(k) in ch}
    # Cryptomatte: ranks are (id, coverage) pairs, two per RGBA layer
    crypto = {}
    manifest = {}
    for a in spec.extra_attribs:
        if a.name.startswith("cryptomatte/") and a.name.endswith("/manifest"):
            manifest = {int(h, 16): n for n, h in json.loads(a.value).items()}
    cl = sorted({n.rsplit(".", 1)[0] for n in ch if ".Crypto" in n})
    ranks = []
    for c in cl:
        ranks.append((ch[c + ".r"], ch[c + ".g"]))
        ranks.append((ch[c + ".b"], ch[c + ".a"]))
    cov_sum = sum(cv for _, cv in ranks)
    ids = set()
    for idf, cv in ranks:
        for f in np.unique(idf[cv > 0]):
            ids.add(struct.unpack("<I", struct.pack("<f", float(f)))[0])
    crypto["layers"] = cl
    crypto["ranks"] = len(ranks)
    crypto["coverage_sum_range_alpha1"] = (float(cov_sum[masks["alpha==1"]].min()), float(cov_sum[masks["alpha==1"]].max()))
    crypto["coverage_sum_range_alpha0"] = (float(cov_sum[masks["alpha==0"]].min()), float(cov_sum[masks["alpha==0"]].max())) if masks["alpha==0"].any() else None
    crypto["max |coverage sum - alpha|"] = float(np.abs(cov_sum - alpha).max())
    crypto["ids_found"] = sorted(manifest.get(i, "unknown:%08x" % i) for i in ids)
    res["crypto"] = crypto
    res["terms"] = {k: (rgb(ch, L(k + "Dir")) + rgb(ch, L(k + "Ind")), rgb(ch, L(k + "Col")))
                    for k in ("Diff", "Gloss", "Trans")}
    return res, comb


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("files", nargs="+")
    p.add_argument("--ref")
    a = p.parse_args()
    worst = {}
    combs = []
    terms = []
    for i, f in enumerate(a.files):
        res, comb = analyse(f, verbose=(i == 0))
        combs.append(comb)
        terms.append(res["terms"])
        if i == 0:
            print("alpha pixel counts: %s" % res["alpha counts"])
            print("light groups: %s" % res["groups"])
            print("labels (unique values, all integer?): %s" % res["labels"])
            print("depth ranges: %s" % res["depth"])
            print("cryptomatte: %s" % res["crypto"])
            print("Env max where alpha==0: %s, where alpha==1: %s" % (res["env_max_alpha0"], res["env_max_alpha1"]))
            print("light-group sum max where alpha==0: %s" % res["groups_sum_max_alpha0"])
        for rel in ("lightgroups", "lightgroups_minus_env", "lightpaths", "lightpaths_without_env"):
            for m, v in res[rel].items():
                if v is None:
                    continue
                key = (rel, m)
                n, dabs, drel, refmax = v
                w = worst.get(key)
                if w is None or dabs > w[1]:
                    worst[key] = (n, dabs, drel, refmax, f)
    print("\n== sum relations, worst over %d file(s): |sum - Combined| (max over RGB)" % len(a.files))
    print("%-24s %-10s %8s %12s %12s %12s  %s" % ("relation", "pixels", "count", "max abs", "max rel", "max |Comb|", "file"))
    for (rel, m), (n, dabs, drel, refmax, f) in sorted(worst.items()):
        print("%-24s %-10s %8d %12s %12s %12s  %s" % (rel, m, n, fmt(dabs), fmt(drel), fmt(refmax), f))
    if a.ref:
        rres, ref = analyse(a.ref, verbose=False)
        mean = np.mean(combs, axis=0)
        rmse = lambda x: float(np.sqrt(np.mean((x - ref) ** 2)))
        single = [rmse(c) for c in combs]
        print("\nreference %s: RMSE of the mean of %d files %s; one file: median %s, max %s; max |Combined| one file %s, reference %s"
              % (a.ref, len(combs), fmt(rmse(mean)), fmt(float(np.median(single))), fmt(max(single)),
                 fmt(float(max(c.max() for c in combs))), fmt(float(ref.max()))))
        # Cycles stores Dir and Ind divided by Col: is the mean of the products the product of the means?
        print("light-path terms, averaged over the files two ways: A = mean(light*Col), B = mean(light)*mean(Col)")
        for k in ("Diff", "Gloss", "Trans"):
            A = np.mean([t[k][0] * t[k][1] for t in terms], axis=0)
            B = np.mean([t[k][0] for t in terms], axis=0) * np.mean([t[k][1] for t in terms], axis=0)
            R = rres["terms"][k][0] * rres["terms"][k][1]
            print("  %-5s max|A-B| %s (max|A| %s); RMSE vs reference term: A %s, B %s; Col varies across files: max std %s"
                  % (k, fmt(float(np.abs(A - B).max())), fmt(float(np.abs(A).max())),
                     fmt(float(np.sqrt(np.mean((A - R) ** 2)))), fmt(float(np.sqrt(np.mean((B - R) ** 2)))),
                     fmt(float(np.std([t[k][1] for t in terms], axis=0).max()))))


if __name__ == "__main__":
    main()
