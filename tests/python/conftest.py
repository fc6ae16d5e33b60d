"""Fixtures of the mcstat Python module's tests (docs/python.md): small renders made once per
test file with the fixture renderer, and the command-line tool whose output the module must equal.
CTest runs each file with Debian's python3, PYTHONPATH=<build>/python and MCSTAT_BUILD_DIR."""

import os
import subprocess
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

BUILD = Path(os.environ.get("MCSTAT_BUILD_DIR", Path(__file__).resolve().parents[2] / "build"))
SOURCE = Path(__file__).resolve().parents[2]
CLI = BUILD / "oiiotool-ext" / "mcstat"
RENDER = BUILD / "render-fixture" / "mcstat-render"


def tool_env(**extra):
    """The environment for a program that loads none of our code into an uninstrumented process
    (bash scripts and their awk, chromium): without the sanitizer runtime the sanitizer build
    preloads into python3 (its executables carry their own). Under it, mawk's own heap overflow
    aborts the script."""
    env = {k: v for k, v in os.environ.items() if k != "LD_PRELOAD"}
    env.update({k: str(v) for k, v in extra.items()})
    return env


def run(*args, check=True):
    """Runs a command (str(args)); returns the CompletedProcess with text stdout/stderr."""
    p = subprocess.run([str(a) for a in args], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise AssertionError("{} failed ({}): {}".format(args, p.returncode, p.stderr))
    return p


def render(path, *args, scene="default", res=(40, 30), spp=64, M=8, seed=1):
    run(RENDER, "--scene", scene, "--res", res[0], res[1], "--spp", spp, "--M", M, "--seed", seed,
        "--quiet", *args, "-o", path)
    return path


def cli_error(*args):
    """The one line `mcstat ARGS` prints on stderr when it fails, without the "mcstat: " prefix."""
    p = run(CLI, *args, check=False)
    assert p.returncode == 1, (args, p.returncode, p.stdout, p.stderr)
    lines = [l for l in p.stderr.splitlines() if l.startswith("mcstat: ") and "note:" not in l
             and "warning:" not in l]
    assert len(lines) == 1, p.stderr
    return lines[0][len("mcstat: "):]


def read_exr(path):
    """channel name -> (H, W) float32 array of an image file, through OpenImageIO's reader (not
    its cache, which would keep an overwritten file's old pixels)."""
    inp = oiio.ImageInput.open(str(path))
    assert inp, oiio.geterror()
    px = inp.read_image(0, 0, 0, inp.spec().nchannels, oiio.FLOAT)
    names = inp.spec().channelnames
    inp.close()
    assert px is not None, path
    return {name: px[..., i] for i, name in enumerate(names)}


def assert_same_channels(result, cli_exr):
    """Every channel of an mcstat.Image equals the CLI's file's channel of that name, bit for bit
    (NaN where the CLI has NaN), and both have the same channels."""
    cli = read_exr(cli_exr)
    assert sorted(result.channels) == sorted(cli), (result.channels, list(cli))
    for i, name in enumerate(result.channels):
        a, b = result.all_channels[..., i], cli[name]
        assert a.shape == b.shape, name
        np.testing.assert_array_equal(a.view(np.uint32)[~np.isnan(a)],
                                      b.view(np.uint32)[~np.isnan(a)], err_msg=name)
        assert np.array_equal(np.isnan(a), np.isnan(b)), name


@pytest.fixture(scope="module")
def tmp(tmp_path_factory):
    return tmp_path_factory.mktemp("mcstat")
