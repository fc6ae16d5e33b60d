// Pictures for review tools: heatmaps with a colour bar and contact sheets
// (include/mcstat/review/review_pictures.h, docs/review.md). Everything drawn goes through
// ImageBufAlgo (color_map, render_text, fill, paste, resample); the only pixels written by hand are
// data: the positions on the colour scale that color_map turns into colours, and the non-finite
// mask.
#include "mcstat/review/review_pictures.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imagebufalgo_util.h>
#include <OpenImageIO/strutil.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "mcstat/core/untrusted_text.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/review/display.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;
using OIIO::TypeDesc;
namespace IBA = OIIO::ImageBufAlgo;
using OIIO::Strutil::fmt::format;

namespace {

constexpr int kMaxScale = 64;
// A sheet or heatmap larger than this is a mistake (a huge :scale=), not a picture.
constexpr long long kMaxCanvasPixels = 1LL << 28;

ImageBuf canvas(int w, int h, const std::array<float, 3>& bg) {
    ImageBuf c(ImageSpec(w, h, 3, TypeDesc::FLOAT));
    IBA::fill(c, bg);
    return c;
}

/// Distance from the top of a line of text to its baseline (DejaVu Sans' ascent is 0.76 em).
int ascent(const ReviewStyle& st) { return int(std::lround(0.8 * st.fontSize)); }

int textWidth(const std::string& text, int fontSize) {
    if (text.empty()) return 0;
    const ROI r = IBA::text_size(text, fontSize, kReviewFont);
    // An empty box (e.g. only spaces) comes back as begin > end, near INT_MAX and INT_MIN.
    if (!r.defined() || r.xend <= r.xbegin) return 0;
    return r.xend - r.xbegin;
}

/// `text`, shortened with "..." until it is at most `width` pixels wide, so a long file name does
/// not run into the next tile.
std::string fitText(const std::string& text, int width, int fontSize) {
    if (textWidth(text, fontSize) <= width) return text;
    std::string s = text;
    while (!s.empty()) {
        s.pop_back();
        if (textWidth(s + "...", fontSize) <= width) return s + "...";
    }
    return "";
}

/// `text` broken at spaces into lines at most `width` pixels wide (a word wider than that is cut
/// with "..."); empty text gives no lines.
std::vector<std::string> wrapWords(const std::string& text, int width, int fontSize) {
    std::vector<std::string> lines;
    std::string line;
    for (const std::string& word : OIIO::Strutil::splits(text, " ")) {
        if (word.empty()) continue;
        const std::string longer = line.empty() ? word : line + " " + word;
        if (line.empty() || textWidth(longer, fontSize) <= width) {
            line = longer;
            continue;
        }
        lines.push_back(fitText(line, width, fontSize));
        line = word;
    }
    if (!line.empty()) lines.push_back(fitText(line, width, fontSize));
    return lines;
}

/// `text` in lines at most `width` pixels wide, broken preferably where it has a newline: its
/// newline-separated clauses are packed onto lines (joined by a space) as long as they fit, and a
/// clause wider than a line is broken at its spaces (wrapWords).
std::vector<std::string> wrapText(const std::string& text, int width, int fontSize) {
    std::vector<std::string> lines;
    std::string line;
    for (const std::string& clause : OIIO::Strutil::splits(text, "\n")) {
        if (clause.empty()) continue;
        const std::string longer = line.empty() ? clause : line + " " + clause;
        if (textWidth(longer, fontSize) <= width) {
            line = longer;
            continue;
        }
        if (!line.empty()) lines.push_back(line);
        line.clear();
        std::vector<std::string> parts = wrapWords(clause, width, fontSize);
        if (parts.empty()) continue;
        line = parts.back();  // the clause's last line may take the next clause
        parts.pop_back();
        lines.insert(lines.end(), parts.begin(), parts.end());
    }
    if (!line.empty()) lines.push_back(line);
    return lines;
}

/// Draws `text` with its top at `top` (baseline at top + ascent) and its left edge at `x`.
bool drawText(ImageBuf& dst, int x, int top, const std::string& text, const ReviewStyle& st) {
    if (text.empty()) return true;
    return IBA::render_text(dst, x, top + ascent(st), text, st.fontSize, kReviewFont, st.text);
}

/// The RGB of `src` within `roi`, moved to origin (0, 0) with the full window equal to the data
/// window, so that resample maps pixel to pixel.
bool cutRGB(ImageBuf& dst, const ImageBuf& src, ROI roi, int nthreads) {
    if (src.nchannels() < 3) {
        dst.errorfmt("needs R, G, B channels; the image has {}", src.nchannels());
        return false;
    }
    roi.chbegin = 0;
    roi.chend = 3;
    if (!IBA::cut(dst, src, roi, nthreads)) return false;
    return true;
}

/// Integer nearest-pixel upscaling (ImageBufAlgo::resample without interpolation: every source
/// pixel becomes an s x s block of the same value).
bool upscale(ImageBuf& dst, const ImageBuf& src, int s, int nthreads) {
    if (s == 1) return dst.copy(src);
    const ImageSpec& in = src.spec();
    dst.reset(floatSpec(ROI(0, in.width * s, 0, in.height * s), in.channelnames));
    return IBA::resample(dst, src, false, {}, nthreads);
}

bool checkCanvas(ImageBuf& dst, long long w, long long h, const char* what) {
    if (w <= 0 || h <= 0 || w * h > kMaxCanvasPixels) {
        dst.errorfmt("{}: {} x {} pixels is too large (at most {} pixels; lower :scale=)", what, w,
                     h, kMaxCanvasPixels);
        return false;
    }
    return true;
}

/// Tick values of a scale: decades on a log scale, 1-2-5 steps on a linear one; the two ends (and
/// the one such value between them, if any) when fewer than two fall inside.
std::vector<double> tickValues(const ColorScale& s) {
    std::vector<double> v;
    if (s.log) {
        const double a = std::log10(s.lo), b = std::log10(s.hi);
        const int k0 = int(std::ceil(a - 1e-9)), k1 = int(std::floor(b + 1e-9));
        const int n = k1 - k0 + 1;
        const int step = std::max(1, (n + 5) / 6);  // at most about six decades labelled
        for (int k = k0; k <= k1; k += step) v.push_back(std::pow(10.0, k));
    } else {
        const double raw = (s.hi - s.lo) / 5.0;
        const double mag = std::pow(10.0, std::floor(std::log10(raw)));
        const double f = raw / mag;
        const double step = (f < 1.5 ? 1.0 : f < 3.5 ? 2.0 : f < 7.5 ? 5.0 : 10.0) * mag;
        for (double k = std::ceil(s.lo / step - 1e-9); k * step <= s.hi + 1e-9 * step; k += 1.0)
            v.push_back(std::abs(k) < 0.5 ? 0.0 : k * step);
    }
    if (v.size() < 2) {  // the ends, and the one value inside if there is one
        std::vector<double> ends = {s.lo};
        for (double x : v)
            if (x > s.lo && x < s.hi) ends.push_back(x);
        ends.push_back(s.hi);
        v = ends;
    }
    return v;
}

std::string tickLabel(double v) { return format("{:.3g}", v); }

/// OIIO's colour maps plus "cool-warm", a diverging map with a neutral grey at its middle
/// (Moreland, "Diverging Color Maps for Scientific Visualization", ISVC 2009: its end points and a
/// grey centre, as scene-linear knots) for signed data such as --compare's z-scores: OIIO's
/// "blue-red" is purple at 0, where nothing happened.
bool colorMap(ImageBuf& dst, const ImageBuf& src, const std::string& map, int nthreads = 0) {
    if (map == "cool-warm") {
        static const float knots[] = {0.0437f, 0.0730f, 0.527f,   0.723f, 0.723f,
                                      0.723f,  0.456f,  0.00121f, 0.0194f};
        return IBA::color_map(dst, src, 0, 3, 3, knots, {}, nthreads);
    }
    return IBA::color_map(dst, src, 0, map, {}, nthreads);
}

bool knownMap(const std::string& map) {
    ImageBuf one(ImageSpec(1, 1, 1, TypeDesc::FLOAT));
    IBA::zero(one);
    ImageBuf out;
    const bool ok = colorMap(out, one, map);
    (void)out.geterror();  // consumed: an unknown name is reported by the caller
    return ok;
}

}  // namespace

