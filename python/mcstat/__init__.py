"""mcstat from Python: statistics files (.mcstat) as numpy arrays, every registry operation and
the noise-aware comparison, each equal to the ``mcstat`` command line bit for bit
(docs/python.md).

    import mcstat
    s = mcstat.read("scene.mcstat")           # s.mean (H, W, 3), s.buffers (H, W, M, 3), ...
    img = mcstat.estimate(s, "gmon", mode="lum")  # (H, W, 3) float32, as `mcstat --gmon`
    r = mcstat.compare("a.mcstat", "b.mcstat", test="yuen")
    print(r.verdict, r.exit_code)

Only numpy arrays, dicts, lists, str and numbers cross the boundary: no OpenImageIO or pybind11
object is handed out, so the module mixes with OIIO's own bindings (pybind11 in 2.4, nanobind
from 3.2) and with OpenEXR's.
"""

import os
import numpy as np

from . import _mcstat
from ._mcstat import Error, __version__

__all__ = ["__version__", "Error", "Stats", "Image", "CompareResult", "read", "read_header", "blocks", "write",
           "ingest", "estimate", "operations", "compare"]


def _text(value):
    """A keyword argument as the command line's modifier text (core/params.h parses it)."""
    if isinstance(value, (bool, np.bool_)):
        return "1" if value else "0"
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, tuple):  # a size: (5, 5) -> "5x5"
        return "x".join(_text(v) for v in value)
    if isinstance(value, list):  # a list: [3, 5, 7] -> "3,5,7"
        return ",".join(_text(v) for v in value)
    return str(value)


def _params(kwargs):
    return {k: _text(v) for k, v in kwargs.items()}


def _aov_dict(channels, aov):
    """name -> view of the AOV array: channels named LAYER.X consecutively grouped as
    (H, W, M, n) under LAYER, any other channel (H, W, M) under its own name."""
    out = {}
    i = 0
    while aov is not None and i < len(channels):
        layer = channels[i].rpartition(".")[0]
        j = i + 1
        if layer:
            while j < len(channels) and channels[j].rpartition(".")[0] == layer:
                j += 1
            out[layer] = aov[..., i:j]
        else:
            out[channels[i]] = aov[..., i]
        i = j
    return out


class Stats:
    """A statistics image (a file read whole, an ingest, or one block of rows of a file).

    mean     (H, W, 3) float32   the plain mean of every sample (part beauty)
    buffers  (H, W, M, 3)        sub-buffer means; adaptive M and compact files: NaN where a
                                 pixel holds fewer than M buffers (buffers_per_pixel says how many)
    counts   (H, W, M)           samples per sub-buffer (0 where absent)
    buffers_per_pixel (H, W) int32, adaptive layouts only (None for fixed M)
    count    (H, W)              samples per pixel; variance (H, W, 3) their variance
    aovs     dict                AOV name -> (H, W, M, n) or (H, W, M) (aov_channels: every name)
    features dict                'N', 'P', 'Albedo' (H, W, 3), 'Z', 'A' (H, W): those the file holds
    header   dict                M, spp, seeds, color_space, width, height, data_window, ...

    For a fixed-M file the arrays are views of the image mcstat holds (no copy): writing into
    them changes what write() writes and what estimate() sees. Adaptive layouts' (and compact
    files') buffers, counts and AOVs are padded copies, read-only: an edit raises ValueError
    instead of being dropped by write().
    """

    def __init__(self, native, first_row=0):
        self._native = native
        self.name = native.name
        self.header = native.header
        self.first_row = first_row
        a = native.arrays()
        self.mean = a["mean"]
        self.buffers = a["buffers"]
        self.counts = a["counts"]
        self.buffers_per_pixel = a.get("buffers_per_pixel")
        self.count = a["count"]
        self.variance = a["variance"]
        self.spread = a["spread"]
        held = set(self.header["features"])
        self.features = {k: v for k, v in a["features"].items() if k in held and v is not None}
        self.aov_channels = [c["name"] for c in self.header["aovs"]]
        self.aov = a["aov"]
        if self.buffers_per_pixel is not None:
            # Adaptive and compact layouts: buffers, counts and AOVs are padded copies, which
            # write() and estimate() never see: read-only, so that an edit fails where it is made
            # instead of vanishing silently (issue 50).
            for arr in (self.buffers, self.counts, self.aov):
                if arr is not None:
                    arr.flags.writeable = False
        self.aovs = _aov_dict(self.aov_channels, self.aov)

    @property
    def M(self):
        return self.header["M"]

    @property
    def shape(self):
        return (self.header["height"], self.header["width"], self.header["M"])

    def __repr__(self):
        h = self.header
        return "<mcstat.Stats {} {}x{} M={} spp={}>".format(self.name, h["width"], h["height"],
                                                          h["M"], h["spp"])


