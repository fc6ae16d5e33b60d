#!/usr/bin/env python3
"""Benchmark (not a unit test): calibrate `mcstat --compare` on Blender Cycles renders and
put it next to idiff at Blender's and OSL's regression-test thresholds.

    /usr/bin/python3 tests/compare/calibrate_cycles.py [DATA_DIR [MCSTAT]] [options]

DATA_DIR (default /work/data/cmp) holds one folder per render set, one multilayer EXR per
seed (seed_<s>.exr, 128x128, 64 spp, the caustic scene of tests/aovs/cycles_caustic.py):

    same_a  seeds  1..21  the scene
    same_b  seeds 22..42  the scene, other seeds
    same_c  seeds 43..63  the scene, a third set of seeds (a second null pair)
    key102  seeds 22..42  key light 2 % brighter
    ior145  seeds 22..42  glass IOR 1.45 instead of 1.5 (the caustic moves)

Missing seeds are rendered with tests/aovs/render_cycles_seeds.sh (Blender 3.2+, ~1 s each).

Tables:
  1. false alarms of --compare (test=welch, yuen; each level) over random splits of one
     scene's seeds: same_a's 21 seeds into 10 + 11, and same_a + same_b's 42 into 21 + 21;
  2. detection: the pairs above, 21 + 21 seeds, verdict, pixels and tiles differing, exit status;
  3. idiff on the same pairs (one 64-spp render each, and the means of the 21 renders) at
     Blender's render-test thresholds (8-bit sRGB PNG, idiff -fail 0.016 -failpercent 1) and
     OSL's testsuite defaults (float EXR, idiff -a -fail 0.004 -failpercent 0.02 -hardfail 0.01
     -warn 0.008 -warnpercent 0.02);
  4. idiff's false alarms on the same splits (mean of one half against the mean of the other);
  5. the four side by side.

Needs numpy and the OpenImageIO Python module, and idiff and oiiotool on PATH; no scipy.
"""

import argparse
import concurrent.futures as cf
import hashlib
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

N_SEEDS = 21
RES = (128, 128)
SPP = 64
CHANNELS = ("ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B")

# name, first seed, key-light scale, glass IOR, description
SETS = [
    ("same_a", 1, 1.0, 1.5, "the scene"),
    ("same_b", 22, 1.0, 1.5, "the scene, other seeds"),
    ("same_c", 43, 1.0, 1.5, "the scene, third seeds"),
    ("key102", 22, 1.02, 1.5, "key light x1.02"),
    ("ior145", 22, 1.0, 1.45, "glass IOR 1.45"),
]

# a, b, what differs (the truth)
PAIRS = [
    ("same_a", "same_b", "nothing (other seeds)"),
    ("same_a", "same_c", "nothing (other seeds)"),
    ("same_a", "key102", "key light +2%"),
    ("same_a", "ior145", "IOR 1.45, caustic moves"),
    ("same_b", "key102", "key +2%, SAME seeds"),
    ("same_b", "ior145", "IOR 1.45, SAME seeds"),
]

# Blender: tests/python/modules/render_report.py: idiff -fail 0.016 -failpercent 1 ref.png new.png
# on the 8-bit PNGs Blender writes (-F PNG); idiff's exit status 1 (WARNING) passes, 2 (FAILURE) fails.
BLENDER_ARGS = ["-fail", "0.016", "-failpercent", "1"]
BLENDER_FAIL = 0.016
# OSL: testsuite/runtest.py defaults failthresh 0.004, failpercent 0.02, hardfail 0.01, warn 2 x
# failthresh, warnpercent = failpercent, "-a"; anything but exit status 0 is "NO MATCH".
OSL_ARGS = ["-a", "-fail", "0.004", "-failpercent", "0.02", "-hardfail", "0.01",
            "-warn", "0.008", "-warnpercent", "0.02"]
OSL_FAIL = 0.004

VERDICT_RE = re.compile(r": (SAME|DIFFERENT): ")
COUNTS_RE = re.compile(r"pixels: (\d+) tested of (\d+), (\d+) differ"
                       r"(?:; tiles (\S+): (\d+) tested of (\d+), (\d+) differ)?")
