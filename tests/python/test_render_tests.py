"""Render tests (docs/compare.md, "Reports for CI" and "Render tests in pytest"): --compare's JUnit
read back by a JUnit consumer's parser (junitparser, as CI plugins read it) and by the structure
Jenkins and GitLab read, its JSON parsed back, its report page opened in a real headless browser
(Debian's chromium), Mitsuba 3's reference rule from the command line, and
mcstat.testing.assert_same_render passing one scene's seeds and failing the light 2 % brighter."""

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import OpenImageIO as oiio
import pytest
from junitparser import Failure, JUnitXml

import mcstat
from mcstat.testing import assert_same_render, report_dir_for, report_name
from conftest import CLI, RENDER, SOURCE, read_exr, run, tool_env

RES = (32, 24)  # the render-test scenes' size
SCENES = SOURCE / "tests/render-test/scenes"


PAGE = [".mcstat-report", "a.png", "b.png", "colorbar.png", "crop-a.png", "crop-b.png",
        "heatmap.png", "index.html", "outlines.png"]  # --compare:html=DIR's files


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
    assert sorted(os.listdir(d / "page")) == PAGE
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


def test_cli_page_never_overwrites_a_users_file(pair, tmp):
    """--compare:html=DIR writes into a folder holding other files and leaves them; it replaces
    its own earlier page; it refuses, in one line, a folder where a file of the page's names is
    not one it wrote (or was edited since), and then writes nothing there."""
    a, _, light = pair
    page = tmp / "cli-users" / "page"
    page.mkdir(parents=True)
    (page / "notes.txt").write_text("mine")
    for _ in range(2):  # the second run replaces the first one's page
        p = run(CLI, a, light, "--compare:html={}".format(page), check=False)
        assert p.returncode == 2, p.stderr
        assert (page / "notes.txt").read_text() == "mine"
    assert sorted(os.listdir(page)) == sorted(PAGE + ["notes.txt"])
    manifest = json.loads((page / ".mcstat-report").read_text())
    assert manifest["files"]["b.png"] == hashlib.sha1((page / "b.png").read_bytes()).hexdigest()
    (page / "a.png").write_bytes(b"the user's own picture now")
    for folder, planted in ((page, "a.png"), (tmp / "cli-users" / "other", "index.html")):
        folder.mkdir(exist_ok=True)
        (folder / planted).write_bytes(b"the user's own picture now")
        before = snapshot(folder)
        p = run(CLI, a, light, "--compare:html={}".format(folder), check=False)
        assert p.returncode == 1, p.stderr
        line = "mcstat: --compare: {}: holds {}, which mcstat did not write".format(folder, planted)
        assert p.stderr.startswith(line) and p.stderr.count("\n") == 1, p.stderr
        assert snapshot(folder) == before


