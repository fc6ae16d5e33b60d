#!/usr/bin/env python3
"""The tables of docs/trade.md from the table scripts/trade.sh writes (trade.csv).

python3 scripts/trade_tables.py trade.csv [SPP]

Per scene, method and spp the seeds are averaged (relMSE, SSIM, fireflies, nbias, seconds, bytes
per pixel) and their spread kept (the standard deviation over the seeds). Two comparisons with the
mean, both in the same scene:
  - equal time: the method's relMSE over the mean's relMSE at the method's time, the mean's taken
    from its own measured curve (relMSE against seconds at every spp it ran, log-log linear between
    points; beyond its last point extended with slope -1, relMSE ~ 1/time, which is what more
    samples give an unbiased estimate while its noise dominates). Below 1: the method beats simply
    rendering longer.
  - efficiency, 1 / (relMSE x seconds), over the mean's at the same spp.
Pooled rows take the geometric mean of the per-scene ratios (scenes differ in scale by orders of
magnitude; a ratio per scene keeps each scene's weight equal).
"""
import csv
import math
import statistics
import sys
from collections import OrderedDict, defaultdict


def load(path):
    rows = list(csv.DictReader(open(path, newline="")))
    for r in rows:
        for k in ("spp", "seconds", "bytesPerPixel", "relMSE", "SSIM", "fireflies", "pixels",
                  "nbias", "nnoise"):
            r[k] = float(r[k])
        # detail (docs/metrics.md) came later: older tables have no such column
        r["detail"] = float(r.get("detail") or "nan")
        r["energy"] = float(r.get("energy") or "nan")
    return rows


def summarise(rows):
    """(scene, method, spp) -> averages and spreads over the seeds."""
    groups = OrderedDict()
    for r in rows:
        groups.setdefault((r["scene"], r["method"], r["spp"]), []).append(r)
    out = OrderedDict()
    for key, g in groups.items():
        def mean(k):
            return statistics.fmean(x[k] for x in g)

        def sd(k):
            return statistics.stdev(x[k] for x in g) if len(g) > 1 else 0.0

        out[key] = {"n": len(g), "seconds": mean("seconds"), "bytes": mean("bytesPerPixel"),
                    "relMSE": mean("relMSE"), "relMSE_sd": sd("relMSE"), "SSIM": mean("SSIM"),
                    "fireflies": mean("fireflies"), "nbias": mean("nbias"),
                    "detail": mean("detail"), "energy": mean("energy"),
                    "nbias_sd": sd("nbias"), "pixels": g[0]["pixels"]}
    return out


def mean_curve(summary, scene):
    pts = sorted((v["seconds"], v["relMSE"]) for (s, m, _), v in summary.items()
                 if s == scene and m == "mean")
    return pts


def mean_at(curve, t):
    """The mean's relMSE at time t: log-log linear between its points, slope -1 beyond them."""
    if t <= curve[0][0]:
        t0, r0 = curve[0]
        return r0 * t0 / t
    for (t0, r0), (t1, r1) in zip(curve, curve[1:]):
        if t <= t1:
            a = (math.log(t) - math.log(t0)) / (math.log(t1) - math.log(t0))
            return math.exp(math.log(r0) + a * (math.log(r1) - math.log(r0)))
    t1, r1 = curve[-1]
    return r1 * t1 / t


def gmean(xs):
    xs = [x for x in xs if x > 0 and math.isfinite(x)]
    return math.exp(statistics.fmean(math.log(x) for x in xs)) if xs else float("nan")