PIXEL_RE = re.compile(r"(?:strongest|largest \|z\|): pixel \((\d+), (\d+)\) [^:]*: (\S+) -> (\S+) "
                      r"\(([^,]+), ([^,]+), (\S+) standard errors\), p = (\S+)")
IDIFF_OVER_RE = re.compile(r"(\d+) pixels \(([^)]*)%\) over (\S+)")
IDIFF_MAX_RE = re.compile(r"Max error\s*=\s*(\S+)")


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def seed_files(data, name, first):
    return [data / name / f"seed_{s}.exr" for s in range(first, first + N_SEEDS)]


def ensure_renders(data, render_script):
    """Render the seeds that are missing from each set folder."""
    for name, first, key, ior, _ in SETS:
        missing = [s for s in range(first, first + N_SEEDS)
                   if not (data / name / f"seed_{s}.exr").is_file()]
        if not missing:
            continue
        log(f"{name}: {len(missing)} of {N_SEEDS} seeds missing, rendering them with {render_script}")
        runs, start, prev = [], missing[0], missing[0]
        for s in missing[1:] + [None]:
            if s is not None and s == prev + 1:
                prev = s
                continue
            runs.append((start, prev - start + 1))
            if s is not None:
                start = prev = s
        for start, count in runs:
            cmd = ["bash", str(render_script), "-n", str(count), "--first", str(start),
                   "-o", str(data / name), "--res", str(RES[0]), str(RES[1]), "--spp", str(SPP),
                   "--key-scale", repr(key), "--ior", repr(ior)]
            log("  " + " ".join(cmd))
            subprocess.run(cmd, check=True, stdout=sys.stderr)


def read_combined(path):
    """The Combined beauty's R, G, B of one render, float32 HxWx3."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise RuntimeError(f"{path}: {oiio.geterror()}")
    spec = inp.spec()
    names = list(spec.channelnames)
    try:
        idx = [names.index(c) for c in CHANNELS]
    except ValueError:
        raise RuntimeError(f"{path}: no {', '.join(CHANNELS)} (channels: {names[:6]}...)")
    lo, hi = min(idx), max(idx) + 1
    px = np.asarray(inp.read_image(0, 0, lo, hi, oiio.FLOAT), dtype=np.float32)
    inp.close()
    if px.shape[:2] != (RES[1], RES[0]):
        raise RuntimeError(f"{path}: {px.shape[1]}x{px.shape[0]}, expected {RES[0]}x{RES[1]}")
    return px[:, :, [i - lo for i in idx]]


def write_exr(path, rgb):
    h, w, _ = rgb.shape
    spec = oiio.ImageSpec(w, h, 3, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B")
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, 3), np.ascontiguousarray(rgb, dtype=np.float32))
    if not buf.write(str(path)):
        raise RuntimeError(f"{path}: {buf.geterror()}")


def run(cmd, ok=(0,)):
    p = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    if p.returncode not in ok:
        raise RuntimeError(f"{' '.join(map(str, cmd))[:400]}: exit status {p.returncode}\n"
                           f"{p.stdout[-2000:]}{p.stderr[-2000:]}")
    return p


def to_png(exr, png):
    """8-bit sRGB, as Blender's render tests compare: clamp, sRGB OETF, round (oiiotool)."""
    run(["oiiotool", exr, "--colorconvert", "linear", "sRGB", "-d", "uint8", "-o", png])


def extract_combined(src, dst):
    run(["oiiotool", src, "--ch", ",".join(f"{c}={n}" for c, n in zip("RGB", CHANNELS)),
         "-d", "float", "-o", dst])


def idiff(a, b, args):
    p = run(["idiff", *args, a, b], ok=(0, 1, 2))
    out = p.stdout + p.stderr
    words = [ln.strip() for ln in out.splitlines() if ln.strip() in ("PASS", "WARNING", "FAILURE")]
    if not words:
        raise RuntimeError(f"idiff {a} {b}: no verdict in\n{out}")
    over = {float(t): int(n) for n, _, t in IDIFF_OVER_RE.findall(out)}
    m = IDIFF_MAX_RE.search(out)
    return {"rc": p.returncode, "verdict": words[-1], "over": over,
            "max": float(m.group(1)) if m else 0.0}