std::array<std::string, 2> binaryNames(const std::string& channel) {
    for (const std::string& part : OIIO::Strutil::splits(channel, ".")) {
        if (part == "firefly") return {"no firefly", "firefly"};
        if (part == "differs") return {"same", "differs"};
    }
    return {"0", "1"};
}

int defaultReviewScale(int width, int minWidth) {
    if (width <= 0) return 1;
    return std::clamp((minWidth + width - 1) / width, 1, kMaxScale);
}

double colorScalePosition(const ColorScale& s, double v) {
    if (s.infiniteAtEnds && std::isinf(v)) return v > 0.0 ? 1.0 : 0.0;
    if (!std::isfinite(v)) return std::numeric_limits<double>::quiet_NaN();
    double t;
    if (s.log)
        t = v > 0.0 ? (std::log10(v) - std::log10(s.lo)) / (std::log10(s.hi) - std::log10(s.lo))
                    : 0.0;
    else
        t = (v - s.lo) / (s.hi - s.lo);
    return std::clamp(t, 0.0, 1.0);
}

namespace {

/// The channel a heatmap draws (opt.channel, else relerr when there is one, else the first) and
/// a known colour map, or false with `err`.
bool heatmapChannel(const ImageSpec& spec, const HeatmapOptions& opt, int& channel,
                    std::string& err) {
    if (spec.nchannels < 1) {
        err = "the image has no channels";
        return false;
    }
    if (opt.channel.empty()) {
        // relerr when there is one: OpenEXR stores channels sorted by name, so an error map read
        // back from a file starts with "firefly".
        channel = std::max(0, spec.channelindex("relerr"));
    } else {
        channel = spec.channelindex(opt.channel);
        if (channel < 0) {
            err = format("no channel '{}' (channels: {})", printable(opt.channel),
                         printableList(spec.channelnames));
            return false;
        }
    }
    if (!knownMap(opt.map)) {
        err = format(
            "unknown colour map '{}' (known: inferno, viridis, magma, plasma, turbo, blue-red, "
            "spectrum, heat, and cool-warm, diverging)",
            opt.map);
        return false;
    }
    return true;
}

}  // namespace

