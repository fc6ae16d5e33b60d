"""The trade's scripts (docs/trade.md): scripts/trade_tables.py's ratios against hand-computed values,
and scripts/trade.sh run small with ONLY (the rows it writes, the detail column)."""

import csv
import subprocess
import sys

import pytest

from conftest import BUILD, SOURCE, tool_env

TABLES = SOURCE / "scripts" / "trade_tables.py"
HEADER = "scene,method,spp,seed,seconds,bytesPerPixel,relMSE,SSIM,PSNR,fireflies,pixels,nbias,nnoise"


def tables(path, spp):
    p = subprocess.run([sys.executable, str(TABLES), str(path), str(spp)], capture_output=True,
                       text=True)
    assert p.returncode == 0, p.stderr
    return p.stdout


def section(text, title):
    """The markdown table rows under the heading that starts with `title`: {method: [cells]}."""
    lines = text.splitlines()
    start = next(i for i, l in enumerate(lines) if l.startswith("### " + title))
    rows = {}
    for l in lines[start + 1:]:
        if l.startswith("###"):
            break
        if l.startswith("| ") and not l.startswith("| method"):
            cells = [c.strip() for c in l.strip("|").split("|")]
            rows[cells[0]] = cells[1:]
    return rows


def test_equal_time_ratio_and_detail_hand_computed(tmp_path):
    # The mean: relMSE 0.4 in 1 s, 0.1 in 4 s: log-log linear between, so 0.2 at 2 s.
    # G-MoN at 16 spp: relMSE 0.1 in 2 s -> 0.1 / 0.2 = 0.50 of the mean at equal time; its two
    # seeds' detail 0.9 and 0.7 -> 0.800. Efficiency against the mean at 16 spp:
    # (0.4 x 1) / (0.1 x 2) = 2.00.
    t = tmp_path / "trade.csv"
    t.write_text(HEADER + ",detail,energy\n"
                 "s,reference,4096,0,0,0,0.001,0.99,40,0,100,0,0,0.98,0.001\n"
                 "s,mean,16,1,1,4,0.4,0.5,20,3,100,0.1,1,1.0,0.02\n"
                 "s,mean,16,2,1,4,0.4,0.5,20,3,100,0.1,1,1.0,0.0\n"
                 "s,mean,64,1,4,4,0.1,0.7,25,1,100,0.0,0.5,1.0,0.0\n"
                 "s,mean,64,2,4,4,0.1,0.7,25,1,100,0.0,0.5,1.0,0.0\n"
                 "s,G-MoN,16,1,2,40,0.1,0.8,30,0,100,-0.2,0.1,0.9,-0.3\n"
                 "s,G-MoN,16,2,2,40,0.1,0.8,30,0,100,-0.2,0.1,0.7,-0.2\n")
    out = tables(t, 16)
    assert section(out, "relMSE at equal time × mean, per scene, 16 spp")["G-MoN"] == ["0.50"]
    pooled = section(out, "Every scene pooled, 16 spp")["G-MoN"]
    # time × mean, bytes/px, relMSE, equal time, efficiency, SSIM, detail, fireflies, energy, nbias
    assert pooled[0] == "2.00" and pooled[3] == "0.50" and pooled[4] == "2.00"
    assert pooled[6] == "0.800" and pooled[8] == "-25.0 %"
    assert section(out, "Energy per scene, 16 spp")["G-MoN"] == ["-25.0 %"]
    assert section(out, "detail per scene, 16 spp")["G-MoN"] == ["0.800"]
    assert section(out, "relMSE per scene, 16 spp")["G-MoN"] == ["0.1"]


def test_tables_of_a_run_before_the_detail_column(tmp_path):
    # docs/trade.csv of earlier runs has no detail column: the tables still come, detail says nan.
    t = tmp_path / "old.csv"
    t.write_text(HEADER + "\n"
                 "s,mean,16,1,1,4,0.4,0.5,20,3,100,0.1,1\n"
                 "s,mean,64,1,4,4,0.1,0.7,25,1,100,0.0,0.5\n"
                 "s,G-MoN,16,1,2,40,0.1,0.8,30,0,100,-0.2,0.1\n")
    out = tables(t, 16)
    assert section(out, "detail per scene, 16 spp")["G-MoN"] == ["nan"]
    assert section(out, "relMSE at equal time × mean, per scene, 16 spp")["G-MoN"] == ["0.50"]


