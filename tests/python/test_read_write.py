"""Reading, writing, streaming and ingesting statistics files against the command line's files."""

import numpy as np
import pytest

import mcstat
from conftest import CLI, RENDER, assert_same_channels, read_exr, render, run


@pytest.fixture(scope="module")
def scene(tmp):
    return render(tmp / "scene.mcstat", "--aovs")


def test_read_arrays_match_the_file(scene):
    s = mcstat.read(scene)
    h = s.header
    assert (h["width"], h["height"], h["M"], h["spp"]) == (40, 30, 8, 64)
    assert h["seeds"] == ("1",) and h["color_space"] == "lin_rec709" and not h["adaptive"]
    # Every list in the header is a tuple of str (issue 50), as beauty_channels is.
    assert h["beauty_channels"] == ("R", "G", "B") and h["sources"] == ()
    assert isinstance(h["features"], tuple) and "Albedo" in h["features"]
    assert s.mean.shape == (30, 40, 3) and s.mean.dtype == np.float32
    assert s.buffers.shape == (30, 40, 8, 3) and s.counts.shape == (30, 40, 8)
    # round robin: 64 samples in 8 buffers, 8 each; the counts sum to the pixel's count
    assert np.all(s.counts == 8) and np.all(s.count == 64)
    # part beauty is the plain mean: the count-weighted mean of the buffers (float rounding)
    np.testing.assert_allclose((s.buffers * s.counts[..., None]).sum(2) / 64, s.mean, rtol=1e-5,
                               atol=1e-6)
    # part beauty as OpenImageIO's own EXR reader reads it (part 0)
    beauty = read_exr(scene)
    for c, name in enumerate("RGB"):
        np.testing.assert_array_equal(s.mean[..., c], beauty[name])
    assert set(s.features) == {"N", "P", "Albedo", "Z", "A"}
    assert s.features["N"].shape == (30, 40, 3) and s.features["Z"].shape == (30, 40)
    # AOVs: alpha and the six light-path passes, grouped by layer, (H, W, M, 3) views
    assert "A" in s.aovs and s.aovs["A"].shape == (30, 40, 8)
    assert s.aovs["diffuse_direct"].shape == (30, 40, 8, 3)
    passes = [k for k in s.aovs if k != "A"]
    assert len(passes) == 6
    total = sum(s.aovs[k] for k in passes)
    np.testing.assert_allclose(total, s.buffers, rtol=1e-4, atol=1e-4)


def test_write_gives_the_command_lines_bytes(scene, tmp):
    s = mcstat.read(scene)
    mcstat.write(s, tmp / "py.mcstat")
    run(CLI, scene, "-o", tmp / "cli.mcstat")
    assert (tmp / "py.mcstat").read_bytes() == (tmp / "cli.mcstat").read_bytes()
    run(CLI, tmp / "py.mcstat", "--check")


def test_arrays_are_views_written_back(scene, tmp):
    s = mcstat.read(scene)
    # Doubling is exact in float: every mean the CLI computes from the file doubles exactly.
    s.buffers *= 2
    s.mean *= 2
    mcstat.write(s, tmp / "double.mcstat")
    run(CLI, scene, "--gmon", "-o", tmp / "gmon1.exr")
    run(CLI, tmp / "double.mcstat", "--gmon", "-o", tmp / "gmon2.exr")
    g1, g2 = read_exr(tmp / "gmon1.exr"), read_exr(tmp / "gmon2.exr")
    for c in "RGB":
        np.testing.assert_array_equal(g2[c], 2 * g1[c])
    assert not np.array_equal(mcstat.read(tmp / "double.mcstat").mean, mcstat.read(scene).mean)


def test_blocks_stream_the_same_rows(scene):
    s = mcstat.read(scene)
    rows = []
    for b in mcstat.blocks(scene, rows=7):
        assert b.buffers.shape[1:] == (40, 8, 3) and b.buffers.shape[0] <= 7
        rows.append(b)
    assert [b.first_row for b in rows] == [0, 7, 14, 21, 28]
    np.testing.assert_array_equal(np.concatenate([b.buffers for b in rows]), s.buffers)
    np.testing.assert_array_equal(np.concatenate([b.counts for b in rows]), s.counts)
    np.testing.assert_array_equal(np.concatenate([b.mean for b in rows]), s.mean)
    np.testing.assert_array_equal(np.concatenate([b.aov for b in rows]), s.aov)


