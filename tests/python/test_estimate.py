"""Every registry operation through the module equals `mcstat FILE --OP -o out.exr` bit for bit,
from a Stats in memory and from the path (streamed by blocks of rows)."""

import numpy as np
import pytest

import mcstat
from conftest import CLI, assert_same_channels, render, run


@pytest.fixture(scope="module")
def files(tmp):
    return {
        "aovs": render(tmp / "aovs.mcstat", "--aovs"),
        # every sample kept, for the per-sample operations (Pajot, RPF)
        "samples": render(tmp / "samples.mcstat", "--keep-samples", scene="dof", res=(24, 16),
                          spp=8, M=4),
    }


def cli_result(tmp, src, op, mods=""):
    out = tmp / "cli-{}{}.exr".format(op, mods.replace(":", "_").replace("=", "-"))
    info = next(o for o in mcstat.operations() if o["name"] == op)
    pre = ["--mean"] if info["takes_image"] else []  # MIF/WMIF filter an image: the mean's
    run(CLI, src, *pre, "--" + op + mods, "-o", out)
    return out


OPERATIONS = [o["name"] for o in mcstat.operations()]


def test_the_registry_is_listed():
    ops = mcstat.operations()
    assert {"mean", "gmon", "mon", "mif", "3dwtmf", "pajot", "rpf"} <= set(OPERATIONS)
    gmon = next(o for o in ops if o["name"] == "gmon")
    assert "mode" in [p["name"] for p in gmon["params"]] and gmon["has_diagnostics"]


@pytest.mark.parametrize("op", OPERATIONS)
def test_every_operation_equals_the_command_line(op, files, tmp):
    info = next(o for o in mcstat.operations() if o["name"] == op)
    if info["reads_samples"]:
        src = files["samples"]
        result = mcstat.estimate(src, op)
    else:
        src = files["aovs"]
        result = mcstat.estimate(mcstat.read(src), op)
        streamed = mcstat.estimate(src, op)
        np.testing.assert_array_equal(result.all_channels, streamed.all_channels)
    assert result.shape[2] == 3 and result.dtype == np.float32
    assert_same_channels(result, cli_result(tmp, src, op))
    if not info["reads_samples"]:
        assert len(result.aovs) == 19  # A and six RGB passes carried by every operation


def test_parameters_diagnostics_and_residual(files, tmp):
    src = files["aovs"]
    s = mcstat.read(src)
    r = mcstat.estimate(s, "gmon", diag=True)
    assert_same_channels(r, cli_result(tmp, src, "gmon", ":diag=1"))
    assert {"gini", "kept", "excluded"} <= set(r.diagnostics)
    r = mcstat.estimate(s, "gmon", residual=True)
    assert_same_channels(r, cli_result(tmp, src, "gmon", ":residual=1"))
    # robust + residual = mean, up to one rounding
    np.testing.assert_allclose(r + np.stack([r.residual[c] for c in "RGB"], -1),
                               mcstat.estimate(s, "mean"), rtol=1e-6, atol=1e-6)
    r = mcstat.estimate(src, "gmon", removed=True, removedradius=1)
    assert_same_channels(r, cli_result(tmp, src, "gmon", ":removed=1:removedradius=1"))
    assert set(r.removed) == {"Y", "se", "z", "zlocal", "significant"}
    # removed.Y is the residual's luminance (the file is Rec.709)
    both = mcstat.estimate(s, "gmon", removed=True, residual=True)
    y = sum(w * both.residual[c] for w, c in zip((0.2126, 0.7152, 0.0722), "RGB"))
    np.testing.assert_allclose(both.removed["Y"], y, rtol=1e-4, atol=1e-4)  # float residual
    # keeplight: in memory and streamed, the command's pixels bit for bit; the mean's light
    r = mcstat.estimate(s, "gmon", keeplight=True)
    assert_same_channels(r, cli_result(tmp, src, "gmon", ":keeplight=1"))
    np.testing.assert_array_equal(r.all_channels,
                                  mcstat.estimate(src, "gmon", keeplight=True).all_channels)
    mean = mcstat.estimate(s, "mean")
    np.testing.assert_allclose(r.sum(axis=(0, 1)), mean.sum(axis=(0, 1)), rtol=1e-5)
    with pytest.raises(mcstat.Error, match="keeplightgamma needs keeplight=1"):
        mcstat.estimate(s, "gmon", keeplightgamma=2)
    r = mcstat.estimate(src, "3dwtmf", size=(5, 5))
    assert_same_channels(r, cli_result(tmp, src, "3dwtmf", ":size=5x5"))
    r = mcstat.estimate(mcstat.read(render(tmp / "plain.mcstat")), "gmon", mode="channel")
    assert_same_channels(r, cli_result(tmp, tmp / "plain.mcstat", "gmon", ":mode=channel"))
    assert not np.array_equal(r, mcstat.estimate(tmp / "plain.mcstat", "gmon"))


