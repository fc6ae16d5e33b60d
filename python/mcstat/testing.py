"""Render tests under pytest (docs/compare.md, "Render tests in pytest").

    from mcstat.testing import assert_same_render

    def test_cornell_box(tmp_path):
        new = mcstat.ingest(sorted(glob.glob(str(tmp_path / "seed_*.exr"))))
        assert_same_render("refs/cornell_box.mcstat", new, reltol=0.01)

assert_same_render compares as `mcstat A B --compare` does and, when the renders differ, keeps
the evidence for the reviewer in a folder named after the test: the maps (maps.exr), the report
page (index.html with a.png, b.png and heatmap.png), report.json and junit.xml. Then it raises
AssertionError with the one-line verdict.
"""

import inspect
import os
import re
import shutil
import tempfile
from pathlib import Path

from . import compare

__all__ = ["assert_same_render", "report_dir_for"]


def _test_name():
    """The running test's name from pytest (PYTEST_CURRENT_TEST: "path::name[params] (call)"),
    made a safe folder name; "render" outside pytest."""
    current = os.environ.get("PYTEST_CURRENT_TEST", "")
    name = current.split("::")[-1].rsplit(" ", 1)[0] if current else "render"
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "render"


def report_dir_for(name=None, caller_file=None):
    """Where assert_same_render keeps a failure's evidence: $MCSTAT_REPORT_DIR/<test> when the
    environment sets it (a CI job collecting artifacts), else mcstat-reports/<test> beside the
    test file that called it."""
    name = name or _test_name()
    root = os.environ.get("MCSTAT_REPORT_DIR")
    if root:
        return Path(root) / name
    base = Path(caller_file).resolve().parent if caller_file else Path.cwd()
    return base / "mcstat-reports" / name


def _caller_file():
    for frame in inspect.stack()[2:]:
        if Path(frame.filename).resolve() != Path(__file__).resolve():
            return frame.filename
    return None


def assert_same_render(a, b, report_dir=None, **options):
    """Asserts that the renders `a` and `b` (Stats, statistics file paths) are the same image up
    to their Monte Carlo noise: mcstat.compare(a, b, **options) (level, test, reltol, tol,
    channels, aovs, equivalence...). On failure the maps, the HTML report, JSON and JUnit go to
    `report_dir` (default: report_dir_for(), beside the calling test file) and AssertionError
    carries the one-line verdict and the folder. Returns the CompareResult when they agree."""
    for key in ("html", "json", "junit", "maps"):
        if key in options:
            raise TypeError("assert_same_render writes {} itself (report_dir=)".format(key))
    name = options.pop("name", None) or _test_name()
    work = Path(tempfile.mkdtemp(prefix="mcstat-render-test-"))
    try:
        r = compare(a, b, maps=work / "maps.exr", html=str(work / "page"),
                    json=str(work / "report.json"), junit=str(work / "junit.xml"), name=name,
                    **options)
        if not r.fail:
            return r
        target = Path(report_dir) if report_dir else report_dir_for(name, _caller_file())
        if target.exists():
            shutil.rmtree(target)
        target.parent.mkdir(parents=True, exist_ok=True)
        page = work / "page"
        for f in ("maps.exr", "report.json", "junit.xml"):
            shutil.move(str(work / f), str(page / f))
        shutil.move(str(page), str(target))
        raise AssertionError("{} (report: {})".format(r.verdict, target / "index.html"))
    finally:
        shutil.rmtree(work, ignore_errors=True)
