#!/usr/bin/env python3
"""scripts/keep_light_tables.py KEEP_LIGHT_CSV: the tables of docs/keep-light.md ("Measured") from
one run of scripts/keep_light_table.sh (one row per scene, spp, seed and method).

The first table holds the means over the seeds. The second holds issue 49's goals with their
power: each figure is the mean over the seeds of a per-seed value, with its 95 % Student t
interval over the seeds (each seed is its own render: independent). A goal is met when the
whole interval meets it, missed when none of it does, and undecided otherwise: the seeds cannot
tell.

The goals: on the firefly scenes, relMSE at most 1.0x G-MoN's, firefly pixels at most G-MoN's
plus one, energy within 1 % of the reference; on the smooth scenes, relMSE at most 1.05x the
plain mean's.
"""

import collections
import csv
import math
import sys

from scipy.stats import t as student_t

FIREFLY_SCENES = {"default", "caustic", "tiny", "arealight"}
KEEPLIGHT = "gmon:keeplight=1"


def interval(xs):
    """The mean of xs and its 95 % t interval; NaN bounds for one value."""
    m = sum(xs) / len(xs)
    if len(xs) < 2:
        return m, math.nan, math.nan
    sd = math.sqrt(sum((x - m) ** 2 for x in xs) / (len(xs) - 1))
    h = student_t.ppf(0.975, len(xs) - 1) * sd / math.sqrt(len(xs))
    return m, m - h, m + h


def verdict(lo, hi, goal_lo, goal_hi):
    if math.isnan(lo):
        return "one seed"
    if goal_lo <= lo and hi <= goal_hi:
        return "met"
    if hi < goal_lo or lo > goal_hi:
        return "missed"
    return "undecided"


def cell(m, lo, hi, unit=""):
    return "%.2f%s [%.2f, %.2f]" % (m, unit, lo, hi)


def main(path):
    rows = list(csv.DictReader(open(path)))
    g = collections.defaultdict(list)
    for r in rows:
        g[(r["scene"], int(r["spp"]), r["method"])].append(r)

    def mean(rs, k):
        return sum(float(r[k]) for r in rs) / len(rs)

    print("| scene | spp | method | relMSE | vs G-MoN | vs mean | energy (mean of seeds) | fireflies | SSIM |")
    print("|---|---|---|---|---|---|---|---|---|")
    for (scene, spp, method), rs in sorted(g.items()):
        gm = mean(g[(scene, spp, "gmon")], "relMSE")
        mm = mean(g[(scene, spp, "mean")], "relMSE")
        rel = mean(rs, "relMSE")
        print("| %s | %d | %s | %.4g | %.2fx | %.2fx | %+.2f %% | %.1f | %.4f |" % (
            scene, spp, method, rel, rel / gm, rel / mm, 100 * mean(rs, "energy"),
            mean(rs, "fireflies"), mean(rs, "SSIM")))

    print()
    print("| scene | spp | seeds | relMSE ratio | goal | firefly pixels over G-MoN's | goal | energy % | goal |")
    print("|---|---|---|---|---|---|---|---|---|")
    for scene, spp in sorted({(k[0], k[1]) for k in g if k[2] == KEEPLIGHT}):
        firefly = scene in FIREFLY_SCENES
        by_seed = lambda method: {r["seed"]: r for r in g[(scene, spp, method)]}
        kl, gmon, plain = by_seed(KEEPLIGHT), by_seed("gmon"), by_seed("mean")
        base = gmon if firefly else plain
        seeds = sorted(set(kl) & set(base) & set(gmon), key=int)
        if not seeds:
            continue
        ratio = interval([float(kl[s]["relMSE"]) / float(base[s]["relMSE"]) for s in seeds])
        cells = [cell(*ratio, "x"), verdict(ratio[1], ratio[2], -math.inf, 1.0 if firefly else 1.05)]
        if firefly:
            ff = interval([float(kl[s]["fireflies"]) - float(gmon[s]["fireflies"]) for s in seeds])
            energy = interval([100 * float(kl[s]["energy"]) for s in seeds])
            cells += [cell(*ff), verdict(ff[1], ff[2], -math.inf, 1.0),
                      cell(*energy), verdict(energy[1], energy[2], -1.0, 1.0)]
        else:
            cells += ["", "", "", ""]
        print("| %s | %d | %d | %s |" % (scene, spp, len(seeds), " | ".join(cells)))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: keep_light_tables.py KEEP_LIGHT_CSV")
    main(sys.argv[1])