def chromium_dom(page):
    """The page's DOM after load in Debian's headless chromium (about 1 s)."""
    env = tool_env()
    p = subprocess.run(["chromium", "--headless", "--disable-gpu", "--no-sandbox",
                        "--allow-file-access-from-files", "--virtual-time-budget=3000",
                        "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=60,
                       env=env)
    assert p.returncode == 0, p.stderr
    return p.stdout


@pytest.fixture(scope="module")
def pair160(tmp):
    """The render-test scene and its light 2 % brighter at 160 x 120: some 16 x 16 tiles differ
    (at 32 x 24 only the light's own pixels do)."""
    jobs = [(tmp / "a160.mcstat", SCENES / "box.json", 11),
            (tmp / "light160.mcstat", SCENES / "box-light-1.02.json", 12)]
    procs = [subprocess.Popen([str(RENDER), "--scene", str(scene), "--res", "160", "120", "--spp",
                               "64", "--M", "8", "--seed", str(seed), "--quiet", "-o", str(path)])
             for path, scene, seed in jobs]
    assert all(p.wait() == 0 for p in procs)
    return tuple(path for path, _, _ in jobs)


def page_sizes(dom):
    """body's data-sizes: {id: ((shown width, height), (own width, height))}."""
    sizes = re.search(r'data-sizes="([^"]*)"', dom).group(1)
    out = {}
    for item in sizes.split():
        m = re.fullmatch(r"([\w-]*)=(\d+)x(\d+)/(\d+)x(\d+)", item)
        out[m.group(1)] = ((int(m.group(2)), int(m.group(3))), (int(m.group(4)), int(m.group(5))))
    return out


def test_report_page_in_a_real_browser(pair160, tmp):
    """The reviewer's page (docs/compare.md, "Reports for CI"): the verdict with its power in one
    line, the tile map first, A with the differing tiles outlined, one A/B flip with an exposure
    control, the strongest tile enlarged; every picture of the whole image shown at one scale and
    at its own size; every picture loads, no script error."""
    a, light = pair160
    p, d = cli_reports(tmp, a, light, "browser")
    assert p.returncode == 2, p.stderr
    report = json.loads((d / "report.json").read_text())
    assert report["tiles"]["differing"] > 0
    page = d / "page" / "index.html"
    dom = chromium_dom(page)
    assert 'data-ready="1"' in dom, dom[:2000]
    assert 'data-images="6 of 6 loaded"' in dom
    assert "data-errors" not in dom
    verdict = re.search(r'<p id="verdict"[^>]*>([^<]*)</p>', dom).group(1)
    assert verdict.startswith(report["verdict_line"]) and "\n" not in verdict
    power = "{:.2g} % in one tile".format(report["power"]["tile_relative"] * 100)
    assert power in verdict and "in one pixel with probability 0.8" in verdict, verdict
    # The tile map is the first picture; the map, the outlines and the flip are shown at one scale
    # (160 x 120 three times), each picture at its own size (no browser resampling).
    assert re.search(r"<img [^>]*>", dom).group(0).startswith('<img id="map"')
    sizes = page_sizes(dom)
    assert list(sizes) == ["map", "colorbar", "outlines", "flip", "crop-a", "crop-b"]
    for name in ("map", "outlines", "flip"):
        assert sizes[name] == ((480, 360), (480, 360)), (name, sizes)
    assert sizes["crop-a"] == sizes["crop-b"] == ((256, 256), (256, 256))  # a tile at 16x
    assert "tile.z" in dom and "shown at 3x" in dom and "shown at 16x" in dom
    # The exposure control: two stops brighten the pictures of A and B, and nothing else.
    exposed = d / "exposed"
    shutil.copytree(d / "page", exposed)
    html = (exposed / "index.html").read_text()
    (exposed / "index.html").write_text(html.replace("</body>", EXPOSE + "</body>"))
    dom = chromium_dom(exposed / "index.html")
    assert "data-errors" not in dom
    filters = re.search(r'data-filters="([^"]*)"', dom).group(1)
    assert filters == "map:none colorbar:none outlines:{0} flip:{0} crop-a:{0} crop-b:{0}".format(
        "brightness(1.8779)"), filters  # 2^(2 / 2.2)
    assert "+2 stops" in dom
    # The check can fail: a missing picture and a script error show.
    broken = d / "broken"
    shutil.copytree(d / "page", broken)
    (broken / "outlines.png").unlink()
    html = (broken / "index.html").read_text()
    (broken / "index.html").write_text(html.replace("</body>", "<script>noSuchFunction();</script></body>"))
    dom = chromium_dom(broken / "index.html")
    assert 'data-images="5 of 6 loaded"' in dom
    assert 'data-errors="Uncaught ReferenceError: noSuchFunction' in dom


EXPOSE = """<script>
const e = document.getElementById("exposure");
e.value = "2";
e.dispatchEvent(new Event("input"));
document.body.dataset.filters = Array.from(document.images).map(function (i) {
  return i.id + ":" + (getComputedStyle(i).filter || "none"); }).join(" ");
</script>"""


def test_report_page_paints_exact_changes_at_the_ends(pair, tmp):
    """At 32 x 24 no tile differs, only the light's own pixels, exactly (no noise on either side):
    the page shows the pixels' map, those pixels in the colour of the scale's warm end, never the
    magenta of NaN, and says no NaN/Inf; the outlines frame the differing pixels."""
    a, _, light = pair
    p, d = cli_reports(tmp, a, light, "exact")
    assert p.returncode == 2, p.stderr
    report = json.loads((d / "report.json").read_text())
    assert report["tiles"]["differing"] == 0 and report["strongest_pixel"]["exact"]
    run(CLI, a, light, "--compare", "-o", d / "maps.exr", check=False)
    z = read_exr(d / "maps.exr")["z"]
    heat = oiio.ImageBuf(str(d / "page" / "heatmap.png")).get_pixels(oiio.UINT8)
    bar = oiio.ImageBuf(str(d / "page" / "colorbar.png")).get_pixels(oiio.UINT8)
    s = heat.shape[1] // RES[0]
    assert heat.shape[:2] == (RES[1] * s, RES[0] * s) and s == 15
    exact = np.argwhere(np.isinf(z))
    assert len(exact) == report["pixels"]["differing"] and (z[np.isinf(z)] > 0).all()
    gradient = bar[4, :, :3].astype(int)  # column i: t = (i + 0.5) / width
    for y, x in exact:
        c = heat[y * s + s // 2, x * s + s // 2, :3].astype(int)
        at = int(np.argmin(((gradient - c) ** 2).sum(axis=1)))  # where on the scale it is
        assert at >= len(gradient) - 3 and list(c) != [255, 0, 255], (x, y, c, at)
    html = (d / "page" / "index.html").read_text()
    assert "NaN/Inf" not in html and 'id="map"' in html and "outlined: 16 of 768 pixels differ" in html
    dom = chromium_dom(d / "page" / "index.html")
    assert 'data-images="6 of 6 loaded"' in dom and "data-errors" not in dom


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
    root = tmp / "reports-fail"
    with pytest.raises(AssertionError) as e:
        assert_same_render(a, light, report_dir=root, level=0.01)
    message = str(e.value)
    verdict = mcstat.compare(a, light).verdict
    # The report's own sub-folder: module, test, parameters.
    target = root / "test_render_tests.test_assert_same_render_fails_the_brighter_light"
    assert message == "{} (report: {})".format(verdict, target / "index.html")
    assert "\n" not in message
    assert os.listdir(root) == [target.name]
    files = sorted([f for f in PAGE if f != ".mcstat-report"] + ["junit.xml", "maps.exr",
                                                                 "report.json"])
    assert sorted(os.listdir(target)) == [".mcstat-report"] + files
    manifest = json.loads((target / ".mcstat-report").read_text())
    assert manifest["name"] == "test_render_tests.py::test_assert_same_render_fails_the_brighter_light"
    assert sorted(manifest["files"]) == files
    assert manifest["files"]["maps.exr"] == hashlib.sha1((target / "maps.exr").read_bytes()).hexdigest()
    maps = read_exr(target / "maps.exr")
    assert {"p", "z", "effect", "differs", "tile.z"} <= set(maps)
    assert np.nansum(maps["differs"]) + np.nansum(maps["tile.differs"]) > 0
    report = json.loads((target / "report.json").read_text())
    assert report["name"] == manifest["name"]
    check_junit(target / "junit.xml", 1, verdict)


def user_files(folder):
    """A user's folder: a file, a sub-folder with a file; returns {relative path: bytes}."""
    (folder / "src").mkdir(parents=True)
    (folder / "notes.txt").write_text("my notes")
    (folder / "src" / "main.py").write_text("print('mine')")
    return snapshot(folder)


def snapshot(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def test_a_report_never_deletes_a_users_files(pair, tmp):
    """Issue 47: report_dir= named a folder holding a user's project; a failing assert emptied it."""
    a, _, light = pair
    project = tmp / "project"
    mine = user_files(project)
    with pytest.raises(AssertionError) as e:
        assert_same_render(a, light, report_dir=project)
    after = snapshot(project)
    assert {k: after[k] for k in mine} == mine  # every file of the user, unchanged
    added = sorted(set(after) - set(mine))
    folder = "test_render_tests.test_a_report_never_deletes_a_users_files"
    assert added and all(k.startswith(folder + "/") for k in added), added
    assert str(project / folder / "index.html") in str(e.value)


def test_report_dir_tmp_path_keeps_the_tests_own_files(pair, tmp_path):
    """The natural call, report_dir=tmp_path, where the test's own renders live."""
    a, _, light = pair
    shutil.copy(a, tmp_path / "a.mcstat")
    shutil.copy(light, tmp_path / "light.mcstat")
    (tmp_path / "index.html").write_text("the test's own page")
    mine = snapshot(tmp_path)
    with pytest.raises(AssertionError):
        assert_same_render(tmp_path / "a.mcstat", tmp_path / "light.mcstat", report_dir=tmp_path)
    with pytest.raises(AssertionError):  # a rerun replaces its own report, nothing else
        assert_same_render(tmp_path / "a.mcstat", tmp_path / "light.mcstat", report_dir=tmp_path)
    after = snapshot(tmp_path)
    assert {k: after[k] for k in mine} == mine
    reports = sorted({k.split("/")[0] for k in set(after) - set(mine)})
    assert reports == ["test_render_tests.test_report_dir_tmp_path_keeps_the_tests_own_files"]


def test_a_folder_of_the_reports_name_holding_a_users_file_is_left_alone(pair, tmp):
    a, _, light = pair
    root = tmp / "taken"
    name = "test_render_tests.test_a_folder_of_the_reports_name_holding_a_users_file_is_left_alone"
    (root / name).mkdir(parents=True)
    (root / name / "index.html").write_text("not mcstat's")
    with pytest.raises(AssertionError) as e:
        assert_same_render(a, light, report_dir=root)
    assert (root / name / "index.html").read_text() == "not mcstat's"
    assert os.listdir(root / name) == ["index.html"]
    assert str(root / (name + "-2") / "index.html") in str(e.value)
    assert (root / (name + "-2") / "report.json").is_file()


def test_a_passing_rerun_leaves_no_stale_report(pair, tmp):
    """Fail, then pass under the same test name: the DIFFERENT report is gone; a file the user
    put into the report's folder stays, and so does one of the report's files the user edited."""
    a, b, light = pair
    root = tmp / "rerun"
    with pytest.raises(AssertionError):
        assert_same_render(a, light, report_dir=root, name="scene")
    assert json.loads((root / "scene" / "report.json").read_text())["verdict"] == "DIFFERENT"
    assert_same_render(a, b, report_dir=root, name="scene")
    assert not (root / "scene").exists()
    # Again, with the user's note in the report's folder and the page edited by the user.
    with pytest.raises(AssertionError):
        assert_same_render(a, light, report_dir=root, name="scene")
    (root / "scene" / "note.txt").write_text("looked at it")
    (root / "scene" / "index.html").write_text("edited")
    assert_same_render(a, b, report_dir=root, name="scene")
    assert sorted(os.listdir(root / "scene")) == ["index.html", "note.txt"]
    assert not (root / "scene" / "report.json").exists()


MODULE = """
import os
import pytest
from mcstat.testing import assert_same_render

@pytest.mark.parametrize("kind", ["light"])
def test_scene(kind):
    assert_same_render(os.environ["A"], os.environ["LIGHT"])
"""


def test_two_tests_of_one_name_in_two_modules_keep_two_reports(pair, tmp):
    """test_cornell.py::test_scene[light] and glass/test_glass.py::test_scene[light] under one
    $MCSTAT_REPORT_DIR: two sub-folders, two reports (pytest run as a user's suite runs)."""
    a, _, light = pair
    suite = tmp / "suite"
    (suite / "glass").mkdir(parents=True)
    (suite / "test_cornell.py").write_text(MODULE)
    (suite / "glass" / "test_glass.py").write_text(MODULE)
    reports = tmp / "suite-reports"
    env = dict(os.environ, A=str(a), LIGHT=str(light), MCSTAT_REPORT_DIR=str(reports))
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        "--rootdir", str(suite), "--basetemp", str(tmp / "suite-tmp"), str(suite)],
                       cwd=str(suite), env=env, capture_output=True, text=True, timeout=240)
    assert p.returncode == 1 and "2 failed" in p.stdout, p.stdout + p.stderr
    assert sorted(os.listdir(reports)) == ["glass.test_glass.test_scene[light]",
                                           "test_cornell.test_scene[light]"]
    for d in os.listdir(reports):
        report = json.loads((reports / d / "report.json").read_text())
        assert report["verdict"] == "DIFFERENT" and report["name"].endswith("::test_scene[light]")


def test_report_names():
    assert report_name("tests/test_glass.py::TestA::test_scene[light]") == \
        "tests.test_glass.TestA.test_scene[light]"
    assert report_name("test_x.py::test_y") == "test_x.test_y"
    # Characters a folder name should not hold become "_", and a hash keeps two ids apart.
    one, two = report_name("t.py::test[a b]"), report_name("t.py::test[a/b]")
    assert one.startswith("t.test[a_b]-") and two.startswith("t.test[a_b]-") and one != two
    assert report_name("../../t.py::test").startswith("t.test_-")
    assert not report_name("t.py::" + "x" * 500).startswith(".") and len(report_name(
        "t.py::" + "x" * 500)) <= 130


def test_default_report_folder():
    os.environ.pop("MCSTAT_REPORT_DIR", None)
    here = os.path.dirname(os.path.abspath(__file__))
    assert str(report_dir_for("t", __file__)) == os.path.join(here, "mcstat-reports", "t")
    with pytest.raises(TypeError):
        assert_same_render("a", "b", html="x")