bool resolveColorScale(const ImageBuf& src, const HeatmapOptions& opt, int& channel,
                       ColorScale& scale, std::string& err, ROI roi) {
    const ImageSpec& spec = src.spec();
    if (!heatmapChannel(spec, opt, channel, err)) return false;
    const std::string name = spec.channel_name(channel);
    ColorScale s;
    s.map = opt.map;
    s.infiniteAtEnds = opt.infiniteAtEnds;
    // Errors span decades: a linear relerr map would show one firefly and black elsewhere.
    s.log = opt.log < 0 ? OIIO::Strutil::starts_with(name, "relerr") : opt.log != 0;
    roi = prepareRoi(roi, src.roi());
    std::vector<float> v(roi.npixels());
    if (!v.empty() &&
        !src.get_pixels(ROI(roi.xbegin, roi.xend, roi.ybegin, roi.yend, 0, 1, channel, channel + 1),
                        TypeDesc::FLOAT, v.data())) {
        err = src.geterror();
        return false;
    }
    double lo = INFINITY, hi = -INFINITY;
    bool zeroOne = true;  // every finite value 0 or 1: a mask
    for (float x : v) {
        if (!std::isfinite(x)) {
            ++(s.infiniteAtEnds && std::isinf(x) ? s.infinite : s.nonFinite);
            continue;
        }
        zeroOne = zeroOne && (x == 0.f || x == 1.f);
        if (s.log && !(x > 0.f)) continue;  // zeros sit at the bottom of a log scale
        lo = std::min(lo, double(x));
        hi = std::max(hi, double(x));
    }
    if (lo > hi) {  // no usable value: an arbitrary range, so the bar still has numbers
        lo = s.log ? 1.0 : 0.0;
        hi = s.log ? 10.0 : 1.0;
    }
    const bool userMin = !std::isnan(opt.min), userMax = !std::isnan(opt.max);
    // A 0/1 mask (a firefly mask, --compare's differs) has two values, not a range: [0, 1] on a
    // linear scale, shown with a two-swatch legend, unless a log scale or another range is asked.
    const std::array<std::string, 2> names = binaryNames(name);
    const bool named = names[1] != "1";
    const bool anyFinite = s.nonFinite + s.infinite < long(v.size());
    if ((anyFinite ? zeroOne : named) && opt.log != 1 && (!userMin || opt.min == 0.0) &&
        (!userMax || opt.max == 1.0)) {
        s.binary = true;
        s.binaryNames = names;
        s.log = false;
        s.lo = 0.0;
        s.hi = 1.0;
        s.label = printable(name);
        scale = s;
        return true;
    }
    if (opt.symmetric && !s.log && lo <= hi) {
        const double m = std::max(std::fabs(lo), std::fabs(hi));
        lo = -m;
        hi = m;
    }
    if (userMin) lo = opt.min;
    if (userMax) hi = opt.max;
    if (!std::isfinite(lo) || !std::isfinite(hi)) {
        err = "min and max must be finite";
        return false;
    }
    if (hi <= lo) {
        if (userMin && userMax) {
            err = format("min ({}) must be below max ({})", lo, hi);
            return false;
        }
        if (!userMax)
            hi = s.log ? lo * 10.0 : lo + 1.0;
        else
            lo = s.log ? hi / 10.0 : hi - 1.0;
    }
    if (s.log && !(lo > 0.0)) {
        err = format("a log scale needs min > 0, not {}", lo);
        return false;
    }
    s.lo = lo;
    s.hi = hi;
    s.label = s.log ? printable(name) + " (log scale)" : printable(name);
    if (s.infinite > 0) s.label += format(" ({} px exact, no noise: at the ends)", s.infinite);
    scale = s;
    return true;
}

