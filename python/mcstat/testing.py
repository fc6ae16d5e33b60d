"""Render tests under pytest (docs/compare.md, "Render tests in pytest").

    from mcstat.testing import assert_same_render

    def test_cornell_box(tmp_path):
        new = mcstat.ingest(sorted(glob.glob(str(tmp_path / "seed_*.exr"))))
        assert_same_render("refs/cornell_box.mcstat", new, reltol=0.01)

assert_same_render compares as `mcstat A B --compare` does and, when the renders differ, keeps
the evidence for the reviewer in a new sub-folder of the report folder, named after the test
(module, class, function and parameters): the maps (maps.exr), the report page (index.html with
its pictures: docs/compare.md, "Reports for CI"), report.json and junit.xml. Then it raises AssertionError with the
one-line verdict.

It never deletes or overwrites a file it did not write (docs/compare.md, "Report folders"): the
files of a report are listed with their SHA-1 in the sub-folder's manifest `.mcstat-report`, the
one format the command line's `--compare:html=` writes too. A later run of the same test replaces
exactly those files (still holding what it wrote), or removes them when the renders now agree, so
no stale DIFFERENT is left behind; a sub-folder holding anything else is left alone and the report
goes to the next free name (NAME-2, NAME-3, ...).
"""

import hashlib
import inspect
import json
import os
import re
import shutil
import tempfile
from pathlib import Path

from . import compare

__all__ = ["assert_same_render", "report_dir_for", "report_name"]

MANIFEST = ".mcstat-report"  # include/mcstat/compare/report/report_folder.h: the same file, the same rule
_SAFE = re.compile(r"[^A-Za-z0-9_.\-\[\]]+")
_MAX_NAME = 120
_MAX_CANDIDATES = 100


def _test_id():
    """The running test's pytest node id ("tests/test_glass.py::TestA::test_scene[light]", from
    PYTEST_CURRENT_TEST without its " (call)"); "" outside pytest."""
    current = os.environ.get("PYTEST_CURRENT_TEST", "")
    return current.rsplit(" ", 1)[0] if current else ""


def _folder_name(readable, identity):
    """`readable` made a safe folder name: characters outside letters, digits, "_.-[]" become "_",
    leading dots go (never a hidden folder, never "." or ".."); when that changed anything, or the
    name is long, 8 hex digits of `identity`'s SHA-1 are appended, so two tests never share it."""
    safe = _SAFE.sub("_", readable).lstrip(".")
    if safe != readable or len(safe) > _MAX_NAME or not safe:
        digest = hashlib.sha1(identity.encode("utf-8", "surrogateescape")).hexdigest()[:8]
        safe = "{}-{}".format(safe[:_MAX_NAME].rstrip("-") or "render", digest)
    return safe


def report_name(test_id=None):
    """The report sub-folder's name for a pytest node id (default: the running test's): its module
    path, class, function and parameters joined by dots, "tests/test_glass.py::test_scene[light]"
    -> "tests.test_glass.test_scene[light]"; "render" outside pytest."""
    tid = _test_id() if test_id is None else test_id
    if not tid:
        return "render"
    path, _, rest = tid.partition("::")
    module = path[:-3] if path.endswith(".py") else path
    split = re.split(r"[\\/]+", module)
    parts = [p for p in split if p not in ("", ".", "..")]
    readable = ".".join(parts + ([rest.replace("::", ".")] if rest else []))
    name = _folder_name(readable, tid)
    if len(parts) != len(split) and name == readable:  # a dropped ".." must not merge two ids
        name = _folder_name(readable + "/", tid)
    return name


def _report_root(caller_file=None):
    """The folder that holds the report sub-folders: $MCSTAT_REPORT_DIR when the environment sets
    it (a CI job collecting artifacts), else mcstat-reports beside the test file."""
    root = os.environ.get("MCSTAT_REPORT_DIR")
    if root:
        return Path(root)
    base = Path(caller_file).resolve().parent if caller_file else Path.cwd()
    return base / "mcstat-reports"


def report_dir_for(name=None, caller_file=None):
    """Where assert_same_render keeps a failure's evidence when no report_dir is given: the
    sub-folder report_name() (or `name`, made a safe folder name) of $MCSTAT_REPORT_DIR, else of
    mcstat-reports beside the test file. A later free name (NAME-2...) is used when that folder
    holds files mcstat did not write."""
    folder = _folder_name(name, name) if name else report_name()
    return _report_root(caller_file) / folder


def _caller_file():
    for frame in inspect.stack()[2:]:
        if Path(frame.filename).resolve() != Path(__file__).resolve():
            return frame.filename
    return None


