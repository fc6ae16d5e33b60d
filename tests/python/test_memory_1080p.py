"""Reading a 1920 x 1080 file with M = 21 costs its arrays plus at most 10 %: the module reads
into the image it hands out as numpy views, never into a copy. Measured in a fresh process:
the peak resident set (getrusage) against the resident set before the read."""

import os
import subprocess
import sys

from conftest import render

PROBE = r"""
import resource, sys
import mcstat
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize()
before = rss()
s = mcstat.read(sys.argv[1])
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
a = s._native.arrays()
arrays = [v for v in list(a.values()) + list(a["features"].values()) if hasattr(v, "nbytes")]
print(sum(v.nbytes for v in arrays), peak - before, s.buffers.shape)
"""


def test_1080p_read_peak_memory(tmp):
    # One sample per pixel: 20 of the 21 buffers are empty, but a full file holds every buffer of
    # every pixel (the reader sizes its arrays from the header, never from the content), so the
    # arrays and the read are those of a 21-spp file, and the render, most of this test's time
    # (116 s under the sanitizers), takes 2.8 s instead of 18 s. The file compresses to 56 MB
    # (320 MB at 21 spp): only the compressed chunks read per block are smaller.
    path = render(tmp / "1080p.mcstat", res=(1920, 1080), spp=1, M=21)
    p = subprocess.run([sys.executable, "-c", PROBE, str(path)], capture_output=True, text=True)
    path.unlink()
    assert p.returncode == 0, p.stderr
    arrays, grown, shape = p.stdout.split(" ", 2)
    arrays, grown = int(arrays), int(grown)
    assert shape.strip() == "(1080, 1920, 21, 3)"
    assert arrays > 21 * 1920 * 1080 * 16  # the buffers' means and counts at least
    print("arrays {:.1f} MB, peak growth {:.1f} MB ({:+.1f} %)".format(
        arrays / 1e6, grown / 1e6, 100.0 * (grown - arrays) / arrays))
    # Under the sanitizer build (python3 started with the ASan runtime preloaded) the resident set
    # also holds ASan's shadow: one byte for every 8 the program touches.
    shadow = arrays / 8 if "asan" in os.environ.get("LD_PRELOAD", "") else 0
    assert grown <= 1.10 * arrays + shadow