def over(r, thresh):
    return next((n for t, n in r["over"].items() if abs(t - thresh) <= 1e-9 * max(1, thresh)), 0)


def blender_fails(r):
    return r["rc"] == 2        # render_report.py: failed = e.returncode != 1 (WARNING passes)


def osl_fails(r):
    return r["rc"] != 0        # runtest.py: ok only when the idiff command returns 0


def compare(mcstat, a_files, b_files, test, level):
    for f in a_files + b_files:
        if "," in str(f):
            raise RuntimeError(f"{f}: a comma in a path breaks --ingest's file list")
    cmd = [mcstat, "--ingest", ",".join(map(str, a_files)), "--ingest", ",".join(map(str, b_files)),
           f"--compare:test={test}:level={level}"]
    p = run(cmd, ok=(0, 2))
    out = p.stdout
    v = VERDICT_RE.search(out)
    c = COUNTS_RE.search(out)
    if not v or not c:
        raise RuntimeError(f"cannot parse --compare output:\n{out}\n{p.stderr}")
    px = PIXEL_RE.search(out)
    r = {"rc": p.returncode, "verdict": v.group(1),
         "px": int(c.group(3)), "px_tested": int(c.group(1)), "px_all": int(c.group(2)),
         "tile": c.group(4) or "-", "tiles": int(c.group(7) or 0), "tiles_tested": int(c.group(5) or 0),
         "consistent": (v.group(1) == "SAME") == (p.returncode == 0) and
                       (v.group(1) == "DIFFERENT") == (p.returncode == 2),
         "top": None}
    if px:
        r["top"] = {"x": int(px.group(1)), "y": int(px.group(2)), "rel": px.group(6).strip(),
                    "z": float(px.group(7)), "p": px.group(8)}
    return r


def clopper_pearson(k, n, conf=0.95):
    """Exact binomial confidence interval (no scipy: bisection on the binomial tail)."""
    def cdf(x, p):  # P(X <= x)
        if p <= 0:
            return 1.0
        if p >= 1:
            return 1.0 if x >= n else 0.0
        lp, lq = math.log(p), math.log1p(-p)
        return min(1.0, sum(math.exp(math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1)
                                     + i * lp + (n - i) * lq) for i in range(0, x + 1)))

    def solve(f, target):  # f decreasing in p
        lo, hi = 0.0, 1.0
        for _ in range(100):
            mid = (lo + hi) / 2
            if f(mid) > target:
                lo = mid
            else:
                hi = mid
        return (lo + hi) / 2

    a = (1 - conf) / 2
    lower = 0.0 if k == 0 else solve(lambda p: -(1 - cdf(k - 1, p)), -a)
    upper = 1.0 if k == n else solve(lambda p: cdf(k, p), a)
    return lower, upper