def test_adaptive_and_compact_files(scene, tmp):
    adaptive = render(tmp / "adaptive.mcstat", "--adaptive-m", M=17, spp=128)
    run(CLI, scene, "--compact", "-o", tmp / "compact.mcstat")
    for path in (adaptive, tmp / "compact.mcstat"):
        s = mcstat.read(path)
        assert s.header["adaptive"]
        m = s.buffers_per_pixel
        assert m.shape == (30, 40) and m.min() >= 1 and m.max() <= s.M
        assert m.min() < m.max()  # some pixels hold fewer buffers than others
        held = np.arange(s.M)[None, None, :] < m[..., None]
        # absent buffers: NaN means and count 0; present ones hold samples
        assert np.all(np.isnan(s.buffers[~held])) and np.all(s.counts[~held] == 0)
        assert np.all(s.counts[held] > 0) and not np.any(np.isnan(s.buffers[held]))
        np.testing.assert_array_equal(s.counts.sum(2), s.count)
        run(CLI, path, "--gmon", "-o", tmp / "gmon-cli.exr")
        assert_same_channels(mcstat.estimate(s, "gmon"), tmp / "gmon-cli.exr")
    assert mcstat.read(tmp / "compact.mcstat").header["compact"]


def test_ingest_gives_the_command_lines_file(tmp):
    for seed in (1, 2, 3):
        run(RENDER, "--scene", "default", "--res", 24, 16, "--spp", 8, "--seed", seed,
            "--reference", "--quiet", "-o", tmp / "seed_{}.exr".format(seed))
    s = mcstat.ingest(str(tmp / "seed_*.exr"))
    assert s.header["M"] == 3 and s.header["assignment"] == "perfile" and s.header["spp"] == 24
    mcstat.write(s, tmp / "py-seeds.mcstat")
    run(CLI, "--ingest", tmp / "seed_*.exr", "-o", tmp / "cli-seeds.mcstat")
    assert (tmp / "py-seeds.mcstat").read_bytes() == (tmp / "cli-seeds.mcstat").read_bytes()
    # a list of files and a modifier: the same renders, 8 spp each said explicitly
    t = mcstat.ingest([tmp / "seed_1.exr", tmp / "seed_2.exr"], spp=8, aovs=False)
    assert t.header["M"] == 2 and t.header["spp"] == 16
    np.testing.assert_array_equal(t.buffers, s.buffers[:, :, :2])


def test_version_is_the_projects_one():
    # the module, the command line and the renderer report the version CMake defines once
    # (include/mcstat/version.h, generated from project(mcstat VERSION ...))
    assert mcstat.__version__ == run(CLI, "--version").stdout.split()[1]
    assert run(RENDER, "--version").stdout.split() == ["mcstat-render", mcstat.__version__]
    major, minor, patch = (int(p) for p in mcstat.__version__.split("."))
    assert (major, minor, patch) >= (0, 1, 0)


def test_a_compact_files_buffers_refuse_edits(tmp):
    """A compact file's buffers are a padded copy that write() never sees: editing them raises
    instead of vanishing from the written file (issue 50); a fixed-M file's are views and keep
    the edit."""
    full = tmp / "edit-full.mcstat"
    run(RENDER, "--scene", "default", "--res", "16", "12", "--spp", "16", "--M", "4", "--quiet",
        "-o", full)
    run(CLI, full, "--compact", "-o", tmp / "edit-compact.mcstat")
    c = mcstat.read(tmp / "edit-compact.mcstat")
    assert c.buffers_per_pixel is not None
    with pytest.raises(ValueError):
        c.buffers[0, 0, 0, 0] = 5.0
    with pytest.raises(ValueError):
        c.counts[0, 0, 0] = 1.0
    s = mcstat.read(full)
    s.buffers[0, 0, 0, 0] = 5.0
    mcstat.write(s, tmp / "edited.mcstat")
    assert mcstat.read(tmp / "edited.mcstat").buffers[0, 0, 0, 0] == 5.0