class Image(np.ndarray):
    """An operation's result: the (H, W, 3) float32 R, G, B, with
    channels     every channel name of the result, as `mcstat FILE --OP -o out.exr` writes them
    all_channels (H, W, len(channels)): every channel
    diagnostics  name -> (H, W): gini, kept, excluded (diag=True), the maps of other operations
    aovs         name -> (H, W): the AOVs carried with the beauty's weights
    residual     name -> (H, W): mean - robust of R, G, B and the AOVs (residual=True), else {}
    ci_low, ci_high  name -> (H, W): the confidence interval's bounds of R, G, B (and of the AOVs
                 with ciaovs=True) when ci=LEVEL was given (docs/confidence.md), else {}
    removed      name -> (H, W): the removed-light layers Y, se, z, zlocal, significant
                 (removed=True, docs/removed-light.md), else {}
    A slice or a copy of the image keeps every one of these as it is: the whole image's layers.
    """

    def __array_finalize__(self, obj):
        for name, default in (("channels", None), ("all_channels", None), ("diagnostics", None),
                              ("aovs", None), ("residual", None), ("removed", None),
                              ("ci_low", None), ("ci_high", None)):
            setattr(self, name, getattr(obj, name, default))


def _image(channels, pixels, aov_names):
    img = np.ascontiguousarray(pixels[..., :3]).view(Image)
    img.channels = list(channels)
    img.all_channels = pixels
    img.diagnostics, img.aovs, img.residual, img.removed = {}, {}, {}, {}
    img.ci_low, img.ci_high = {}, {}
    aov_names = set(aov_names)
    for i, c in enumerate(channels[3:], start=3):
        if c.startswith("residual."):
            img.residual[c[len("residual."):]] = pixels[..., i]
        elif c.startswith("removed."):
            img.removed[c[len("removed."):]] = pixels[..., i]
        elif c.startswith("ci_low."):
            img.ci_low[c[len("ci_low."):]] = pixels[..., i]
        elif c.startswith("ci_high."):
            img.ci_high[c[len("ci_high."):]] = pixels[..., i]
        elif c in aov_names:
            img.aovs[c] = pixels[..., i]
        else:
            img.diagnostics[c] = pixels[..., i]
    return img


def _source(s):
    """A Stats' image, or a path (str, bytes or os.PathLike) to a statistics file. Anything else
    (an array, None, a number) is a TypeError naming its type, never a file name."""
    if isinstance(s, Stats):
        return s._native
    if isinstance(s, (str, bytes)) or hasattr(s, "__fspath__"):
        return os.fsdecode(os.fspath(s))
    raise TypeError("mcstat: expected a statistics file's path or a Stats, got {} (an image's "
                    "array is not a statistics file: mcstat.read(path) gives a Stats)".format(
                        type(s).__name__))


def read(path):
    """The statistics file `path` whole, validated (mcstat.Error with mcstat's one-line message)."""
    return Stats(_mcstat._read(_source(path)))


def read_header(path):
    """The headers only (cheap): the dict Stats.header holds."""
    return _mcstat._read_header(_source(path))


def blocks(path, rows=64):
    """Streams the statistics file `path` by blocks of `rows` rows (the last may be shorter):
    yields Stats of those rows only (first_row says where they start), so that memory follows
    the block and not the image."""
    reader = _mcstat._BlockReader(_source(path))
    height = reader.height
    rows = max(1, int(rows))
    for y in range(0, height, rows):
        yield Stats(reader.read(y, min(rows, height - y)), first_row=y)