def sha256(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()[:16]


def pct(x):
    return f"{100 * x:.1f}%"


def main():
    here = Path(__file__).resolve().parent
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", nargs="?", default="/work/data/cmp", help="data folder (default %(default)s)")
    ap.add_argument("mcstat", nargs="?", default="/work/data/bin/mcstat", help="mcstat binary (default %(default)s)")
    ap.add_argument("--splits", type=int, default=200, help="random splits per pool (default %(default)s)")
    ap.add_argument("--rng-seed", type=int, default=20240917, help="numpy RNG seed of the splits (default %(default)s)")
    ap.add_argument("--levels", default="0.01,0.05", help="--compare levels of table 1 (default %(default)s)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="splits run in parallel (default: cores)")
    ap.add_argument("--render-script", default=str(here.parent / "aovs" / "render_cycles_seeds.sh"))
    args = ap.parse_args()

    data = Path(args.data).resolve()
    mcstat = str(Path(args.mcstat).resolve())
    levels = [float(x) for x in args.levels.split(",") if x]
    tests = ["welch", "yuen"]
    t_start = time.time()

    for tool in ("idiff", "oiiotool"):
        if shutil.which(tool) is None:
            sys.exit(f"calibrate_cycles.py: {tool} not found on PATH")
    if not os.access(mcstat, os.X_OK):
        sys.exit(f"calibrate_cycles.py: {mcstat} is not an executable")
    data.mkdir(parents=True, exist_ok=True)
    ensure_renders(data, Path(args.render_script))

    files = {name: seed_files(data, name, first) for name, first, *_ in SETS}
    log("reading the Combined layers ...")
    combined = {name: np.stack([read_combined(f) for f in fs]) for name, fs in files.items()}

    version = run([mcstat, "--help"]).stdout.splitlines()[0].split(":")[0]
    mcstat_sha = sha256(mcstat)
    oiio_version = run(["oiiotool", "--version"]).stdout.strip()
    tmproot = Path(tempfile.mkdtemp(prefix="calibrate_tmp_", dir=data))
    try:
        print("calibrate_cycles.py: mcstat --compare against idiff on Blender Cycles renders")
        print(f"  data {data}; {version} ({mcstat}, sha256 {mcstat_sha}...); idiff and oiiotool {oiio_version}")
        print(f"  renders: {RES[0]}x{RES[1]}, {SPP} spp, multilayer EXR, beauty {','.join(CHANNELS)}")
        for name, first, key, ior, what in SETS:
            print(f"    {name}: seeds {first}..{first + N_SEEDS - 1}  key x{key:g}  IOR {ior:g}  ({what})")
        print(f"  splits: numpy.random.default_rng({args.rng_seed}), {args.splits} per pool; {args.jobs} in parallel")
        print("  mcstat command: mcstat --ingest A1.exr,A2.exr,... --ingest B1.exr,... --compare:test=T:level=L"
              " (control=fdr, channels=luminance, tile=16)")
        print()

        # ---- the splits (tables 1 and 4) --------------------------------------------------------
        rng = np.random.default_rng(args.rng_seed)
        pools = [("same_a", "21 seeds of same_a", files["same_a"], combined["same_a"], 10),
                 ("same_ab", "42 seeds of same_a+same_b", files["same_a"] + files["same_b"],
                  np.concatenate([combined["same_a"], combined["same_b"]]), 21)]
        jobs = []
        for pid, _, fs, _, na in pools:
            for i in range(args.splits):
                perm = rng.permutation(len(fs))
                jobs.append((pid, i, sorted(perm[:na].tolist()), sorted(perm[na:].tolist())))
        pool_by_id = {p[0]: p for p in pools}

        def split_task(job):
            pid, i, ia, ib = job
            _, _, fs, comb, _ = pool_by_id[pid]
            fa, fb = [fs[k] for k in ia], [fs[k] for k in ib]
            res = {(t, lv): compare(mcstat, fa, fb, t, lv) for lv in levels for t in tests}
            tmp = Path(tempfile.mkdtemp(dir=tmproot))
            try:
                ea, eb, pa, pb = tmp / "a.exr", tmp / "b.exr", tmp / "a.png", tmp / "b.png"
                write_exr(ea, comb[ia].astype(np.float64).mean(axis=0))
                write_exr(eb, comb[ib].astype(np.float64).mean(axis=0))
                to_png(ea, pa)
                to_png(eb, pb)
                res["blender"] = idiff(pa, pb, BLENDER_ARGS)
                res["osl"] = idiff(ea, eb, OSL_ARGS)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
            return job, res

        log(f"running {len(jobs)} splits x {len(tests) * len(levels)} compares + idiff ...")
        results = {p[0]: [] for p in pools}
        done, lock, t0 = 0, threading.Lock(), time.time()
        with cf.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as ex:
            for job, res in ex.map(split_task, jobs):
                results[job[0]].append((job, res))
                with lock:
                    done += 1
                    if done % 25 == 0 or done == len(jobs):
                        el = time.time() - t0
                        log(f"  {done}/{len(jobs)} splits, {el:.0f} s, ~{el / done * (len(jobs) - done):.0f} s left")
        t_splits = time.time() - t0

        inconsistent = sum(1 for rs in results.values() for _, r in rs
                           for k, v in r.items() if isinstance(k, tuple) and not v["consistent"])

        print(f"1. False alarms of --compare: DIFFERENT on two halves of one scene's renders "
              f"({args.splits} random splits per pool)")
        for pid, desc, fs, _, na in pools:
            j0 = results[pid][0][0]
            print(f"   pool {pid}: {desc}, split {na} + {len(fs) - na}; first split: "
                  f"A = seeds {','.join(fs[k].stem[5:] for k in j0[2])}")
        print()
        hdr = (f"   {'pool':<8} {'split':<6} {'test':<6} {'level':>5}  {'DIFFERENT':>9}  {'rate':>6}  "
               f"{'95% CI (Clopper-Pearson)':<24}  {'nominal':>7}  {'false alarms: pixels, tiles differing':<38}")
        print(hdr)
        print("   " + "-" * (len(hdr) - 3))
        fa_summary = {}
        for pid, _, fs, _, na in pools:
            for lv in levels:
                for t in tests:
                    rs = [r[(t, lv)] for _, r in results[pid]]
                    k = sum(r["verdict"] == "DIFFERENT" for r in rs)
                    n = len(rs)
                    lo, hi = clopper_pearson(k, n)
                    fa_summary[(pid, t, lv)] = (k, n)
                    alarms = [f"{r['px']}px/{r['tiles']}t" for r in rs if r["verdict"] == "DIFFERENT"]
                    shown = ", ".join(alarms[:6]) + (", ..." if len(alarms) > 6 else "")
                    print(f"   {pid:<8} {f'{na}+{len(fs) - na}':<6} {t:<6} {lv:>5g}  {f'{k}/{n}':>9}  "
                          f"{pct(k / n):>6}  [{pct(lo):>5}, {pct(hi):>5}]{'':<11}  {f'<= {lv:g}':>7}  "
                          f"{shown or '-'}")
        top_p = {}
        for pid, *_ in pools:
            for t in tests:
                ps = [float(r[(t, levels[0])]["top"]["p"]) for _, r in results[pid]
                      if r[(t, levels[0])]["top"]]
                top_p[(pid, t)] = ps
        print("   smallest pixel p-value per split (median; 5th percentile):  " + "; ".join(
            f"{pid} {t}: {np.median(ps):.2g}; {np.percentile(ps, 5):.2g}" for (pid, t), ps in top_p.items() if ps))
        print(f"   verdict and exit status agree in every run: {'yes' if inconsistent == 0 else f'NO ({inconsistent} runs)'}")
        print("   (the splits re-use the same renders, so they are not independent: the interval is optimistic)")
        print()

        # ---- table 2: detection --------------------------------------------------------------
        log("detection ...")
        det = {}
        print("2. Detection: all 21 + 21 seeds of each pair, --compare:test=T:level=0.01 (FDR, luminance, 16x16 tiles);")
        print("   ingested from the seed folders (mcstat --ingest <21 files> --ingest <21 files>), not from any .mcstat file")
        hdr = (f"   {'A vs B':<17} {'truth':<24} {'test':<6} {'verdict':<9} {'pixels differ':>14} "
               f"{'tiles differ':>12} {'exit':>4}  {'strongest / largest-|z| pixel':<40}")
        print(hdr)
        print("   " + "-" * (len(hdr) - 3))
        for a, b, truth in PAIRS:
            for t in tests:
                r = compare(mcstat, files[a], files[b], t, 0.01)
                det[(a, b, t)] = r
                top = r["top"]
                tops = (f"({top['x']},{top['y']}) {top['rel']}, z {top['z']:+.1f}, p {top['p']}" if top else "-")
                pxs = "%d/%d" % (r["px"], r["px_tested"])
                tls = "%d/%d" % (r["tiles"], r["tiles_tested"])
                bad = "" if r["consistent"] else "  (verdict/exit status MISMATCH)"
                print(f"   {a + ' vs ' + b:<17} {truth:<24} {t:<6} {r['verdict']:<9} "
                      f"{pxs:>14} {tls:>12} {r['rc']:>4}  {tops}{bad}")
        print()

        # ---- table 3: idiff on the pairs ----------------------------------------------------------
        log("idiff on the pairs ...")
        work = tmproot / "pairs"
        work.mkdir()
        single, mean = {}, {}
        for name, *_ in SETS:
            e = work / f"{name}_1.exr"
            extract_combined(files[name][0], e)
            to_png(e, work / f"{name}_1.png")
            single[name] = e
            full = work / f"{name}_meanfull.exr"
            run([mcstat, "--ingest", ",".join(map(str, files[name])), "--mean", "-o", full])
            m = work / f"{name}_mean.exr"
            extract_combined(full, m)
            to_png(m, work / f"{name}_mean.png")
            mean[name] = m
        # checks: the conversions are what they claim
        chk_mean = max(float(np.max(np.abs(np.asarray(oiio.ImageBuf(str(mean[n])).get_pixels(oiio.FLOAT))
                                           - combined[n].astype(np.float64).mean(axis=0))))
                       for n in mean)
        lin = np.asarray(oiio.ImageBuf(str(single["same_a"])).get_pixels(oiio.FLOAT), dtype=np.float64)
        png = np.asarray(oiio.ImageBuf(str(work / "same_a_1.png")).get_pixels(oiio.UINT8), dtype=np.int64)
        x = np.clip(lin, 0, 1)
        ref = np.floor(255 * np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055) + 0.5)
        lsb = np.abs(png - ref)
        chk_first = float(np.max(np.abs(lin - combined["same_a"][0])))

        print("3. idiff on the same pairs")
        print("   Blender: Combined RGB -> 8-bit sRGB PNG (oiiotool X.exr --colorconvert linear sRGB -d uint8: clamp to [0,1],")
        print("            sRGB OETF, round; no alpha, no dither, 'Standard' view), then idiff -fail 0.016 -failpercent 1;")
        print("            the test fails on FAILURE (exit 2); WARNING (exit 1) passes")
        print("   OSL:     Combined RGB as float EXR, idiff -a -fail 0.004 -failpercent 0.02 -hardfail 0.01 -warn 0.008 "
              "-warnpercent 0.02;")
        print("            anything but PASS (exit 0) fails")
        print(f"   1 render = seed_<first> of each set (oiiotool --ch R=ViewLayer.Combined.R,...); mean of 21 = "
              f"mcstat --ingest <21 files> --mean -o, then --ch")
        print(f"   checks: oiiotool's sRGB PNG vs the IEC 61966-2-1 formula: {int((lsb > 0).sum())} of {lsb.size} values "
              f"differ, by at most {int(lsb.max())} LSB; mcstat --mean vs numpy mean: max |diff| {chk_mean:.2g}; "
              f"extracted vs read Combined: {chk_first:.2g}")
        npx = RES[0] * RES[1]
        print(f"   limits: Blender fails above {0.01 * npx:.1f} pixels (1%) over 0.016; OSL above {0.0002 * npx:.2f} "
              f"pixels (0.02%) over 0.004, or any pixel over 0.01")
        hdr = (f"   {'A vs B':<17} {'truth':<24} {'images':<9} | {'Blender':<8} {'px>0.016':>15} {'max err':>8} "
               f"{'fails':>5} | {'OSL':<8} {'px>0.004':>15} {'max err':>9} {'fails':>5}")
        print(hdr)
        print("   " + "-" * (len(hdr) - 3))
        pair_idiff = {}
        for a, b, truth in PAIRS:
            for kind, imgs in (("1 render", single), ("mean 21", mean)):
                rb = idiff(imgs[a].with_suffix(".png"), imgs[b].with_suffix(".png"), BLENDER_ARGS)
                ro = idiff(imgs[a], imgs[b], OSL_ARGS)
                pair_idiff[(a, b, kind)] = (rb, ro)
                nb, no = over(rb, BLENDER_FAIL), over(ro, OSL_FAIL)
                print(f"   {a + ' vs ' + b:<17} {truth:<24} {kind:<9} | {rb['verdict']:<8} "
                      f"{f'{nb} ({pct(nb / npx)})':>15} {rb['max']:>8.4f} {'yes' if blender_fails(rb) else 'no':>5} | "
                      f"{ro['verdict']:<8} {f'{no} ({pct(no / npx)})':>15} {ro['max']:>9.4g} "
                      f"{'yes' if osl_fails(ro) else 'no':>5}")
        print(f"   (seeds: same_a {SETS[0][1]}, same_b/key102/ior145 22, same_c 43; SAME-seed rows pair seed 22 with seed 22)")
        print()

        # ---- table 4: idiff on the splits ---------------------------------------------------------
        print("4. idiff's false alarms on the same splits (mean of one half against the mean of the other, numpy means)")
        hdr = (f"   {'pool':<8} {'split':<6} {'thresholds':<10} {'PASS':>5} {'WARNING':>8} {'FAILURE':>8}  "
               f"{'test fails':>10} {'rate':>7}  {'px over fail threshold: median [min, max]':<42} {'max err median':>14}")
        print(hdr)
        print("   " + "-" * (len(hdr) - 3))
        idiff_fa = {}
        for pid, _, fs, _, na in pools:
            for key, thr, fails in (("blender", BLENDER_FAIL, blender_fails), ("osl", OSL_FAIL, osl_fails)):
                rs = [r[key] for _, r in results[pid]]
                cnt = {w: sum(r["verdict"] == w for r in rs) for w in ("PASS", "WARNING", "FAILURE")}
                k = sum(fails(r) for r in rs)
                idiff_fa[(pid, key)] = (k, len(rs))
                ov = [over(r, thr) for r in rs]
                print(f"   {pid:<8} {f'{na}+{len(fs) - na}':<6} {key:<10} {cnt['PASS']:>5} {cnt['WARNING']:>8} "
                      f"{cnt['FAILURE']:>8}  {f'{k}/{len(rs)}':>10} {pct(k / len(rs)):>7}  "
                      f"{f'{np.median(ov):.0f} [{min(ov)}, {max(ov)}] of {npx}':<42} "
                      f"{np.median([r['max'] for r in rs]):>14.4g}")
        print()

        # ---- table 5: side by side ---------------------------------------------------------------
        print("5. Side by side: false-alarm rate on the splits, and the verdict on the 21 + 21 pairs (level 0.01)")
        cols = ["mcstat welch", "mcstat yuen", "idiff Blender", "idiff OSL"]
        print(f"   {'':<44} " + " ".join(f"{c:>14}" for c in cols))
        for pid, _, fs, _, na in pools:
            vals = [fa_summary[(pid, "welch", 0.01)] if 0.01 in levels else None,
                    fa_summary[(pid, "yuen", 0.01)] if 0.01 in levels else None,
                    idiff_fa[(pid, "blender")], idiff_fa[(pid, "osl")]]
            print(f"   {'false alarms ' + pid + ' ' + f'{na}+{len(fs) - na}':<44} " +
                  " ".join(f"{(pct(v[0] / v[1]) if v else '-'):>14}" for v in vals))
        for a, b, truth in PAIRS:
            rb, ro = pair_idiff[(a, b, "mean 21")]
            vals = [det[(a, b, "welch")]["verdict"], det[(a, b, "yuen")]["verdict"],
                    "DIFFERENT" if blender_fails(rb) else "same", "DIFFERENT" if osl_fails(ro) else "same"]
            print(f"   {a + ' vs ' + b + ' (' + truth + ')':<44} " + " ".join(f"{v:>14}" for v in vals))
        print("   (idiff columns of the pairs: means of the 21 renders; 'same' = the test passes)")
        print()
        total = time.time() - t_start
        print(f"time: {total:.0f} s in all ({t_splits:.0f} s for the {len(jobs)} splits)")
        if sha256(mcstat) != mcstat_sha:
            print(f"WARNING: {mcstat} changed while this ran (sha256 now {sha256(mcstat)}...): the tables mix two builds")
    finally:
        shutil.rmtree(tmproot, ignore_errors=True)


if __name__ == "__main__":
    main()
