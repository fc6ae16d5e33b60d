"""Errors: mcstat.Error (a RuntimeError) carrying the command line's one-line message."""

import shutil

import pytest

import mcstat
from conftest import CLI, cli_error, render, run


@pytest.fixture(scope="module")
def scene(tmp):
    return render(tmp / "scene.mcstat", res=(16, 12), spp=16, M=4)


def test_missing_file(tmp):
    missing = tmp / "missing.mcstat"
    with pytest.raises(mcstat.Error) as e:
        mcstat.read(missing)
    assert str(e.value) == cli_error(missing, "--gmon", "-o", tmp / "x.exr")
    assert isinstance(e.value, RuntimeError)
    with pytest.raises(mcstat.Error, match="missing.mcstat: cannot open"):
        mcstat.estimate(missing, "gmon")


def test_damaged_file(scene, tmp):
    damaged = tmp / "damaged.mcstat"
    data = scene.read_bytes()
    damaged.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(mcstat.Error) as e:
        mcstat.read(damaged)
    assert str(e.value) == cli_error(damaged, "--gmon", "-o", tmp / "x.exr")
    assert str(damaged) in str(e.value) and "\n" not in str(e.value)


def test_plain_exr_is_not_a_statistics_file(scene, tmp):
    run(CLI, scene, "--mean", "-o", tmp / "mean.exr")
    with pytest.raises(mcstat.Error, match="plain EXR image, not a statistics file"):
        mcstat.read(tmp / "mean.exr")


def test_unknown_operation(scene):
    with pytest.raises(mcstat.Error, match="unknown operation 'gmoon'.*gmon"):
        mcstat.estimate(scene, "gmoon")


def test_bad_parameter_value(scene, tmp):
    with pytest.raises(mcstat.Error) as e:
        mcstat.estimate(scene, "gmon", mode="sideways")
    assert str(e.value) == cli_error(scene, "--gmon:mode=sideways", "-o", tmp / "x.exr")
    with pytest.raises(mcstat.Error) as e:
        mcstat.compare(scene, scene, level=0.9)
    assert str(e.value) == cli_error(scene, scene, "--compare:level=0.9")
    with pytest.raises(mcstat.Error) as e:
        mcstat.estimate(scene, "gmon", mdoe="lum")
    assert str(e.value) == cli_error(scene, "--gmon:mdoe=lum", "-o", tmp / "x.exr")
    assert "did you mean mode?" in str(e.value)
    with pytest.raises(mcstat.Error) as e:
        mcstat.estimate(scene, "mif", residual=True)
    assert str(e.value) == cli_error(scene, "--mean", "--mif:residual=1", "-o", tmp / "x.exr")
    with pytest.raises(mcstat.Error) as e:
        mcstat.compare(scene, scene, tset="yuen")
    assert str(e.value) == cli_error(scene, scene, "--compare:tset=yuen")
    with pytest.raises(mcstat.Error) as e:
        mcstat.ingest(str(scene), spp=0)
    assert str(e.value) == cli_error("--ingest:spp=0", scene, "-o", tmp / "x.mcstat")
    with pytest.raises(mcstat.Error) as e:
        mcstat.ingest(str(tmp / "nothing_*.exr"))
    assert str(e.value) == cli_error("--ingest", tmp / "nothing_*.exr", "-o", tmp / "x.mcstat")


def test_per_sample_operation_needs_the_file(scene):
    with pytest.raises(mcstat.Error, match="per-sample records"):
        mcstat.estimate(mcstat.read(scene), "pajot")


def test_not_a_path_is_a_type_error(scene):
    """An array or None where a file is expected: TypeError naming the type, never the array
    printed as a file name (issue 50)."""
    img = mcstat.estimate(scene, "mean")
    for bad in (img, None, 3.5):
        with pytest.raises(TypeError) as e:
            mcstat.estimate(bad, "gmon")
        assert type(bad).__name__ in str(e.value) and "\n" not in str(e.value)
        assert len(str(e.value)) < 200
    with pytest.raises(TypeError):
        mcstat.compare(None, scene)


def test_a_slice_keeps_the_removed_light_layers(scene):
    img = mcstat.estimate(scene, "gmon", removed=True)
    assert sorted(img.removed) == ["Y", "se", "significant", "z", "zlocal"]
    part = img[2:5, 1:4]
    assert part.removed is img.removed and part.shape == (3, 3, 3)
    assert img.copy().removed is img.removed


def test_removed_light_settings_need_removed(scene):
    """removedradius without removed=True was ignored silently; now refused as on the command
    line, as ciaovs without ci is."""
    with pytest.raises(mcstat.Error, match="removedradius needs removed=1"):
        mcstat.estimate(scene, "gmon", removedradius=3)
    assert sorted(mcstat.estimate(scene, "gmon", removed=True, removedradius=3).removed)
