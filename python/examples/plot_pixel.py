#!/usr/bin/env python3
"""One pixel's sub-buffers, as a notebook would look at them (docs/python.md): the M sub-buffer
means of R, G and B (marker size: samples), against the plain mean, MoN and G-MoN of the pixel.

    PYTHONPATH=build/python python3 python/examples/plot_pixel.py scene.mcstat 120 80 -o pixel.png

Each "# %%" starts a cell (Jupyter, VS Code); run as a script it writes the plot to -o and prints
the pixel's buffers.
"""

# %% the file and the pixel
import argparse

import matplotlib

matplotlib.use("Agg")  # a file, no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import mcstat  # noqa: E402

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("file")
parser.add_argument("x", type=int)
parser.add_argument("y", type=int)
parser.add_argument("-o", "--output", default="pixel.png")
args = parser.parse_args()

s = mcstat.read(args.file)
x, y = args.x - s.header["data_window"]["x"], args.y - s.header["data_window"]["y"]

# %% the pixel's buffers and three estimates of it
buffers, counts = s.buffers[y, x], s.counts[y, x]  # (M, 3), (M,)
estimates = {name: mcstat.estimate(s, name)[y, x] for name in ("mean", "mon", "gmon")}
print("pixel ({}, {}) of {}: M = {}, {} samples".format(args.x, args.y, args.file, s.M,
                                                       int(counts.sum())))
for j, (b, n) in enumerate(zip(buffers, counts)):
    print("  buffer {:3d}  n {:5d}  R {!r}  G {!r}  B {!r}".format(j, int(n), *map(float, b)))
for name, v in estimates.items():
    print("  {:<10s}  R {!r}  G {!r}  B {!r}".format(name, *map(float, v)))

# %% the plot
fig, axes = plt.subplots(1, 3, figsize=(10, 3.2), sharey=False)
held = counts > 0
for c, (ax, channel) in enumerate(zip(axes, "RGB")):
    j = np.arange(s.M)[held]
    ax.scatter(j, buffers[held, c], s=8 + 40 * counts[held] / max(1, counts.max()), color="0.3",
               label="sub-buffers")
    for (name, v), style, color in zip(estimates.items(), ("-", "--", ":"), ("C0", "C1", "C3")):
        ax.axhline(v[c], linestyle=style, color=color, label=name)
    ax.set_title(channel)
    ax.set_xlabel("sub-buffer")
axes[0].legend(fontsize=7)
fig.suptitle("{} pixel ({}, {})".format(args.file, args.x, args.y), fontsize=9)
fig.tight_layout()
fig.savefig(args.output, dpi=80)
print("wrote", args.output)