def test_trade_script_runs_only_the_methods_asked(tmp_path):
    # The whole script, small: one scene, one seed, 32 x 24; ONLY picks two methods besides the mean.
    out = tmp_path / "trade"
    env = tool_env(SKIP_BUILD="1", BUILD=str(BUILD), SCENES="detail", RES="32 24",
               SPPS="4", SEEDS="1", REF_SPP="64", REF_SPP_SCENES="", MEAN_SPPS="8",
               ONLY="G-MoN keeplight,median 3x3 (oiiotool)", OUT=str(out))
    p = subprocess.run(["bash", str(SOURCE / "scripts" / "trade.sh")], env=env,
                       capture_output=True, text=True, timeout=240)
    assert p.returncode == 0, p.stderr[-2000:]
    rows = list(csv.DictReader(open(out / "trade.csv", newline="")))
    methods = [(r["method"], r["spp"]) for r in rows]
    assert methods == [("reference", "64"), ("mean", "4"), ("G-MoN keeplight", "4"),
                       ("median 3x3 (oiiotool)", "4"), ("mean", "8")]
    for r in rows:
        assert r["pixels"] == "768"
        # every --diff metric made it into its column, detail included
        for k in ("relMSE", "SSIM", "nbias", "detail", "energy"):
            float(r[k])
        assert r["detail"] != "" and r["energy"] != ""
    # the tables and the plots came too
    assert "### detail per scene" in p.stdout
    assert (out / "trade-detail-time.png").stat().st_size > 0


def test_trade_on_cycles_renders_runs_every_method_and_the_clamp(tmp_path):
    # scripts/trade_cycles.sh small: 3 Cycles seeds of 4 spp at 32 x 24 with and without Cycles'
    # clamp, a reference of 2 x 16 spp, the mean at 2 x the set's samples. Blender is a dependency
    # (scripts/install-deps.sh); the suite fails, not skips, without it.
    out = tmp_path / "cycles"
    env = tool_env(SKIP_BUILD="1", BUILD=str(BUILD), SCENES="detail=160", RES="32 24",
               SPP="4", SEEDS="3", SETS="1", REF="2 16", MEAN_FACTORS="2", CLAMP="0.5",
               ONLY="G-MoN keeplight,median 3x3 (oiiotool),clamp 0.5 (Cycles)", OUT=str(out))
    p = subprocess.run(["bash", str(SOURCE / "scripts" / "trade_cycles.sh")], env=env,
                       capture_output=True, text=True, timeout=240)
    assert p.returncode == 0, p.stderr[-2000:]
    rows = list(csv.DictReader(open(out / "trade.csv", newline="")))
    assert [(r["scene"], r["method"], r["spp"]) for r in rows] == [
        ("cycles-detail", "reference", "32"), ("cycles-detail", "mean", "12"),
        ("cycles-detail", "G-MoN keeplight", "12"), ("cycles-detail", "median 3x3 (oiiotool)", "12"),
        ("cycles-detail", "clamp 0.5 (Cycles)", "12"), ("cycles-detail", "mean", "24")]
    for r in rows[1:]:
        assert float(r["seconds"]) > 0 and float(r["bytesPerPixel"]) > 0
        assert r["pixels"] == "768"
    # Cycles' clamp took effect. The clamped seeds trace the same paths (same seeds; the clamp
    # changes no random number), each indirect sample at most what it was: less light, surely.
    clamped = [r for r in rows if r["method"] == "clamp 0.5 (Cycles)"][0]
    assert float(clamped["nbias"]) < float(rows[1]["nbias"])


@pytest.mark.parametrize("script", ["trade.sh", "trade_cycles.sh"])
def test_trade_refuses_a_folder_it_did_not_make(tmp_path, script):
    # OUT is the trade's own (it writes trade.csv, renders and pictures there by name): a user's
    # folder holding files is refused before anything is written, and its files stay as they were.
    out = tmp_path / "project"
    out.mkdir()
    (out / "trade.csv").write_text("mine\n")
    env = tool_env(SKIP_BUILD="1", BUILD=str(BUILD), OUT=str(out))
    p = subprocess.run(["bash", str(SOURCE / "scripts" / script)], env=env, capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 1
    assert "is not a trade's folder" in p.stderr and str(out) in p.stderr
    assert (out / "trade.csv").read_text() == "mine\n"
    assert sorted(x.name for x in out.iterdir()) == ["trade.csv"]