namespace {

/// The colour bar's label at `top`, and after it, when the data has NaN / Inf, a magenta swatch
/// and their pixel count.
bool drawScaleLabel(ImageBuf& out, int width, int top, const ColorScale& scale,
                    const ReviewStyle& st) {
    const std::string label = fitText(scale.label, width, st.fontSize);
    if (!drawText(out, 0, top, label, st)) return false;
    if (scale.nonFinite > 0) {
        const int sw = std::max(6, st.fontSize * 3 / 4);
        const int x = textWidth(label, st.fontSize) + st.fontSize;
        if (x + sw < width) {
            const int y = top + ascent(st) - sw;
            IBA::fill(out, kNonFiniteColor, ROI(x, x + sw, y, y + sw));
            const std::string what = fitText(
                format("{}: {} px", scale.infiniteAtEnds ? "NaN" : "NaN/Inf", scale.nonFinite),
                width - (x + sw + 4), st.fontSize);
            if (!drawText(out, x + sw + 4, top, what, st)) return false;
        }
    }
    return true;
}

/// A 0/1 mask's legend, as tall as a colour bar: two swatches in the colours the heatmap gives 0
/// and 1 (t = 0 and t = 1 through the same colour map and display view), each followed by its
/// name, and the label under them.
bool binaryLegend(ImageBuf& dst, int width, const ColorScale& scale, const ReviewStyle& st) {
    const int barH = std::max(10, st.fontSize), tickH = 4, lineH = st.lineHeight();
    const int height = barH + tickH + 2 * lineH + 2;
    ImageBuf out = canvas(width, height, st.background);
    ImageBuf t(ImageSpec(2, 1, 1, TypeDesc::FLOAT)), mapped, disp;
    const float ends[2] = {0.f, 1.f};
    t.set_pixels(t.roi(), TypeDesc::FLOAT, ends);
    if (!colorMap(mapped, t, scale.map) || !displayTransform(disp, mapped)) {
        dst.errorfmt("legend: {}{}", mapped.geterror(), disp.geterror());
        return false;
    }
    ImageSpec& spec = out.specmod();
    const int sw = 2 * barH, gap = 4;
    int x = 0;
    for (int i = 0; i < 2 && x + sw <= width; ++i) {
        std::array<float, 3> c{};
        disp.getpixel(i, 0, c.data(), 3);
        // A frame in the text colour, so a swatch as dark as the background still shows.
        IBA::fill(out, st.text, ROI(x, x + sw, 0, barH));
        IBA::fill(out, c, ROI(x + 1, x + sw - 1, 1, barH - 1));
        const std::string p = format("mcstat:legend:swatch{}:", i);
        spec.attribute(p + "x", x + 1);
        spec.attribute(p + "y", 1);
        spec.attribute(p + "width", sw - 2);
        spec.attribute(p + "height", barH - 2);
        const std::string& n = scale.binaryNames[size_t(i)];
        const std::string text = fitText(n == std::to_string(i) ? n : format("{} = {}", i, n),
                                         std::max(0, width - (x + sw + gap)), st.fontSize);
        if (!drawText(out, x + sw + gap, (barH - st.fontSize) / 2, text, st)) {
            dst.errorfmt("legend: {}", out.geterror());
            return false;
        }
        x += sw + gap + textWidth(text, st.fontSize) + 2 * st.fontSize;
    }
    if (!drawScaleLabel(out, width, barH + tickH, scale, st)) {
        dst.errorfmt("legend: {}", out.geterror());
        return false;
    }
    spec.attribute("mcstat:legend:binary", 1);
    dst = std::move(out);
    return true;
}

}  // namespace

bool colorBar(ImageBuf& dst, int width, const ColorScale& scale, const ReviewStyle& st) {
    if (width < 2 || width > 1 << 16) {
        dst.errorfmt("colour bar: width {} out of range", width);
        return false;
    }
    if (scale.binary) return binaryLegend(dst, width, scale, st);
    const int barH = std::max(10, st.fontSize), tickH = 4, lineH = st.lineHeight();
    const int height = barH + tickH + 2 * lineH + 2;
    ImageBuf out = canvas(width, height, st.background);

    // The gradient: column i holds t = (i + 0.5) / width, colour-mapped like the heatmap's pixels.
    ImageBuf t(ImageSpec(width, barH, 1, TypeDesc::FLOAT));
    {
        std::vector<float> row(size_t(width) * size_t(barH));
        for (int y = 0; y < barH; ++y)
            for (int x = 0; x < width; ++x) row[size_t(y) * width + x] = (float(x) + 0.5f) / width;
        t.set_pixels(t.roi(), TypeDesc::FLOAT, row.data());
    }
    ImageBuf mapped, disp;
    if (!colorMap(mapped, t, scale.map)) {
        dst.errorfmt("colour bar: {}", mapped.geterror());
        return false;
    }
    if (!displayTransform(disp, mapped)) {
        dst.errorfmt("colour bar: {}", disp.geterror());
        return false;
    }
    if (!IBA::paste(out, 0, 0, 0, 0, disp)) {
        dst.errorfmt("colour bar: {}", out.geterror());
        return false;
    }

    // Ticks and numbers; a label that would overlap the previous one is left out.
    int prevRight = -1000000;
    for (double v : tickValues(scale)) {
        const double pos = colorScalePosition(scale, v);
        const int x = std::clamp(int(std::lround(pos * width)), 0, width - 1);
        IBA::fill(out, st.text, ROI(x, x + 1, barH, barH + tickH));
        const std::string label = tickLabel(v);
        const int w = textWidth(label, st.fontSize);
        const int left = std::clamp(x - w / 2, 0, std::max(0, width - w));
        if (left < prevRight + st.fontSize / 2) continue;
        if (!drawText(out, left, barH + tickH, label, st)) {
            dst.errorfmt("colour bar: {}", out.geterror());
            return false;
        }
        prevRight = left + w;
    }
    // The label, and the legend of the non-finite colour after it.
    if (!drawScaleLabel(out, width, barH + tickH + lineH, scale, st)) {
        dst.errorfmt("colour bar: {}", out.geterror());
        return false;
    }
    ImageSpec& spec = out.specmod();
    spec.attribute("mcstat:colorbar:x", 0);
    spec.attribute("mcstat:colorbar:y", 0);
    spec.attribute("mcstat:colorbar:width", width);
    spec.attribute("mcstat:colorbar:height", barH);
    dst = std::move(out);
    return true;
}

