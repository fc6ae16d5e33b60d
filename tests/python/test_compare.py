"""mcstat.compare against `mcstat A B --compare`: the README's pairs (same scene, other seeds:
the same image; the light 2 % brighter: different), verdicts, counts and maps."""

import subprocess

import numpy as np
import pytest

import mcstat
from conftest import CLI, RENDER, SOURCE, read_exr, run

RES = (128, 96)  # 2 % more light shows in a few pixels and a tile at 256 spp


@pytest.fixture(scope="module")
def pair(tmp):
    """The README's three renders (smaller), side by side: other seeds, and the light 2 % brighter."""
    light = SOURCE / "render-fixture/examples/default-light-1.02.json"
    jobs = [(tmp / "a.mcstat", "default", 11), (tmp / "b.mcstat", "default", 12),
            (tmp / "light.mcstat", light, 12)]
    procs = [subprocess.Popen([str(RENDER), "--scene", str(scene), "--res", str(RES[0]),
                               str(RES[1]), "--spp", "256", "--M", "16", "--seed", str(seed),
                               "--quiet", "-o", str(path)]) for path, scene, seed in jobs]
    assert all(p.wait() == 0 for p in procs)
    return tuple(path for path, _, _ in jobs)


def cli_compare(tmp, a, b, mods=""):
    out = tmp / "maps.exr"
    p = run(CLI, a, b, "--compare" + mods, "-o", out, check=False)
    assert p.returncode in (0, 2), p.stderr
    return p, read_exr(out)


@pytest.mark.parametrize("test", ["welch", "yuen"])
def test_same_scene_other_seeds_agree(pair, tmp, test):
    a, b, _ = pair
    r = mcstat.compare(a, b, test=test)
    p, maps = cli_compare(tmp, a, b, ":test=" + test)
    assert p.returncode == 0 and r.exit_code == 0 and not r.fail and r
    assert p.stdout.splitlines()[0] == "{} vs {}: {}".format(a, b, r.verdict)
    assert r.verdict.startswith("SAME")
    assert [l.strip() for l in p.stdout.splitlines()[1:]] == r.evidence
    assert r.pixels == RES[0] * RES[1] and r.pixels_differing == 0
    assert sorted(r.maps) == sorted(maps)
    for name, m in r.maps.items():
        np.testing.assert_array_equal(m, maps[name], err_msg=name)


def test_brighter_light_differs(pair, tmp):
    a, _, light = pair
    r = mcstat.compare(mcstat.read(a), light)
    p, maps = cli_compare(tmp, a, light)
    assert p.returncode == 2 and r.exit_code == 2 and r.fail
    assert r.verdict.startswith("DIFFERENT") and p.stdout.startswith("{} vs {}: {}".format(
        a, light, r.verdict))
    assert r.pixels_differing + r.tiles_differing > 0
    assert r.strongest["quantity"] == "luminance" and r.strongest["z"] > 0  # brighter
    for name, m in r.maps.items():
        np.testing.assert_array_equal(m, maps[name], err_msg=name)


def test_power_minpower_and_identical(pair):
    """A SAME verdict states the change it would have found; minpower holds it to a size;
    identical="fail" makes a file compared with itself fail (for CI)."""
    a, b, _ = pair
    r = mcstat.compare(a, b)
    assert r.verdict.startswith("SAME") and "with probability 0.8" in r.verdict
    assert r.power["probability"] == 0.8
    assert 0 < r.power["tile_relative"] < r.power["pixel_relative"]
    assert r.power["tile_absolute"] > 0 and not r.underpowered
    weak = mcstat.compare(a, b, minpower=r.power["tile_relative"] / 2)
    assert weak.fail and weak.underpowered and weak.exit_code == 2
    assert weak.verdict.startswith("UNDERPOWERED")
    strong = mcstat.compare(a, b, minpower=r.power["tile_relative"] * 2)
    assert not strong.fail and strong.exit_code == 0
    assert mcstat.compare(a, a).exit_code == 0
    same = mcstat.compare(a, a, identical="fail")
    assert same.identical and same.fail and same.exit_code == 2
    assert same.verdict.startswith("IDENTICAL")
