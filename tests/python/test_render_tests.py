"""Render tests (docs/compare.md, "Reports for CI" and "Render tests in pytest"): --compare's JUnit
read back by a JUnit consumer's parser (junitparser, as CI plugins read it) and by the structure
Jenkins and GitLab read, its JSON parsed back, its report page opened in a real headless browser
(Debian's chromium), Mitsuba 3's reference rule from the command line, and
mcstat.testing.assert_same_render passing one scene's seeds and failing the light 2 % brighter."""

import json
import os
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import OpenImageIO as oiio
import pytest
from junitparser import Failure, JUnitXml

import mcstat
from mcstat.testing import assert_same_render, report_dir_for
from conftest import CLI, RENDER, SOURCE, read_exr, run

RES = (32, 24)  # the render-test scenes' size
SCENES = SOURCE / "tests/render-test/scenes"


@pytest.fixture(scope="module")
def pair(tmp):
    """One scene with two seeds, and its light 2 % brighter (seen directly: an exact change)."""
    jobs = [(tmp / "a.mcstat", SCENES / "box.json", 11), (tmp / "b.mcstat", SCENES / "box.json", 12),
            (tmp / "light.mcstat", SCENES / "box-light-1.02.json", 12)]
    procs = [subprocess.Popen([str(RENDER), "--scene", str(scene), "--spp", "64", "--M", "8",
                               "--seed", str(seed), "--quiet", "-o", str(path)])
             for path, scene, seed in jobs]
    assert all(p.wait() == 0 for p in procs)
    return tuple(path for path, _, _ in jobs)


def cli_reports(tmp, a, b, name, mods=""):
    d = tmp / name
    d.mkdir()
    p = run(CLI, a, b, "--compare:junit={0}/junit.xml:json={0}/report.json:html={0}/page{1}"
            .format(d, mods), check=False)
    return p, d


def check_junit(path, failures, verdict):
    """The file as a JUnit consumer reads it (junitparser), and the structure Jenkins' and
    GitLab's importers read: testsuites > testsuite > testcase [> failure], the counts agreeing."""
    xml = JUnitXml.fromfile(str(path))
    suites = list(xml)
    assert len(suites) == 1
    suite = suites[0]
    assert (suite.tests, suite.failures, suite.errors, suite.skipped) == (1, failures, 0, 0)
    cases = list(suite)
    assert len(cases) == 1
    assert (cases[0].classname, cases[0].is_passed) == ("mcstat.compare", failures == 0)
    if failures:
        assert isinstance(cases[0].result[0], Failure)
        assert cases[0].result[0].message == verdict
    root = ET.parse(str(path)).getroot()
    assert root.tag == "testsuites" and root.get("tests") == "1"
    assert root.get("failures") == str(failures)
    assert [c.tag for c in root] == ["testsuite"]
    assert len(root.findall("testsuite/testcase/failure")) == failures
    assert float(root.find("testsuite").get("time")) >= 0.0
    return suite


def test_cli_reports_of_a_difference(pair, tmp):
    a, _, light = pair
    p, d = cli_reports(tmp, a, light, "cli-light")
    assert p.returncode == 2, p.stderr
    verdict = p.stdout.splitlines()[0].split(": ", 1)[1]
    assert verdict.startswith("DIFFERENT")
    report = json.loads((d / "report.json").read_text())
    assert (report["verdict"], report["exit_code"], report["fail"]) == ("DIFFERENT", 2, True)
    assert report["verdict_line"] == verdict
    assert report["test"]["test"] == "welch" and report["test"]["level"] == 0.01
    counts = re.search(r"pixels: (\d+) tested of (\d+), (\d+) differ; tiles 16x16: (\d+) tested "
                       r"of (\d+), (\d+) differ", p.stdout).groups()
    assert [str(report["pixels"][k]) for k in ("tested", "total", "differing")] == list(counts[:3])
    assert [str(report["tiles"][k]) for k in ("tested", "total", "differing")] == list(counts[3:])
    s = report["strongest_pixel"]
    assert "strongest: pixel ({}, {}) luminance".format(s["x"], s["y"]) in p.stdout
    assert s["b"] > s["a"] and s["effect"] > 0  # brighter
    assert report["inputs"]["a"]["files"] == [str(a)]
    assert report["inputs"]["b"]["name"] == str(light)
    suite = check_junit(d / "junit.xml", 1, verdict)
    props = {pr.name: pr.value for pr in suite.properties()}
    assert props["pixels.differing"] == str(report["pixels"]["differing"])
    assert sorted(os.listdir(d / "page")) == ["a.png", "b.png", "heatmap.png", "index.html"]
    assert not [f for f in os.listdir(d) if ".tmp-" in f]  # written by rename


def test_cli_reports_of_the_same_scene_and_a_bad_input(pair, tmp):
    a, b, _ = pair
    p, d = cli_reports(tmp, a, b, "cli-same", ":name=scene <default> & co")
    assert p.returncode == 0, p.stderr
    check_junit(d / "junit.xml", 0, None)
    report = json.loads((d / "report.json").read_text())
    assert (report["verdict"], report["name"]) == ("SAME", "scene <default> & co")
    assert report["pixels"]["differing"] == 0 and report["tiles"]["differing"] == 0
    # A report into a folder that is a file: one line naming it, exit 1.
    p = run(CLI, a, b, "--compare:json={}/report.json/x".format(d), check=False)
    assert p.returncode == 1 and "report.json/x" in p.stderr, p.stderr