ImageBuf colorBar(int width, const ColorScale& scale, const ReviewStyle& style) {
    ImageBuf dst;
    colorBar(dst, width, scale, style);
    return dst;
}

namespace {

/// The heatmap's pixels, one per pixel of `roi`: channel `ch` of `src` colour-mapped on `cs` and
/// made display-referred, a non-finite value in kNonFiniteColor. False with `err`.
bool heatmapPixels(ImageBuf& map, const ImageBuf& src, ROI roi, int ch, const ColorScale& cs,
                   int nthreads, std::string& err) {
    const int w = roi.width(), h = roi.height();
    // Data: each pixel's position on the scale, and which pixels are NaN / Inf (3 channels, to
    // mask the RGB below).
    std::vector<float> v(size_t(w) * size_t(h));
    if (!src.get_pixels(ROI(roi.xbegin, roi.xend, roi.ybegin, roi.yend, 0, 1, ch, ch + 1),
                        TypeDesc::FLOAT, v.data())) {
        err = src.geterror();
        return false;
    }
    std::vector<float> tv(v.size()), nfv(v.size() * 3), keepv(v.size() * 3);
    for (size_t p = 0; p < v.size(); ++p) {
        const double t = colorScalePosition(cs, v[p]);
        const bool bad = std::isnan(t);
        tv[p] = bad ? 0.f : float(t);
        for (int c = 0; c < 3; ++c) {
            nfv[p * 3 + c] = bad ? 1.f : 0.f;
            keepv[p * 3 + c] = bad ? 0.f : 1.f;
        }
    }
    ImageBuf t(ImageSpec(w, h, 1, TypeDesc::FLOAT)), nf(ImageSpec(w, h, 3, TypeDesc::FLOAT)),
        keep(ImageSpec(w, h, 3, TypeDesc::FLOAT));
    t.set_pixels(t.roi(), TypeDesc::FLOAT, tv.data());
    nf.set_pixels(nf.roi(), TypeDesc::FLOAT, nfv.data());
    keep.set_pixels(keep.roi(), TypeDesc::FLOAT, keepv.data());

    // OIIO's colour maps are scene-linear; the display view makes them display-referred (with the
    // built-in config, the maps' published sRGB values), as the contact sheet's image tiles are.
    ImageBuf mapped, disp, magenta;
    if (!colorMap(mapped, t, cs.map, nthreads) || !displayTransform(disp, mapped) ||
        !IBA::mul(magenta, nf, OIIO::cspan<float>(kNonFiniteColor), {}, nthreads) ||
        !IBA::mad(map, disp, keep, magenta, {}, nthreads)) {
        err = mapped.geterror() + disp.geterror() + magenta.geterror() + map.geterror();
        return false;
    }
    return true;
}

/// A heatmap's picture and where its parts are: the map, and the colour bar (or binary legend).
struct HeatmapLayout {
    ImageBuf out, bar;
    int mapX = 0, mapY = 0, barX = 0, barY = 0, barH = 0;
};

/// Lays out the picture: the scaled map (mapW x mapH) under the caption's lines, above a colour
/// bar `barW` wide when opt.colorBar. False with `err`.
bool layoutHeatmap(HeatmapLayout& L, ImageBuf& scaled, const ColorScale& cs,
                   const HeatmapOptions& opt, long long mapW, long long mapH, int barW,
                   const std::vector<std::string>& caption, int nthreads, std::string& err) {
    const int m = opt.style.margin;
    const int captionH = caption.empty() ? 0 : int(caption.size()) * opt.style.lineHeight() + m / 2;
    ImageBuf& out = L.out;
    if (!opt.colorBar && caption.empty()) {
        out = std::move(scaled);
    } else if (!opt.colorBar) {
        out = canvas(int(mapW) + 2 * m, m + captionH + int(mapH) + m, opt.style.background);
        L.mapX = m;
        L.mapY = m + captionH;
        if (!IBA::paste(out, L.mapX, L.mapY, 0, 0, scaled, {}, nthreads)) {
            err = out.geterror();
            return false;
        }
    } else {
        if (!colorBar(L.bar, barW, cs, opt.style)) {
            err = L.bar.geterror();
            return false;
        }
        const int cw = int(std::max<long long>(mapW, barW)) + 2 * m;
        const int chh = m + captionH + int(mapH) + m + L.bar.spec().height + m;
        out = canvas(cw, chh, opt.style.background);
        L.mapX = m;
        L.mapY = m + captionH;
        L.barX = m;
        L.barY = L.mapY + int(mapH) + m;
        L.barH = L.bar.spec().get_int_attribute("mcstat:colorbar:height");
        if (!IBA::paste(out, L.mapX, L.mapY, 0, 0, scaled, {}, nthreads) ||
            !IBA::paste(out, L.barX, L.barY, 0, 0, L.bar, {}, nthreads)) {
            err = out.geterror();
            return false;
        }
    }
    for (size_t i = 0; i < caption.size(); ++i)
        if (!drawText(out, m, m + int(i) * opt.style.lineHeight(), caption[i], opt.style)) {
            err = out.geterror();
            return false;
        }
    return true;
}

/// The heatmap's spec attributes (docs/review.md): its channel, scale and where its parts are.
void tagHeatmap(ImageSpec& spec, const ImageBuf& src, int ch, const ColorScale& cs,
                const HeatmapOptions& opt, const HeatmapLayout& L, long long mapW, long long mapH,
                int barW) {
    spec.channelnames = {"R", "G", "B"};
    spec.attribute("mcstat:heatmap:channel", src.spec().channel_name(ch));
    spec.attribute("mcstat:heatmap:map", cs.map);
    spec.attribute("mcstat:heatmap:min", TypeDesc::DOUBLE, &cs.lo);
    spec.attribute("mcstat:heatmap:max", TypeDesc::DOUBLE, &cs.hi);
    spec.attribute("mcstat:heatmap:log", cs.log ? 1 : 0);
    spec.attribute("mcstat:heatmap:binary", cs.binary ? 1 : 0);
    if (!opt.caption.empty())
        spec.attribute("mcstat:heatmap:caption",
                       OIIO::Strutil::replace(opt.caption, "\n", " ", true));
    spec.attribute("mcstat:heatmap:nonFinite", int(std::min<long>(cs.nonFinite, 0x7fffffff)));
    if (cs.infiniteAtEnds)
        spec.attribute("mcstat:heatmap:infinite", int(std::min<long>(cs.infinite, 0x7fffffff)));
    spec.attribute("mcstat:heatmap:scale", opt.scale);
    spec.attribute("mcstat:heatmap:x", L.mapX);
    spec.attribute("mcstat:heatmap:y", L.mapY);
    spec.attribute("mcstat:heatmap:width", int(mapW));
    spec.attribute("mcstat:heatmap:height", int(mapH));
    const ImageSpec& bar = L.bar.spec();
    if (opt.colorBar && cs.binary) {
        spec.attribute("mcstat:legend:binary", 1);
        for (const char* sw : {"swatch0", "swatch1"}) {
            const std::string p = format("mcstat:legend:{}:", sw);
            if (bar.get_int_attribute(p + "width") <= 0) continue;
            spec.attribute(p + "x", L.barX + bar.get_int_attribute(p + "x"));
            spec.attribute(p + "y", L.barY + bar.get_int_attribute(p + "y"));
            spec.attribute(p + "width", bar.get_int_attribute(p + "width"));
            spec.attribute(p + "height", bar.get_int_attribute(p + "height"));
        }
    } else if (opt.colorBar) {
        spec.attribute("mcstat:colorbar:x", L.barX);
        spec.attribute("mcstat:colorbar:y", L.barY);
        spec.attribute("mcstat:colorbar:width", barW);
        spec.attribute("mcstat:colorbar:height", L.barH);
    }
}

}  // namespace