def _sha1(path):
    h = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _manifest(folder):
    """(report name, {file: sha1}) of a report folder's manifest; (None, {}) when it has none."""
    try:
        m = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None, {}
    if not isinstance(m, dict) or m.get("mcstat_report") != 1 or not isinstance(m.get("files"), dict):
        return None, {}
    return m.get("name"), {k: v for k, v in m["files"].items() if isinstance(v, str)}


def _ours(folder, f, listed):
    """Whether `folder/f` is a regular file the manifest lists with the hash its content has."""
    p = folder / f
    if "/" in f or "\\" in f or f in ("", ".", "..") or p.is_symlink() or not p.is_file():
        return False
    return f in listed and (listed[f] == "" or listed[f].lower() == _sha1(p))


def _remove_report(folder):
    """Removes the files a report wrote into `folder` (listed in its manifest, content unchanged),
    then the manifest, then the folder when nothing else is left. Returns whether it is gone."""
    _, listed = _manifest(folder)
    for f in list(listed):
        if _ours(folder, f, listed):
            (folder / f).unlink()
    (folder / MANIFEST).unlink(missing_ok=True)
    try:
        folder.rmdir()
        return True
    except OSError:  # the user's files are left, and the folder with them
        return False


def _candidates(root, folder):
    yield root / folder
    for i in range(2, _MAX_CANDIDATES + 1):
        yield root / "{}-{}".format(folder, i)


def _earlier_reports(root, folder, name):
    """The sub-folders holding a report of the test `name` from an earlier run."""
    for c in _candidates(root, folder):
        if not c.exists() and not c.is_symlink():
            if c.name != folder:
                return
            continue
        if c.is_dir() and not c.is_symlink() and _manifest(c)[0] == name:
            yield c


def _place(staging, root, folder):
    """Moves the complete report `staging` (a folder inside `root`) to the first of folder,
    folder-2, ... that is free. Never touches a folder that exists."""
    for c in _candidates(root, folder):
        if c.is_symlink() or (c.exists() and not c.is_dir()):
            continue
        if c.exists():  # this test's earlier report was removed above: what is left is not ours
            continue
        try:
            os.rename(staging, c)  # atomic; fails if another process filled c meanwhile
            return c
        except OSError:
            continue
    raise RuntimeError("{}: no free report folder among {} ... {}-{}".format(
        root, folder, folder, _MAX_CANDIDATES))


def assert_same_render(a, b, report_dir=None, **options):
    """Asserts that the renders `a` and `b` (Stats, statistics file paths) are the same image up
    to their Monte Carlo noise: mcstat.compare(a, b, **options) (level, test, reltol, tol,
    channels, aovs, equivalence...). On failure the maps, the HTML report, JSON and JUnit go to a
    new sub-folder of `report_dir` (default: $MCSTAT_REPORT_DIR, else mcstat-reports beside the
    calling test file) named after the test (report_name(), or `name=`), and AssertionError
    carries the one-line verdict and the page. A report of this test from an earlier run is
    replaced (failure) or removed (success); nothing else is ever deleted or overwritten.
    Returns the CompareResult when they agree."""
    for key in ("html", "json", "junit", "maps"):
        if key in options:
            raise TypeError("assert_same_render writes {} itself (report_dir=)".format(key))
    given = options.pop("name", None)
    tid = _test_id()
    name = given or tid or "render"
    folder = _folder_name(given, given) if given else report_name(tid)
    root = Path(report_dir) if report_dir else _report_root(_caller_file())
    work = Path(tempfile.mkdtemp(prefix="mcstat-render-test-"))
    try:
        r = compare(a, b, maps=work / "maps.exr", html=str(work / "page"),
                    json=str(work / "report.json"), junit=str(work / "junit.xml"), name=name,
                    **options)
        if root.is_dir():  # this test's reports of earlier runs: replaced, or stale if it passes
            for earlier in list(_earlier_reports(root, folder, name)):
                _remove_report(earlier)
        if not r.fail:
            return r
        root.mkdir(parents=True, exist_ok=True)
        page = work / "page"
        for f in ("maps.exr", "report.json", "junit.xml"):
            shutil.move(str(work / f), str(page / f))
        files = sorted(p.name for p in page.iterdir() if p.is_file() and p.name != MANIFEST)
        (page / MANIFEST).write_text(json.dumps(
            {"mcstat_report": 1, "name": name, "files": {f: _sha1(page / f) for f in files}},
            indent=1) + "\n", encoding="utf-8")
        staging = Path(tempfile.mkdtemp(prefix=".mcstat-report-", dir=str(root)))
        try:
            staging.rmdir()
            shutil.move(str(page), str(staging))
            target = _place(staging, root, folder)
        finally:
            shutil.rmtree(staging, ignore_errors=True)  # only when it was not placed
        raise AssertionError("{} (report: {})".format(r.verdict, target / "index.html"))
    finally:
        shutil.rmtree(work, ignore_errors=True)
