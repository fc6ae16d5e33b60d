// Pictures for review tools (docs/review.md): heatmaps of one channel with a colour bar, and
// contact sheets assembled from already computed tiles. OIIO's two forms:
//   ImageBuf op(const Src&, ..., ROI roi = {}, int nthreads = 0)
//   bool     op(ImageBuf& dst, const Src&, ..., ROI roi = {}, int nthreads = 0)
// Errors are recorded on the returned / destination ImageBuf (has_error(), geterror()); nothing
// throws. Every result is display-referred (values meant for the screen as they are), RGB float.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <array>
#include <limits>
#include <string>
#include <vector>

#include "mcstat/analysis/metrics.h"

namespace mcstat {

/// Colour of NaN / Inf pixels in a heatmap (display-referred magenta): no colour map in OIIO
/// contains it, so a non-finite pixel is never mistaken for a value.
inline constexpr std::array<float, 3> kNonFiniteColor{1.f, 0.f, 1.f};
/// Font of every label: OIIO 2.4's default font lookup fails on Debian, DejaVu Sans is installed
/// with fonts-dejavu-core (scripts/install-deps.sh).
inline constexpr const char* kReviewFont = "DejaVuSans";

/// Text, colours and spacing shared by heatmaps, colour bars and contact sheets.
struct ReviewStyle {
    int fontSize = 14;  ///< nominal text height in pixels
    int margin = 8;     ///< space around and between tiles, in pixels
    std::array<float, 3> background{0.12f, 0.12f, 0.12f};
    std::array<float, 3> text{0.92f, 0.92f, 0.92f};
    /// Height of one line of text (baseline to baseline).
    int lineHeight() const { return fontSize + fontSize / 2; }
};

/// How values map to colours: value v -> position t in [0, 1] -> map(t).
struct ColorScale {
    std::string map = "inferno";  ///< an OIIO colour map name, or "cool-warm"
    double lo = 0.0, hi = 1.0;    ///< values at t = 0 and t = 1 (lo < hi; lo > 0 when log)
    bool log = false;             ///< t linear in log10(v) instead of v
    std::string label;            ///< what the colour bar says under its numbers
    long nonFinite = 0;           ///< NaN / Inf pixels in the mapped data (shown in the legend)
    /// +Inf at t = 1 and -Inf at t = 0, as the strongest values of their sign (a comparison's
    /// exact differences: z of a change without noise); `infinite` counts them, nonFinite the rest.
    bool infiniteAtEnds = false;
    long infinite = 0;
    /// A 0/1 mask (every finite value 0 or 1, range [0, 1], linear): the legend is two swatches,
    /// the colours of 0 and 1 named by binaryNames, instead of a gradient with numbers.
    bool binary = false;
    std::array<std::string, 2> binaryNames{"0", "1"};
};

/// Position of `v` on the scale, clamped to [0, 1] (a log scale sends v <= 0 to 0); NaN when v is
/// NaN or Inf (with scale.infiniteAtEnds, +Inf is 1 and -Inf 0).
double colorScalePosition(const ColorScale& scale, double v);

/// What a heatmap shows and how.
struct HeatmapOptions {
    std::string channel;          ///< channel name; empty: "relerr" if present, else the first
    std::string map = "inferno";  ///< OIIO colour map name, or "cool-warm" (diverging)
    /// Range: NaN means the data range over the finite values (on a log scale: the positive ones).
    double min = std::numeric_limits<double>::quiet_NaN();
    double max = std::numeric_limits<double>::quiet_NaN();
    /// -1: log10 scale for channels named "relerr*" (errors span decades), linear otherwise.
    int log = -1;
    /// A default range (min and max unset) symmetric about 0, [-m, m] with m the largest finite
    /// |value|: signed data (effects, z-scores) with a diverging map keep 0 in the middle.
    bool symmetric = false;
    /// ColorScale::infiniteAtEnds: +Inf and -Inf drawn in the colours of the scale's ends (the
    /// strongest of their sign), not as non-finite; the legend says so.
    bool infiniteAtEnds = false;
    int scale = 1;         ///< integer upscaling of the map (nearest pixel), 1..64
    bool colorBar = true;  ///< false: only the mapped pixels (a contact-sheet tile)
    /// Text drawn above the map (e.g. a comparison's verdict, or provenanceCaption), wrapped to the
    /// picture's width: a newline marks where a line may break first (its clauses are packed onto
    /// lines as they fit), then spaces.
    std::string caption;
    int minBarWidth = 256;  ///< the colour bar is at least this wide (room for its numbers)
    ReviewStyle style;
};

/// Resolves the channel and the range of a heatmap of `src` within `roi` (default: src's data
/// window): `channel` its index, `scale` the map, range (defaults from the data, an empty range
/// widened: linear to [v, v + 1], log to [v, 10 v]), log flag, label and non-finite count. A
/// binary channel (every finite value 0 or 1; a channel with no finite value when it is named
/// firefly or differs) gets scale.binary, range [0, 1] and linear, unless opt asks for a log
/// scale or a range other than [0, 1]; the names of 0 and 1 are binaryNames(channel). False with
/// `err` for an unknown channel or map, or a bad range.
bool resolveColorScale(const OIIO::ImageBuf& src, const HeatmapOptions& opt, int& channel,
                       ColorScale& scale, std::string& err, OIIO::ROI roi = {});

/// What 0 and 1 mean in a 0/1 mask named `channel` (any layer or component: "firefly",
/// "tile.differs.R"): "no firefly" / "firefly", "same" / "differs"; otherwise "0" / "1".
std::array<std::string, 2> binaryNames(const std::string& channel);

/// A horizontal colour bar `width` pixels wide: the gradient of `scale.map` from scale.lo (left) to
/// scale.hi (right), tick marks and numbers under it, and scale.label (plus a magenta swatch when
/// scale.nonFinite > 0). Column i of the gradient shows t = (i + 0.5) / width. Spec attributes
/// mcstat:colorbar:x, y, width, height give the gradient's rectangle in dst.
/// For scale.binary, a legend instead: two swatches, the colours of t = 0 and t = 1 (as the
/// heatmap's pixels of value 0 and 1 have them), each followed by "0 = name" / "1 = name", then
/// the label; the same height. Spec attributes mcstat:legend:binary = 1 and
/// mcstat:legend:swatch0:x, y, width, height (and swatch1) instead of mcstat:colorbar:*.
bool colorBar(OIIO::ImageBuf& dst, int width, const ColorScale& scale,
              const ReviewStyle& style = {});
OIIO::ImageBuf colorBar(int width, const ColorScale& scale, const ReviewStyle& style = {});

/// Heatmap of one channel of `src` within `roi`: color_map of the position on the resolved scale,
/// through the OCIO display view (OIIO's maps are scene-linear; the built-in config's view gives
/// their published sRGB values), NaN / Inf pixels kNonFiniteColor, upscaled `opt.scale` times,
/// with a colour bar (a binary channel: its two-swatch legend) under it unless opt.colorBar is
/// false and opt.caption above it. Spec attributes:
/// mcstat:heatmap:channel, map, min, max, log, binary, nonFinite, scale, caption (when there is
/// one, newlines as spaces), infinite (with opt.infiniteAtEnds: the ±Inf pixels at the ends);
/// mcstat:heatmap:x, y, width, height (the map's rectangle) and mcstat:colorbar:x, y, width, height
/// (the gradient's) or mcstat:legend:swatch0/1:x, y, width, height (a binary channel's swatches),
/// in dst's pixel coordinates.
bool heatmap(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const HeatmapOptions& opt,
             OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf heatmap(const OIIO::ImageBuf& src, const HeatmapOptions& opt, OIIO::ROI roi = {},
                       int nthreads = 0);

/// What a picture of an image with `spec`'s provenance shows, as a caption: the operation that
/// made it (its registry title and mcstat.parameters), `file` (the statistics file or image it
/// came from; may be empty), the samples (mcstat.M, mcstat.spp, the count of mcstat.sources) and,
/// for an error map, the reference (mcstat.errormap.reference, its file name), one clause per
/// line (HeatmapOptions::caption packs them): "G-MoN (mode=lum)\nof scene.mcstat\n(M = 21, 1000
/// spp)\nvs reference-65536spp.exr". Without provenance: "of FILE"; without either: empty.
std::string provenanceCaption(const OIIO::ImageSpec& spec, const std::string& file);

/// Per-pixel error of the R, G, B (first three channels) of `img` against those of `ref` (same
/// size; pixels paired by their place in each data window, as diffImages pairs them), within `roi`
/// (default: img's data window): channels "relerr" and "firefly" from errorMap (metrics.h), NaN
/// where a value of either pixel is NaN or Inf. Spec attributes mcstat:errormap:eps, ratio, floor,
/// and img's provenance (its "mcstat." attributes: what the error is of).
bool errorImage(OIIO::ImageBuf& dst, const OIIO::ImageBuf& img, const OIIO::ImageBuf& ref,
                const DiffOptions& opt, OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf errorImage(const OIIO::ImageBuf& img, const OIIO::ImageBuf& ref,
                          const DiffOptions& opt, OIIO::ROI roi = {}, int nthreads = 0);

/// One tile of a contact sheet.
struct SheetTile {
    OIIO::ImageBuf image;            ///< display-referred RGB (the first three channels are used)
    std::string title;               ///< drawn above the tile
    std::vector<std::string> lines;  ///< drawn under the tile, one per line
    OIIO::ImageBuf footer;  ///< optional display-referred strip under the lines (a colour bar)
};

struct SheetOptions {
    int scale = 1;  ///< integer upscaling of every tile (nearest pixel), 1..64
    ReviewStyle style;
};

/// Tiles in one row, each upscaled opt.scale times and clamped to [0, 1], with its title above
/// and its lines (and footer) below; every tile must have the same size. Width
/// n * (w * scale) + (n + 1) * margin; height margin + lineHeight (titles) + h * scale +
/// margin / 2 + label strip + margin, the label strip as tall as the tallest tile's lines (one
/// lineHeight each) plus, for a footer, margin / 2 (after lines) and the footer's height. `roi`
/// crops the sheet (default: all of it). Spec attributes: mcstat:sheet:tiles, scale, tileWidth,
/// tileHeight (scaled); mcstat:tile<i>:x, y (i from 1) the top-left corner of tile i's pixels.
bool contactSheet(OIIO::ImageBuf& dst, const std::vector<SheetTile>& tiles, const SheetOptions& opt,
                  OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf contactSheet(const std::vector<SheetTile>& tiles, const SheetOptions& opt,
                            OIIO::ROI roi = {}, int nthreads = 0);

/// Integer upscaling that makes an image `width` pixels wide at least `minWidth` wide (at most 64).
int defaultReviewScale(int width, int minWidth = 256);

}  // namespace mcstat
