"""python/examples/plot_pixel.py runs and plots what the file holds."""

import subprocess
import sys

import OpenImageIO as oiio

import mcstat
from conftest import SOURCE, render


def test_plot_pixel_example(tmp):
    path = render(tmp / "scene.mcstat", res=(32, 24), spp=64, M=8)
    out = tmp / "pixel.png"
    p = subprocess.run([sys.executable, str(SOURCE / "python/examples/plot_pixel.py"), str(path),
                        "16", "12", "-o", str(out)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    spec = oiio.ImageInput.open(str(out)).spec()
    assert spec.width == 800 and spec.height == 256
    s = mcstat.read(path)
    lines = [l.split() for l in p.stdout.splitlines() if l.strip().startswith("buffer")]
    assert len(lines) == 8
    for j, l in enumerate(lines):  # the buffers' values printed exactly
        assert [float(l[5]), float(l[7]), float(l[9])] == [float(v) for v in s.buffers[12, 16, j]]
    gmon = float(mcstat.estimate(s, "gmon")[12, 16, 0])
    assert any(l.split()[0] == "gmon" and float(l.split()[2]) == gmon
               for l in p.stdout.splitlines()[1:] if l.strip())