def chromium_dom(page):
    """The page's DOM after load in Debian's headless chromium (about 1 s)."""
    p = subprocess.run(["chromium", "--headless", "--disable-gpu", "--no-sandbox",
                        "--allow-file-access-from-files", "--virtual-time-budget=3000",
                        "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    return p.stdout


def test_report_page_in_a_real_browser(pair, tmp):
    a, _, light = pair
    _, d = cli_reports(tmp, a, light, "browser")
    page = d / "page" / "index.html"
    dom = chromium_dom(page)
    assert 'data-ready="1"' in dom, dom[:2000]
    assert 'data-images="4 of 4 loaded"' in dom
    assert "data-errors" not in dom
    assert "DIFFERENT" in dom and 'id="flip"' in dom
    # The check can fail: a missing picture and a script error show.
    broken = d / "broken"
    shutil.copytree(d / "page", broken)
    (broken / "a.png").unlink()
    html = (broken / "index.html").read_text()
    (broken / "index.html").write_text(html.replace("</body>", "<script>noSuchFunction();</script></body>"))
    dom = chromium_dom(broken / "index.html")
    assert 'data-images="3 of 4 loaded"' in dom  # the flip shows B; A's own picture is gone
    assert 'data-errors="Uncaught ReferenceError: noSuchFunction' in dom


def test_mitsuba_reference_from_the_command_line(pair, tmp):
    """A Mitsuba-style reference (mean image and per-sample variance image) made from a render of
    2048 spp (Mitsuba's are of 32,000: a variance from few samples is too small in some pixels,
    which its rule then fails); b (other seeds) passes under both rules."""
    a, b, _ = pair
    ref = tmp / "ref.mcstat"
    run(RENDER, "--scene", SCENES / "box.json", "--spp", 2048, "--M", 32, "--seed", 99, "--quiet",
        "-o", ref)
    s = mcstat.read(ref)
    n = s.counts[..., None]
    N = n.sum(axis=2)
    mean = (s.buffers * n).sum(axis=2) / N
    var = (n * (s.buffers - mean[:, :, None, :]) ** 2).sum(axis=2) / (s.buffers.shape[2] - 1)
    for name, img in (("ref.exr", mean), ("ref_var.exr", var)):
        out = oiio.ImageOutput.create(str(tmp / name))
        out.open(str(tmp / name), oiio.ImageSpec(RES[0], RES[1], 3, oiio.FLOAT))
        out.write_image(np.ascontiguousarray(img, dtype=np.float32))
        out.close()
    spp = int(N.max())
    for rule in ("mcstat", "mitsuba"):
        p = run(CLI, tmp / "ref.exr", b, "--compare:refvar={}:refspp={}:rule={}:json={}".format(
            tmp / "ref_var.exr", spp, rule, tmp / (rule + ".json")), check=False)
        assert p.returncode == 0, (rule, p.stdout, p.stderr)
        report = json.loads((tmp / (rule + ".json")).read_text())
        assert report["test"]["rule"] == rule and report["verdict"] == "SAME"
    assert "Mitsuba 3's rule" in p.stdout and report["channel_tests"]["total"] == 3 * RES[0] * RES[1]
    p = run(CLI, a, b, "--compare:refvar={}".format(tmp / "ref_var.exr"), check=False)
    assert p.returncode == 1 and "refvar is for an image reference" in p.stderr


def test_assert_same_render_passes_one_scene(pair, tmp, monkeypatch):
    a, b, _ = pair
    monkeypatch.setenv("MCSTAT_REPORT_DIR", str(tmp / "reports-pass"))
    r = assert_same_render(a, mcstat.read(b))
    assert r.verdict.startswith("SAME") and r.exit_code == 0
    assert not (tmp / "reports-pass").exists()  # nothing kept when the renders agree


def test_assert_same_render_fails_the_brighter_light(pair, tmp):
    a, _, light = pair
    target = tmp / "reports-fail"
    with pytest.raises(AssertionError) as e:
        assert_same_render(a, light, report_dir=target, level=0.01)
    message = str(e.value)
    verdict = mcstat.compare(a, light).verdict
    assert message == "{} (report: {})".format(verdict, target / "index.html")
    assert "\n" not in message
    assert sorted(os.listdir(target)) == ["a.png", "b.png", "heatmap.png", "index.html",
                                          "junit.xml", "maps.exr", "report.json"]
    maps = read_exr(target / "maps.exr")
    assert {"p", "z", "effect", "differs", "tile.z"} <= set(maps)
    assert np.nansum(maps["differs"]) + np.nansum(maps["tile.differs"]) > 0
    report = json.loads((target / "report.json").read_text())
    assert report["name"] == "test_assert_same_render_fails_the_brighter_light"
    check_junit(target / "junit.xml", 1, verdict)


def test_default_report_folder():
    os.environ.pop("MCSTAT_REPORT_DIR", None)
    here = os.path.dirname(os.path.abspath(__file__))
    assert str(report_dir_for("t", __file__)) == os.path.join(here, "mcstat-reports", "t")
    with pytest.raises(TypeError):
        assert_same_render("a", "b", html="x")