bool heatmap(ImageBuf& dst, const ImageBuf& src, const HeatmapOptions& opt, ROI roi, int nthreads) {
    if (opt.scale < 1 || opt.scale > kMaxScale) {
        dst.errorfmt("heatmap: scale must be 1..{}, not {}", kMaxScale, opt.scale);
        return false;
    }
    roi = prepareRoi(roi, src.roi());
    if (roi.npixels() == 0) {
        dst.errorfmt("heatmap: empty region");
        return false;
    }
    int ch = 0;
    ColorScale cs;
    std::string err;
    if (!resolveColorScale(src, opt, ch, cs, err, roi)) {
        dst.errorfmt("heatmap: {}", err);
        return false;
    }
    const int w = roi.width(), h = roi.height();
    const long long mapW = (long long)w * opt.scale, mapH = (long long)h * opt.scale;
    const int barW = opt.colorBar ? int(std::max<long long>(mapW, opt.minBarWidth)) : 0;
    const int m = opt.style.margin;
    if (!checkCanvas(dst, mapW + 2 * m + barW, mapH + 3 * m + 4 * opt.style.lineHeight(),
                     "heatmap"))
        return false;
    // The caption's lines, wrapped to the width of the picture (at least the colour bar's).
    const int textW = int(std::max<long long>(mapW, barW));
    const std::vector<std::string> caption = wrapText(opt.caption, textW, opt.style.fontSize);

    ImageBuf map, scaled;
    if (!heatmapPixels(map, src, roi, ch, cs, nthreads, err)) {
        dst.errorfmt("heatmap: {}", err);
        return false;
    }
    if (!upscale(scaled, map, opt.scale, nthreads)) {
        dst.errorfmt("heatmap: {}", scaled.geterror());
        return false;
    }
    HeatmapLayout layout;
    if (!layoutHeatmap(layout, scaled, cs, opt, mapW, mapH, barW, caption, nthreads, err)) {
        dst.errorfmt("heatmap: {}", err);
        return false;
    }
    tagHeatmap(layout.out.specmod(), src, ch, cs, opt, layout, mapW, mapH, barW);
    dst = std::move(layout.out);
    return true;
}