def main():
    rows = load(sys.argv[1])
    spp_shown = float(sys.argv[2]) if len(sys.argv) > 2 else 64.0
    summary = summarise(rows)
    scenes = list(OrderedDict.fromkeys(r["scene"] for r in rows))
    methods = list(OrderedDict.fromkeys(r["method"] for r in rows if r["method"] != "reference"))
    spps = sorted({r["spp"] for r in rows if r["method"] not in ("reference",)})
    seeds = len({r["seed"] for r in rows if r["method"] != "reference"})
    curves = {s: mean_curve(summary, s) for s in scenes}

    def ratios(method, spp):
        """Per scene: (equal-time ratio, efficiency ratio, time ratio) against the mean."""
        out = {}
        for s in scenes:
            v, base = summary.get((s, method, spp)), summary.get((s, "mean", spp))
            if not v or not base or v["relMSE"] <= 0:
                continue
            eq = v["relMSE"] / mean_at(curves[s], v["seconds"])
            eff = (base["relMSE"] * base["seconds"]) / (v["relMSE"] * v["seconds"])
            out[s] = (eq, eff, v["seconds"] / base["seconds"])
        return out

    print(f"Seeds per point: {seeds}; spp: {', '.join(f'{s:g}' for s in spps)}; "
          f"scenes: {', '.join(scenes)}.\n")
    def reference(scene, key, fmt):
        vs = [r[key] for r in rows if r["scene"] == scene and r["method"] == "reference"]
        return format(statistics.fmean(vs), fmt) if vs else "-"

    print("### The reference's own noise (relMSE of one reference against another, halved; "
          "detail of one against the other)\n")
    print("| | " + " | ".join(scenes) + " |")
    print("|---|" + "---|" * len(scenes))
    print("| relMSE | " + " | ".join(reference(s, "relMSE", ".3g") for s in scenes) + " |")
    print("| detail | " + " | ".join(reference(s, "detail", ".3f") for s in scenes) + " |\n")

    for spp in spps:
        have = [m for m in methods if any((s, m, spp) in summary for s in scenes)]
        if len(have) < 2:
            continue
        print(f"### Every scene pooled, {spp:g} spp\n")
        print("Ratios are geometric means over the scenes of each scene's ratio to the mean at "
              "the same spp (equal time: to the mean given the method's time). relMSE: the "
              "geometric mean over the scenes; nbias: mean ± standard deviation over scenes and "
              "seeds; fireflies: per image, mean over scenes and seeds.\n")
        print("| method | time × mean | bytes/px | relMSE | relMSE at equal time × mean | "
              "efficiency × mean | SSIM | detail | fireflies | energy | nbias |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for m in have:
            r = ratios(m, spp)
            vs = [summary[(s, m, spp)] for s in scenes if (s, m, spp) in summary]
            nb = [x["nbias"] for x in rows if x["method"] == m and x["spp"] == spp]
            print(f"| {m} | {gmean(x[2] for x in r.values()):.2f} | "
                  f"{statistics.fmean(v['bytes'] for v in vs):.0f} | "
                  f"{gmean(v['relMSE'] for v in vs):.3g} | "
                  f"{gmean(x[0] for x in r.values()):.2f} | "
                  f"{gmean(x[1] for x in r.values()):.2f} | "
                  f"{statistics.fmean(v['SSIM'] for v in vs):.3f} | "
                  f"{statistics.fmean(v['detail'] for v in vs):.3f} | "
                  f"{statistics.fmean(v['fireflies'] for v in vs):.1f} | "
                  f"{100 * statistics.fmean(v['energy'] for v in vs):+.1f} % | "
                  f"{statistics.fmean(nb):+.3f} ± {statistics.stdev(nb) if len(nb) > 1 else 0:.3f} |")
        print()

    print(f"### relMSE at equal time × mean, per scene, {spp_shown:g} spp\n")
    print("Below 1: the method beats rendering the mean for as long as the method takes.\n")
    print("| method | " + " | ".join(scenes) + " |")
    print("|---|" + "---|" * len(scenes))
    for m in methods:
        r = ratios(m, spp_shown)
        if not r:
            continue
        print(f"| {m} | " + " | ".join(f"{r[s][0]:.2f}" if s in r else "" for s in scenes) + " |")
    print()

    def per_scene(title, note, cell):
        print(f"### {title} per scene, {spp_shown:g} spp\n")
        if note:
            print(note + "\n")
        print("| method | " + " | ".join(scenes) + " |")
        print("|---|" + "---|" * len(scenes))
        for m in methods:
            cells = [cell(summary[(s, m, spp_shown)]) if (s, m, spp_shown) in summary else ""
                     for s in scenes]
            if any(cells):
                print(f"| {m} | " + " | ".join(cells) + " |")
        print()

    per_scene("relMSE", "Mean over the seeds.", lambda v: f"{v['relMSE']:.3g}")
    per_scene("SSIM", "", lambda v: f"{v['SSIM']:.3f}")
    per_scene("detail", "The slope of the image's 3x3 high pass on the reference's "
              "(docs/metrics.md): 1 keeps all the pixel-scale detail, a blur lowers it; noise "
              "in the reference lowers every method's alike.", lambda v: f"{v['detail']:.3f}")
    per_scene("Firefly pixels", "Per image, mean over the seeds.",
              lambda v: f"{v['fireflies']:.1f}")
    per_scene("Energy", "The light the image holds against the reference's (sum of luminance, "
              "mean over the seeds); nbias below weighs every pixel alike, dark ones too.",
              lambda v: f"{100 * v['energy']:+.1f} %")

    print(f"### nbias (energy) per scene, {spp_shown:g} spp: mean ± standard deviation over the seeds\n")
    print("| method | " + " | ".join(scenes) + " |")
    print("|---|" + "---|" * len(scenes))
    for m in methods:
        cells = []
        for s in scenes:
            v = summary.get((s, m, spp_shown))
            cells.append(f"{v['nbias']:+.3f} ± {v['nbias_sd']:.3f}" if v else "")
        if any(cells):
            print(f"| {m} | " + " | ".join(cells) + " |")
    print()


if __name__ == "__main__":
    main()