def write(s, path):
    """Writes the Stats `s` as the statistics file `path` (atomically: a temporary file renamed),
    the same bytes `mcstat IN -o path` writes for the same image."""
    _mcstat._write(s._native, _source(path))


def ingest(paths, **modifiers):
    """Renders of one image, one EXR per seed, as a Stats (one sub-buffer per file): `mcstat
    --ingest:key=value PATTERN`. `paths`: a glob, a comma-separated list, or a list of either;
    modifiers: layer, spp, colorspace, aovs and the class overrides alpha, light, data, id."""
    if not isinstance(paths, str):
        paths = ",".join(str(p) for p in paths)
    return Stats(_mcstat._ingest(paths, _params(modifiers)))


def operations():
    """Every registry operation: name, title, help, its parameters (name, default, accepts)."""
    return _mcstat._operations()


def estimate(s, name="gmon", *, diag=False, residual=False, **params):
    """Registry operation `name` over `s` (a Stats, or a path: a file is streamed by blocks of
    rows; per-sample operations, those of input kind Samples, need the path) with its parameters as
    keyword arguments, parsed as `mcstat --NAME:key=value` parses them (True/False: 1/0, a tuple
    (5, 5): 5x5, a list: comma-separated). Returns an Image: (H, W, 3) R, G, B, with the AOVs, the
    diagnostics (diag=True), the residual (residual=True), the removed-light layers (removed=True,
    with removedradius and removedz: Y, se, z, zlocal, significant; docs/removed-light.md) and the
    confidence interval (ci=0.95, ciaovs=True for the AOVs' too: ci_low, ci_high) as attributes.
    keeplight=True (keeplightgamma, keeplightradius) gives the removed light back, all of it, where
    the evidence puts it (docs/keep-light.md).
    Equal to `mcstat FILE --NAME -o out.exr` bit for bit."""
    src = _source(s)
    header = s.header if isinstance(s, Stats) else read_header(src)
    channels, pixels = _mcstat._estimate(src, name, _params(params), bool(diag), bool(residual))
    return _image(channels, pixels, [c["name"] for c in header["aovs"]])


class CompareResult:
    """What `mcstat A B --compare` found: verdict (its line), fail, exit_code (0 same, 2
    different, as the command's), evidence (its lines), the counts (pixels, pixels_tested,
    pixels_differing, tiles, tiles_tested, tiles_differing, ...), identical, power (a dict: the
    smallest change of one tile and of one pixel, relative and absolute, found with probability
    0.8: tile_relative, tile_absolute, pixel_relative, pixel_absolute, probability; None where
    unknown), underpowered (minpower was not met), strongest and strongest_tile
    (dicts: x, y, quantity, a, b, p, z, difference, se) and maps (name -> (H, W): p, z, effect,
    differs, tile.p, tile.z, tile.differs, per quantity)."""

    def __init__(self, d):
        channels, pixels = d.pop("maps")
        self.maps = {c: pixels[..., i] for i, c in enumerate(channels)}
        self.__dict__.update(d)
        self.exit_code = 2 if self.fail else 0

    def __bool__(self):
        return not self.fail

    def __repr__(self):
        return "<mcstat.CompareResult {}>".format(self.verdict)


def compare(a, b, maps=None, **params):
    """Are the renders `a` and `b` (Stats or paths) the same image up to their noise? `mcstat A B
    --compare:key=value`: test ("welch", "yuen"), level, control, channels, aovs, tile, tol,
    reltol, equivalence, trim, minpower (fail unless a change of that fraction per tile would have
    been found), identical ("fail": two copies of one render fail); the reports junit=FILE, json=FILE, html=DIR and their name
    (docs/compare.md). maps=PATH writes the maps as an EXR (`-o maps.exr`). Returns a
    CompareResult."""
    return CompareResult(_mcstat._compare(_source(a), _source(b), _params(params),
                                          str(maps) if maps else ""))