ImageBuf heatmap(const ImageBuf& src, const HeatmapOptions& opt, ROI roi, int nthreads) {
    ImageBuf dst;
    heatmap(dst, src, opt, roi, nthreads);
    return dst;
}

std::string provenanceCaption(const ImageSpec& spec, const std::string& file) {
    const std::string p = kProvenancePrefix;
    const std::string opName = spec.get_string_attribute(p + "operation");
    std::string text;
    if (!opName.empty()) {
        const Operation* op = findOperation(opName);
        // What a file says of itself is untrusted: shown through printable() (its picture, and the
        // caption attribute written from it).
        text = op ? op->title : printable(opName);
        const std::string params = printable(spec.get_string_attribute(p + "parameters"));
        if (!params.empty()) text += " (" + OIIO::Strutil::replace(params, ",", ", ", true) + ")";
    }
    // Clauses on lines of their own where a caption may break (wrapText).
    const char* nl = "\n";
    if (!file.empty()) text += (text.empty() ? "" : nl) + std::string("of ") + printable(file);
    std::vector<std::string> samples;
    const int M = spec.get_int_attribute(p + "M", 0), spp = spec.get_int_attribute(p + "spp", 0);
    if (M > 0) samples.push_back(format("M = {}", M));
    if (spp > 0) samples.push_back(format("{} spp", spp));
    const std::string sources = spec.get_string_attribute(p + "sources");
    if (!sources.empty()) {
        const size_t n = OIIO::Strutil::splits(sources, ",").size();
        samples.push_back(format("{} source file{}", n, n == 1 ? "" : "s"));
    }
    if (!samples.empty())
        text += (text.empty() ? "" : nl) + ("(" + OIIO::Strutil::join(samples, ", ") + ")");
    const std::string ref = spec.get_string_attribute(p + "errormap.reference");
    if (!ref.empty())
        text += (text.empty() ? "" : nl) + ("vs " + printable(OIIO::Filesystem::filename(ref)));
    return text;
}

bool errorImage(ImageBuf& dst, const ImageBuf& img, const ImageBuf& ref, const DiffOptions& opt,
                ROI roi, int nthreads) {
    const ROI a = img.roi(), b = ref.roi();
    if (a.width() != b.width() || a.height() != b.height()) {
        dst.errorfmt("error map: image is {}x{} but the reference is {}x{}", a.width(), a.height(),
                     b.width(), b.height());
        return false;
    }
    if (img.nchannels() < 3 || ref.nchannels() < 3) {
        dst.errorfmt("error map: both images need R, G, B channels");
        return false;
    }
    roi = prepareRoi(roi, a);
    if (roi.npixels() == 0) {
        dst.errorfmt("error map: empty region");
        return false;
    }
    const int w = roi.width(), h = roi.height();
    const int dx = b.xbegin - a.xbegin, dy = b.ybegin - a.ybegin;
    std::vector<float> lin(size_t(w) * size_t(h) * 3), rlin(lin.size());
    if (!img.get_pixels(ROI(roi.xbegin, roi.xend, roi.ybegin, roi.yend, 0, 1, 0, 3),
                        TypeDesc::FLOAT, lin.data()) ||
        !ref.get_pixels(
            ROI(roi.xbegin + dx, roi.xend + dx, roi.ybegin + dy, roi.yend + dy, 0, 1, 0, 3),
            TypeDesc::FLOAT, rlin.data())) {
        dst.errorfmt("error map: {}{}", img.geterror(), ref.geterror());
        return false;
    }
    // One thread per block of rows: errorMap is per pixel, so any split gives the same result.
    std::vector<float> out(size_t(w) * size_t(h) * 2), relerr(size_t(w) * size_t(h)),
        firefly(relerr.size());
    IBA::parallel_image(ROI(0, w, 0, h), nthreads, [&](ROI r) {
        for (int y = r.ybegin; y < r.yend; ++y) {
            const size_t p0 = size_t(y) * size_t(w) + size_t(r.xbegin);
            errorMap(lin.data() + 3 * p0, rlin.data() + 3 * p0, size_t(r.width()), opt,
                     relerr.data() + p0, firefly.data() + p0);
        }
    });
    for (size_t p = 0; p < relerr.size(); ++p) {
        out[2 * p] = relerr[p];
        out[2 * p + 1] = firefly[p];
    }
    ImageSpec spec = floatSpec(ROI(roi.xbegin, roi.xbegin + w, roi.ybegin, roi.ybegin + h),
                               {"relerr", "firefly"}, img.roi_full());
    spec.attribute("mcstat:errormap:eps", TypeDesc::DOUBLE, &opt.relmseEpsilon);
    spec.attribute("mcstat:errormap:ratio", TypeDesc::DOUBLE, &opt.fireflyRatio);
    spec.attribute("mcstat:errormap:floor", TypeDesc::DOUBLE, &opt.fireflyFloor);
    // What the error is of: the estimate's provenance (operation, M, spp, sources).
    for (const OIIO::ParamValue& pv : img.spec().extra_attribs)
        if (OIIO::Strutil::starts_with(pv.name(), kProvenancePrefix))
            spec.attribute(pv.name(), pv.type(), pv.data());
    ImageBuf result(spec);
    result.set_pixels(result.roi(), TypeDesc::FLOAT, out.data());
    dst = std::move(result);
    return true;
}