def test_confidence_interval_layers(files, tmp):
    """ci=LEVEL (docs/confidence.md): the same layers as `mcstat --gmon:ci=0.95`, in memory and
    streamed, and with ciaovs=True every AOV but the labels gets its own."""
    src = files["aovs"]
    s = mcstat.read(src)
    r = mcstat.estimate(s, "gmon", ci=0.95)
    assert_same_channels(r, cli_result(tmp, src, "gmon", ":ci=0.95"))
    np.testing.assert_array_equal(r.all_channels, mcstat.estimate(src, "gmon", ci=0.95).all_channels)
    assert set(r.ci_low) == set(r.ci_high) == {"R", "G", "B"}
    for c in "RGB":
        assert np.all(r.ci_low[c] <= r.ci_high[c])
    a = mcstat.estimate(s, "mean", ci=0.9, ciaovs=True)
    assert_same_channels(a, cli_result(tmp, src, "mean", ":ci=0.9:ciaovs=1"))
    assert len(a.ci_low) == 3 + 19 and len(a.aovs) == 19
    for c in a.ci_low:  # the mean lies in the middle of its t interval
        v = a[..., "RGB".index(c)] if c in "RGB" else a.aovs[c]
        tol = 1e-5 * (1 + np.abs(v))  # the interval in double, the estimate in float
        assert np.all(a.ci_low[c] <= v + tol) and np.all(v <= a.ci_high[c] + tol)
    with pytest.raises(mcstat.Error, match="ci must be a number in \\(0, 1\\)"):
        mcstat.estimate(s, "gmon", ci=1)
    # citarget="expected": the command's layers, wider than the pixel's own t interval (the
    # neighbours' variance where larger), about the mean; cipool alone is refused.
    e = mcstat.estimate(s, "gmon", ci=0.95, citarget="expected", cipool=2)
    assert_same_channels(e, cli_result(tmp, src, "gmon", ":ci=0.95:citarget=expected:cipool=2"))
    own = mcstat.estimate(s, "mean", ci=0.95)
    for c in "RGB":
        tol = 1e-5 * (1 + np.abs(own.ci_high[c]))
        assert np.all(e.ci_high[c] - e.ci_low[c] >= own.ci_high[c] - own.ci_low[c] - tol)
    assert np.any(e.ci_high["R"] - e.ci_low["R"] > own.ci_high["R"] - own.ci_low["R"] + 1e-6)
    with pytest.raises(mcstat.Error, match="cipool=2 needs citarget=expected"):
        mcstat.estimate(s, "gmon", ci=0.95, cipool=2)


def test_readme_line(files):
    s = mcstat.read(files["aovs"])
    assert mcstat.estimate(s, "gmon").shape == (30, 40, 3)


def test_threads_run_side_by_side(files):
    """The GIL is released while the C++ works: operations on threads give the serial results."""
    from concurrent.futures import ThreadPoolExecutor

    src = files["aovs"]
    names = ["gmon", "mon", "3dwtmf", "median"]
    serial = [mcstat.estimate(src, n) for n in names]
    with ThreadPoolExecutor(4) as pool:
        threaded = list(pool.map(lambda n: mcstat.estimate(mcstat.read(src), n), names))
    for a, b in zip(serial, threaded):
        np.testing.assert_array_equal(a.all_channels, b.all_channels)