ImageBuf errorImage(const ImageBuf& img, const ImageBuf& ref, const DiffOptions& opt, ROI roi,
                    int nthreads) {
    ImageBuf dst;
    errorImage(dst, img, ref, opt, roi, nthreads);
    return dst;
}

bool contactSheet(ImageBuf& dst, const std::vector<SheetTile>& tiles, const SheetOptions& opt,
                  ROI roi, int nthreads) {
    if (tiles.empty()) {
        dst.errorfmt("contact sheet: no tiles");
        return false;
    }
    if (opt.scale < 1 || opt.scale > kMaxScale) {
        dst.errorfmt("contact sheet: scale must be 1..{}, not {}", kMaxScale, opt.scale);
        return false;
    }
    const int w = tiles[0].image.spec().width, h = tiles[0].image.spec().height;
    for (size_t i = 0; i < tiles.size(); ++i) {
        const ImageSpec& s = tiles[i].image.spec();
        if (s.width != w || s.height != h || s.nchannels < 3) {
            dst.errorfmt(
                "contact sheet: tile {} ({}) is {}x{} with {} channels; every tile must be "
                "{}x{} RGB",
                i + 1, tiles[i].title, s.width, s.height, s.nchannels, w, h);
            return false;
        }
    }
    const ReviewStyle& st = opt.style;
    const int n = int(tiles.size()), m = st.margin, lineH = st.lineHeight();
    const long long W = (long long)w * opt.scale, H = (long long)h * opt.scale;
    int labelH = 0;
    for (const SheetTile& t : tiles) {
        int th = int(t.lines.size()) * lineH;
        if (t.footer.initialized()) th += (t.lines.empty() ? 0 : m / 2) + t.footer.spec().height;
        labelH = std::max(labelH, th);
    }
    const long long sheetW = n * W + (n + 1) * (long long)m;
    const long long tileY = m + lineH, stripY = tileY + H + m / 2;
    const long long sheetH = stripY + labelH + m;
    if (!checkCanvas(dst, sheetW, sheetH, "contact sheet")) return false;

    ImageBuf sheet = canvas(int(sheetW), int(sheetH), st.background);
    ImageSpec& spec = sheet.specmod();
    for (int i = 0; i < n; ++i) {
        const SheetTile& t = tiles[size_t(i)];
        const int x = int(m + i * (W + m));
        ImageBuf rgb, clamped, scaled;
        // Clamped: a PNG clamps anyway, and the EXR of a sheet then shows the same pixels.
        if (!cutRGB(rgb, t.image, t.image.roi(), nthreads) ||
            !IBA::clamp(clamped, rgb, 0.f, 1.f, false, {}, nthreads) ||
            !upscale(scaled, clamped, opt.scale, nthreads) ||
            !IBA::paste(sheet, x, int(tileY), 0, 0, scaled, {}, nthreads)) {
            dst.errorfmt("contact sheet: tile {} ({}): {}{}{}{}", i + 1, t.title, rgb.geterror(),
                         clamped.geterror(), scaled.geterror(), sheet.geterror());
            return false;
        }
        bool ok = drawText(sheet, x, m, fitText(t.title, int(W), st.fontSize), st);
        for (size_t j = 0; ok && j < t.lines.size(); ++j)
            ok = drawText(sheet, x, int(stripY + long(j) * lineH),
                          fitText(t.lines[j], int(W), st.fontSize), st);
        if (ok && t.footer.initialized()) {
            const int fy =
                int(stripY + long(t.lines.size()) * lineH + (t.lines.empty() ? 0 : m / 2));
            ok = IBA::paste(sheet, x, fy, 0, 0, t.footer, {}, nthreads);
        }
        if (!ok) {
            dst.errorfmt("contact sheet: tile {} ({}): {}", i + 1, t.title, sheet.geterror());
            return false;
        }
        spec.attribute(format("mcstat:tile{}:x", i + 1), x);
        spec.attribute(format("mcstat:tile{}:y", i + 1), int(tileY));
    }
    spec.attribute("mcstat:sheet:tiles", n);
    spec.attribute("mcstat:sheet:scale", opt.scale);
    spec.attribute("mcstat:sheet:tileWidth", int(W));
    spec.attribute("mcstat:sheet:tileHeight", int(H));
    spec.attribute("mcstat:sheet:margin", m);
    spec.attribute("mcstat:sheet:titleHeight", lineH);
    spec.attribute("mcstat:sheet:labelHeight", labelH);
    if (roi.defined()) {
        ImageBuf part;
        if (!IBA::cut(part, sheet, roi, nthreads)) {
            dst.errorfmt("contact sheet: {}", part.geterror());
            return false;
        }
        dst = std::move(part);
    } else {
        dst = std::move(sheet);
    }
    return true;
}

ImageBuf contactSheet(const std::vector<SheetTile>& tiles, const SheetOptions& opt, ROI roi,
                      int nthreads) {
    ImageBuf dst;
    contactSheet(dst, tiles, opt, roi, nthreads);
    return dst;
}

}  // namespace mcstat
