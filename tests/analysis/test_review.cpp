// Review pictures (include/mcstat/review/review_pictures.h): the per-pixel error map against
// hand-computed values, heatmap colours against their colour bar, non-finite pixels, and the
// contact sheet's layout and pixels.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

#include "mcstat/analysis/metrics.h"
#include "mcstat/image/imageops.h"
#include "mcstat/review/review_pictures.h"

using namespace mcstat;

namespace {

const float kNaN = std::numeric_limits<float>::quiet_NaN();
const float kInf = std::numeric_limits<float>::infinity();

DiffOptions options() {
    DiffOptions o;
    o.luma = {0.2126, 0.7152, 0.0722};
    return o;
}

/// A one-channel float image named `name` holding `v` (w x h, row by row).
OIIO::ImageBuf channelImage(const std::string& name, int w, int h, const std::vector<float>& v) {
    OIIO::ImageSpec spec(w, h, 1, OIIO::TypeDesc::FLOAT);
    spec.channelnames = {name};
    OIIO::ImageBuf b(spec);
    b.set_pixels(b.roi(), OIIO::TypeDesc::FLOAT, v.data());
    return b;
}

std::array<float, 3> pixel(const OIIO::ImageBuf& b, int x, int y) {
    std::array<float, 3> p{};
    b.getpixel(x, y, p.data(), 3);
    return p;
}

double distance(const std::array<float, 3>& a, const std::array<float, 3>& b) {
    double d = 0.0;
    for (int c = 0; c < 3; ++c) d = std::max(d, double(std::abs(a[c] - b[c])));
    return d;
}

struct Rect {
    int x, y, w, h;
};
Rect rect(const OIIO::ImageBuf& b, const std::string& what) {
    const OIIO::ImageSpec& s = b.spec();
    return {s.get_int_attribute("mcstat:" + what + ":x", -1),
            s.get_int_attribute("mcstat:" + what + ":y", -1),
            s.get_int_attribute("mcstat:" + what + ":width", -1),
            s.get_int_attribute("mcstat:" + what + ":height", -1)};
}

/// The colour bar column whose colour is nearest `c`.
int nearestBarColumn(const OIIO::ImageBuf& img, const Rect& bar, const std::array<float, 3>& c,
                     double* dist = nullptr) {
    int best = -1;
    double bestD = 1e30;
    for (int i = 0; i < bar.w; ++i) {
        const double d = distance(pixel(img, bar.x + i, bar.y + bar.h / 2), c);
        if (d < bestD) {
            bestD = d;
            best = i;
        }
    }
    if (dist) *dist = bestD;
    return best;
}

}  // namespace

// ---- per-pixel error ----------------------------------------------------------------------------

TEST(ReviewOps, ErrorMapMatchesHandComputedValues) {
    // Pixels: identical; a firefly (0.5 against 0.2: 2.5x and 0.3 above); bright by ratio but only
    // 0.02 above the floor; 0.5 above but only 1.5x; NaN; a red firefly.
    const std::vector<float> lin = {1,    1,    1,    0.5f, 0.5f, 0.5f, 0.03f, 0.03f, 0.03f,
                                    1.5f, 1.5f, 1.5f, kNaN, 0,    0,    2.1f,  0,     0};
    const std::vector<float> ref = {1, 1, 1, 0.2f, 0.2f, 0.2f, 0.01f, 0.01f, 0.01f,
                                    1, 1, 1, 0.5f, 0.5f, 0.5f, 0.1f,  0.1f,  0.1f};
    std::vector<float> relerr(6), firefly(6);
    errorMap(lin.data(), ref.data(), 6, options(), relerr.data(), firefly.data());
    auto term = [](double x, double r) { return (x - r) * (x - r) / (r * r + 0.01); };
    const double expected[] = {0.0,
                               term(0.5f, 0.2f),
                               term(0.03f, 0.01f),
                               term(1.5, 1.0),
                               0.0,
                               (term(2.1f, 0.1f) + 2 * term(0, 0.1f)) / 3.0};
    const float expectedFirefly[] = {0, 1, 0, 0, 0, 1};
    for (int p = 0; p < 6; ++p) {
        if (p == 4) {
            EXPECT_TRUE(std::isnan(relerr[p]));
            EXPECT_TRUE(std::isnan(firefly[p]));
            continue;
        }
        EXPECT_NEAR(relerr[p], expected[p], 1e-6 * std::max(1.0, expected[p])) << p;
        EXPECT_EQ(firefly[p], expectedFirefly[p]) << p;
    }
    // 2.0^2 / 0.02 = 200 on red, 0.01 / 0.02 on green and blue
    EXPECT_NEAR(relerr[5], (200.0 + 0.5 + 0.5) / 3.0, 1e-3);
    // A lower floor makes pixel 2 (3x) a firefly; a higher ratio drops pixel 1 (2.5x).
    DiffOptions o = options();
    o.fireflyFloor = 0.01;
    o.fireflyRatio = 2.6;
    errorMap(lin.data(), ref.data(), 6, o, nullptr, firefly.data());
    EXPECT_EQ(firefly[1], 0.f);
    EXPECT_EQ(firefly[2], 1.f);
    EXPECT_EQ(firefly[5], 1.f);  // 4.46x
}

TEST(ReviewOps, ErrorMapAveragesToCompareImages) {
    // relMSE is the mean of relerr over finite pixels; the firefly count its sum.
    const int w = 7, h = 5;
    std::vector<float> lin(w * h * 3), ref(lin.size());
    for (size_t i = 0; i < lin.size(); ++i) {
        ref[i] = 0.05f + 0.1f * float(i % 9);
        lin[i] = ref[i] * (1.f + 0.3f * float((i * 5) % 7) - 0.9f);
    }
    lin[3 * 12 + 1] = 6.f;  // a firefly
    lin[3 * 20] = kInf;     // left out
    std::vector<float> relerr(w * h), firefly(w * h);
    errorMap(lin.data(), ref.data(), w * h, options(), relerr.data(), firefly.data());
    const DiffMetrics m =
        compareImages(lin.data(), ref.data(), lin.data(), ref.data(), w, h, options());
    double sum = 0.0, ff = 0.0;
    for (int p = 0; p < w * h; ++p)
        if (std::isfinite(relerr[p])) {
            sum += relerr[p];
            ff += firefly[p];
        }
    EXPECT_EQ(m.nonFinite, 1);
    EXPECT_NEAR(m.relMSE, sum / double(m.pixels), 1e-6 * m.relMSE);
    EXPECT_EQ(double(m.fireflies), ff);
    EXPECT_GE(m.fireflies, 1);

    // The OIIO form: channels relerr and firefly, the same numbers.
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::FLOAT);
    OIIO::ImageBuf a(spec), b(spec);
    a.set_pixels(a.roi(), OIIO::TypeDesc::FLOAT, lin.data());
    b.set_pixels(b.roi(), OIIO::TypeDesc::FLOAT, ref.data());
    OIIO::ImageBuf e = errorImage(a, b, options());
    ASSERT_FALSE(e.has_error()) << e.geterror();
    ASSERT_EQ(e.nchannels(), 2);
    EXPECT_EQ(e.spec().channelnames[0], "relerr");
    EXPECT_EQ(e.spec().channelnames[1], "firefly");
    for (int p = 0; p < w * h; ++p) {
        float v[2];
        e.getpixel(p % w, p / w, v, 2);
        if (std::isnan(relerr[p])) {
            EXPECT_TRUE(std::isnan(v[0]));
        } else {
            EXPECT_EQ(v[0], relerr[p]) << p;
            EXPECT_EQ(v[1], firefly[p]) << p;
        }
    }
    OIIO::ImageBuf small(OIIO::ImageSpec(3, 3, 3, OIIO::TypeDesc::FLOAT)), bad;
    EXPECT_FALSE(errorImage(bad, a, small, options()));
    EXPECT_NE(bad.geterror().find("reference"), std::string::npos);
}

// ---- heatmap ------------------------------------------------------------------------------------

TEST(ReviewOps, HeatmapColorsFollowTheErrorAndTheBar) {
    // relerr growing left to right over four decades: log scale by default.
    const int w = 64, h = 3;
    std::vector<float> v(w * h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) v[y * w + x] = float(std::pow(10.0, -4.0 + 4.0 * x / (w - 1)));
    const OIIO::ImageBuf src = channelImage("relerr", w, h, v);
    HeatmapOptions opt;
    opt.scale = 4;
    const OIIO::ImageBuf hm = heatmap(src, opt);
    ASSERT_FALSE(hm.has_error()) << hm.geterror();
    const OIIO::ImageSpec& s = hm.spec();
    EXPECT_EQ(s.get_int_attribute("mcstat:heatmap:log"), 1);
    EXPECT_EQ(s.get_string_attribute("mcstat:heatmap:channel"), "relerr");
    const Rect map = rect(hm, "heatmap"), bar = rect(hm, "colorbar");
    EXPECT_EQ(map.w, w * 4);
    EXPECT_EQ(map.h, h * 4);
    EXPECT_GE(bar.w, 256);
    ASSERT_GT(bar.h, 0);
    ColorScale cs;
    cs.lo = 1e-4;
    cs.hi = 1.0;
    cs.log = true;
    int prev = -1;
    for (int x = 0; x < w; ++x) {
        // Every upscaled pixel of the block has the same colour.
        const auto c = pixel(hm, map.x + 4 * x + 1, map.y + 4 * 1 + 2);
        EXPECT_EQ(distance(c, pixel(hm, map.x + 4 * x + 3, map.y + 4 * 2)), 0.0);
        double d = 0.0;
        const int col = nearestBarColumn(hm, bar, c, &d);
        // The value's place on the bar: t = (log10 v + 4) / 4; column i shows t = (i + 0.5) / W.
        const double t = colorScalePosition(cs, v[w + x]);
        EXPECT_NEAR(t, x / double(w - 1), 1e-5);
        EXPECT_LE(d, 2.0 / 255.0) << "x " << x;
        EXPECT_NEAR(col, t * bar.w, 2.0) << "x " << x;
        EXPECT_GE(col, prev) << "x " << x;  // grows left to right
        prev = col;
    }
    EXPECT_LE(nearestBarColumn(hm, bar, pixel(hm, map.x, map.y)), 1);
    EXPECT_GE(nearestBarColumn(hm, bar, pixel(hm, map.x + map.w - 1, map.y)), bar.w - 2);

    // Published inferno ends (matplotlib, sRGB) with the built-in config's sRGB view: the map
    // is display-encoded exactly once.
    if (!std::getenv("OCIO")) {
        EXPECT_LE(distance(pixel(hm, bar.x, bar.y), {0.001462f, 0.000466f, 0.013866f}), 0.01);
        EXPECT_LE(distance(pixel(hm, bar.x + bar.w - 1, bar.y), {0.988362f, 0.998364f, 0.644924f}),
                  0.01);
    }

    // Linear scale: the middle value sits mid-bar, not at t = 0.75 as on the log scale.
    opt.log = 0;
    opt.min = 0.0;
    opt.max = 1.0;
    const OIIO::ImageBuf lin = heatmap(channelImage("relerr", 1, 1, {0.5f}), opt);
    ASSERT_FALSE(lin.has_error()) << lin.geterror();
    const Rect lbar = rect(lin, "colorbar"), lmap = rect(lin, "heatmap");
    EXPECT_NEAR(nearestBarColumn(lin, lbar, pixel(lin, lmap.x, lmap.y)), 0.5 * lbar.w, 2.0);
}

TEST(ReviewOps, HeatmapNonFiniteIsMagentaAndRangeIsClamped) {
    // Values 0 (bottom of a log scale), NaN, Inf, -Inf, 2, 5 (clamped: max 4).
    const OIIO::ImageBuf src = channelImage("relerr", 6, 1, {0.f, kNaN, kInf, -kInf, 2.f, 5.f});
    HeatmapOptions opt;
    opt.min = 0.5;
    opt.max = 4.0;
    const OIIO::ImageBuf hm = heatmap(src, opt);
    ASSERT_FALSE(hm.has_error()) << hm.geterror();
    EXPECT_EQ(hm.spec().get_int_attribute("mcstat:heatmap:nonFinite"), 3);
    const Rect map = rect(hm, "heatmap"), bar = rect(hm, "colorbar");
    const int s = hm.spec().get_int_attribute("mcstat:heatmap:scale");
    EXPECT_EQ(s, 1);  // the library's default; the command line picks one for small images
    const std::array<float, 3> magenta{1.f, 0.f, 1.f};
    for (int x = 1; x <= 3; ++x) EXPECT_EQ(distance(pixel(hm, map.x + x, map.y), magenta), 0.0);
    for (int x : {0, 4, 5}) EXPECT_GT(distance(pixel(hm, map.x + x, map.y), magenta), 0.2);
    for (int i = 0; i < bar.w; ++i)  // no bar colour can be mistaken for it
        EXPECT_GT(distance(pixel(hm, bar.x + i, bar.y), magenta), 0.2);
    EXPECT_LE(nearestBarColumn(hm, bar, pixel(hm, map.x, map.y)), 0);              // 0 -> min
    EXPECT_GE(nearestBarColumn(hm, bar, pixel(hm, map.x + 5, map.y)), bar.w - 1);  // 5 -> max
    EXPECT_NEAR(nearestBarColumn(hm, bar, pixel(hm, map.x + 4, map.y)), 2.0 / 3.0 * bar.w, 2.0);
}

TEST(ReviewOps, InfiniteAtEndsPaintsExactDifferencesAsTheStrongestOfTheirSign) {
    // z of a comparison: -2, 0, 3, +Inf and -Inf (exact differences, no noise), NaN (untested).
    const OIIO::ImageBuf src = channelImage("z", 6, 1, {-2.f, 0.f, 3.f, kInf, -kInf, kNaN});
    HeatmapOptions opt;
    opt.map = "cool-warm";
    opt.symmetric = true;
    opt.infiniteAtEnds = true;
    int ch = -1;
    ColorScale cs;
    std::string err;
    ASSERT_TRUE(resolveColorScale(src, opt, ch, cs, err)) << err;
    EXPECT_EQ(cs.lo, -3.0);  // the finite values' range, symmetric
    EXPECT_EQ(cs.hi, 3.0);
    EXPECT_EQ(cs.infinite, 2);
    EXPECT_EQ(cs.nonFinite, 1);  // NaN only
    EXPECT_NE(cs.label.find("2 px exact"), std::string::npos) << cs.label;
    EXPECT_EQ(colorScalePosition(cs, INFINITY), 1.0);
    EXPECT_EQ(colorScalePosition(cs, -INFINITY), 0.0);
    const OIIO::ImageBuf hm = heatmap(src, opt);
    ASSERT_FALSE(hm.has_error()) << hm.geterror();
    EXPECT_EQ(hm.spec().get_int_attribute("mcstat:heatmap:infinite"), 2);
    EXPECT_EQ(hm.spec().get_int_attribute("mcstat:heatmap:nonFinite"), 1);
    const Rect map = rect(hm, "heatmap");
    const std::array<float, 3> magenta{1.f, 0.f, 1.f};
    EXPECT_EQ(distance(pixel(hm, map.x + 3, map.y), pixel(hm, map.x + 2, map.y)), 0.0);  // +Inf: 3
    EXPECT_GT(distance(pixel(hm, map.x + 4, map.y), magenta), 0.2);
    EXPECT_EQ(distance(pixel(hm, map.x + 5, map.y), magenta), 0.0);  // NaN stays magenta
    // -Inf at the cool end: the colour of -3, which no pixel has; the bar's first column.
    const Rect bar = rect(hm, "colorbar");
    EXPECT_LE(nearestBarColumn(hm, bar, pixel(hm, map.x + 4, map.y)), 1);
    // Without the option both are magenta, as --heatmap draws them.
    opt.infiniteAtEnds = false;
    const OIIO::ImageBuf plain = heatmap(src, opt);
    EXPECT_EQ(plain.spec().get_int_attribute("mcstat:heatmap:nonFinite"), 3);
    for (int x : {3, 4}) EXPECT_EQ(distance(pixel(plain, map.x + x, map.y), magenta), 0.0);
}

TEST(ReviewOps, HeatmapDefaultsAndErrors) {
    // The data range of the finite values; a channel chosen by name; linear for non-relerr.
    OIIO::ImageSpec spec(4, 1, 2, OIIO::TypeDesc::FLOAT);
    spec.channelnames = {"R", "gini"};
    OIIO::ImageBuf src(spec);
    const float px[] = {9, 0.1f, 9, 0.3f, 9, kNaN, 9, 0.2f};
    src.set_pixels(src.roi(), OIIO::TypeDesc::FLOAT, px);
    HeatmapOptions opt;
    opt.channel = "gini";
    int ch = -1;
    ColorScale cs;
    std::string err;
    ASSERT_TRUE(resolveColorScale(src, opt, ch, cs, err)) << err;
    EXPECT_EQ(ch, 1);
    EXPECT_FALSE(cs.log);
    EXPECT_FLOAT_EQ(float(cs.lo), 0.1f);
    EXPECT_FLOAT_EQ(float(cs.hi), 0.3f);
    EXPECT_EQ(cs.nonFinite, 1);
    // A constant channel gets a non-empty range.
    opt.channel = "R";
    ASSERT_TRUE(resolveColorScale(src, opt, ch, cs, err)) << err;
    EXPECT_EQ(cs.lo, 9.0);
    EXPECT_EQ(cs.hi, 10.0);

    OIIO::ImageBuf dst;
    opt.channel = "nope";
    EXPECT_FALSE(heatmap(dst, src, opt));
    EXPECT_NE(dst.geterror().find("no channel 'nope' (channels: 'R', 'gini')"), std::string::npos);
    opt.channel = "";
    opt.map = "no-such-map";
    EXPECT_FALSE(heatmap(dst, src, opt));
    EXPECT_NE(dst.geterror().find("unknown colour map"), std::string::npos);
    opt.map = "viridis";
    opt.log = 1;
    opt.min = -1.0;
    EXPECT_FALSE(heatmap(dst, src, opt));
    EXPECT_NE(dst.geterror().find("log scale needs min > 0"), std::string::npos);
    opt.log = 0;
    opt.min = 2.0;
    opt.max = 1.0;
    EXPECT_FALSE(heatmap(dst, src, opt));
    EXPECT_NE(dst.geterror().find("must be below max"), std::string::npos);
}

TEST(ReviewOps, BinaryChannelsGetATwoSwatchLegend) {
    // A firefly mask: 0, 1 and a NaN pixel.
    const OIIO::ImageBuf src = channelImage("firefly", 4, 1, {0.f, 1.f, kNaN, 0.f});
    HeatmapOptions opt;
    const OIIO::ImageBuf hm = heatmap(src, opt);
    ASSERT_FALSE(hm.has_error()) << hm.geterror();
    const OIIO::ImageSpec& s = hm.spec();
    EXPECT_EQ(s.get_int_attribute("mcstat:heatmap:binary"), 1);
    EXPECT_EQ(s.get_int_attribute("mcstat:heatmap:log"), 0);
    EXPECT_EQ(s.get_float_attribute("mcstat:heatmap:min", -1.f), 0.f);
    EXPECT_EQ(s.get_float_attribute("mcstat:heatmap:max", -1.f), 1.f);
    EXPECT_EQ(s.get_int_attribute("mcstat:heatmap:nonFinite"), 1);
    EXPECT_EQ(s.get_int_attribute("mcstat:legend:binary"), 1);
    EXPECT_EQ(rect(hm, "colorbar").w, -1);  // no gradient
    const Rect map = rect(hm, "heatmap"), sw0 = rect(hm, "legend:swatch0"),
               sw1 = rect(hm, "legend:swatch1");
    ASSERT_GT(sw0.w, 0);
    ASSERT_GT(sw1.w, 0);
    EXPECT_EQ(sw0.y, sw1.y);
    EXPECT_GT(sw0.y, map.y + map.h);  // under the map
    EXPECT_GT(sw1.x, sw0.x + sw0.w);  // side by side, the name of 0 between them
    // The swatches have exactly the colours of the pixels of value 0 and 1.
    const auto c0 = pixel(hm, sw0.x + sw0.w / 2, sw0.y + sw0.h / 2),
               c1 = pixel(hm, sw1.x + sw1.w / 2, sw1.y + sw1.h / 2);
    EXPECT_EQ(distance(pixel(hm, map.x, map.y), c0), 0.0);
    EXPECT_EQ(distance(pixel(hm, map.x + 3, map.y), c0), 0.0);
    EXPECT_EQ(distance(pixel(hm, map.x + 1, map.y), c1), 0.0);
    EXPECT_GT(distance(c0, c1), 0.5);  // inferno's ends: black and yellow
    EXPECT_EQ(distance(pixel(hm, map.x + 2, map.y), {1.f, 0.f, 1.f}), 0.0);  // NaN: magenta
    // The name of 0 is drawn between the swatches (text pixels, brighter than the background).
    const ReviewStyle st;
    double bright = 0.0;
    for (int x = sw0.x + sw0.w + 1; x < sw1.x - 1; ++x)  // inside the swatches' frames
        for (int y = sw0.y; y < sw0.y + sw0.h; ++y)
            bright = std::max(bright, distance(pixel(hm, x, y), st.background));
    EXPECT_GT(bright, 0.3);

    // Names by channel (any layer or component); other masks say 0 and 1.
    EXPECT_EQ(binaryNames("firefly"), (std::array<std::string, 2>{"no firefly", "firefly"}));
    EXPECT_EQ(binaryNames("tile.differs.R"), (std::array<std::string, 2>{"same", "differs"}));
    EXPECT_EQ(binaryNames("kept"), (std::array<std::string, 2>{"0", "1"}));

    // Binary by its values, whatever its name; not when another value occurs.
    int ch = 0;
    ColorScale cs;
    std::string err;
    HeatmapOptions any;
    ASSERT_TRUE(
        resolveColorScale(channelImage("excluded", 3, 1, {0.f, 1.f, 1.f}), any, ch, cs, err))
        << err;
    EXPECT_TRUE(cs.binary);
    EXPECT_EQ(cs.binaryNames[1], "1");
    ASSERT_TRUE(resolveColorScale(channelImage("kept", 3, 1, {0.f, 1.f, 2.f}), any, ch, cs, err));
    EXPECT_FALSE(cs.binary);
    // A mask of ones only is still [0, 1]: its pixels are 1's colour (a widened [1, 2] range would
    // paint them as the bottom of the scale).
    ASSERT_TRUE(resolveColorScale(channelImage("differs", 2, 1, {1.f, 1.f}), any, ch, cs, err));
    EXPECT_TRUE(cs.binary);
    EXPECT_EQ(cs.lo, 0.0);
    EXPECT_EQ(cs.hi, 1.0);
    EXPECT_EQ(cs.binaryNames[1], "differs");
    // No finite value: the name decides.
    ASSERT_TRUE(resolveColorScale(channelImage("firefly", 2, 1, {kNaN, kNaN}), any, ch, cs, err));
    EXPECT_TRUE(cs.binary);
    ASSERT_TRUE(resolveColorScale(channelImage("gini", 2, 1, {kNaN, kNaN}), any, ch, cs, err));
    EXPECT_FALSE(cs.binary);
    // A log scale or another range asked for: the colour bar.
    HeatmapOptions asked;
    asked.log = 1;
    ASSERT_TRUE(resolveColorScale(src, asked, ch, cs, err)) << err;
    EXPECT_FALSE(cs.binary);
    asked.log = 0;
    asked.max = 2.0;
    ASSERT_TRUE(resolveColorScale(src, asked, ch, cs, err)) << err;
    EXPECT_FALSE(cs.binary);
    asked.min = 0.0;
    asked.max = 1.0;  // the mask's own range: still the legend
    ASSERT_TRUE(resolveColorScale(src, asked, ch, cs, err)) << err;
    EXPECT_TRUE(cs.binary);
}

TEST(ReviewOps, CaptionSaysWhatThePictureIsOf) {
    OIIO::ImageSpec spec(2, 2, 3, OIIO::TypeDesc::FLOAT);
    EXPECT_EQ(provenanceCaption(spec, ""), "");
    EXPECT_EQ(provenanceCaption(spec, "x.exr"), "of x.exr");
    spec.attribute("mcstat.operation", "gmon");
    spec.attribute("mcstat.parameters", "mode=lum");
    spec.attribute("mcstat.M", 21);
    spec.attribute("mcstat.spp", 1000);
    // One clause per line: where a caption may break.
    EXPECT_EQ(provenanceCaption(spec, "scene.mcstat"),
              "G-MoN (mode=lum)\nof scene.mcstat\n(M = 21, 1000 spp)");
    spec.attribute("mcstat.errormap.reference", "out/demo/reference-65536spp.exr");
    spec.attribute("mcstat.sources", "s1.exr,s2.exr");
    spec.attribute("mcstat.parameters", "mode=channel,threshold=0.5");
    EXPECT_EQ(provenanceCaption(spec, "seeds.mcstat"),
              "G-MoN (mode=channel, threshold=0.5)\nof seeds.mcstat\n(M = 21, 1000 spp, 2 source "
              "files)\nvs reference-65536spp.exr");

    // The error map keeps the estimate's provenance.
    OIIO::ImageSpec is(4, 1, 3, OIIO::TypeDesc::FLOAT);
    is.attribute("mcstat.operation", "mean");
    is.attribute("mcstat.M", 5);
    OIIO::ImageBuf img(is), ref(OIIO::ImageSpec(4, 1, 3, OIIO::TypeDesc::FLOAT));
    OIIO::ImageBufAlgo::fill(img, {0.5f, 0.5f, 0.5f});
    OIIO::ImageBufAlgo::fill(ref, {0.4f, 0.4f, 0.4f});
    const OIIO::ImageBuf e = errorImage(img, ref, options());
    ASSERT_FALSE(e.has_error()) << e.geterror();
    EXPECT_EQ(e.spec().get_string_attribute("mcstat.operation"), "mean");
    EXPECT_EQ(e.spec().get_int_attribute("mcstat.M"), 5);

    // The caption above the map, recorded; without one the map starts at the margin.
    HeatmapOptions opt;
    const OIIO::ImageBuf plain = heatmap(e, opt);
    opt.caption = provenanceCaption(e.spec(), "a.mcstat");
    EXPECT_EQ(opt.caption, "mean\nof a.mcstat\n(M = 5)");
    const OIIO::ImageBuf hm = heatmap(e, opt);
    ASSERT_FALSE(hm.has_error()) << hm.geterror();
    // Recorded on one line; drawn on one line too, as the clauses fit the 256-pixel bar's width.
    EXPECT_EQ(hm.spec().get_string_attribute("mcstat:heatmap:caption"), "mean of a.mcstat (M = 5)");
    EXPECT_EQ(plain.spec().get_string_attribute("mcstat:heatmap:caption", "none"), "none");
    const ReviewStyle st;
    EXPECT_EQ(rect(plain, "heatmap").y, st.margin);
    EXPECT_EQ(rect(hm, "heatmap").y, st.margin + st.lineHeight() + st.margin / 2);
    // Narrower than the clauses together: a line each, broken between them, not inside them.
    opt.colorBar = false;
    opt.caption = "G-MoN (mode=lum)\nof scene.mcstat\n(M = 21, 1000 spp)";
    OIIO::ImageBuf big(OIIO::ImageSpec(150, 2, 1, OIIO::TypeDesc::FLOAT));
    OIIO::ImageBufAlgo::zero(big);
    const OIIO::ImageBuf narrow = heatmap(big, opt);
    ASSERT_FALSE(narrow.has_error()) << narrow.geterror();
    EXPECT_EQ(rect(narrow, "heatmap").y, st.margin + 3 * st.lineHeight() + st.margin / 2);
}

// ---- contact sheet ------------------------------------------------------------------------------

TEST(ReviewOps, ContactSheetLayoutAndPixels) {
    const int w = 10, h = 6, n = 3, s = 3;
    std::vector<SheetTile> tiles(n);
    for (int i = 0; i < n; ++i) {
        std::vector<float> v(w * h * 3);
        for (int p = 0; p < w * h; ++p)
            for (int c = 0; c < 3; ++c)
                v[p * 3 + c] = 0.1f * float(i + 1) + 0.013f * float(p) + 0.2f * float(c);
        v[5] = 3.f;   // clamped to 1
        v[7] = -1.f;  // clamped to 0
        OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::FLOAT);
        spec.x = 100;  // any data window origin
        tiles[i].image.reset(spec);
        tiles[i].image.set_pixels(tiles[i].image.roi(), OIIO::TypeDesc::FLOAT, v.data());
        tiles[i].title = "tile " + std::to_string(i + 1);
        tiles[i].lines = std::vector<std::string>(size_t(i), "a line");
    }
    ColorScale cs;
    tiles[2].footer = colorBar(w * s, cs);
    ASSERT_FALSE(tiles[2].footer.has_error()) << tiles[2].footer.geterror();
    SheetOptions opt;
    opt.scale = s;
    const OIIO::ImageBuf sheet = contactSheet(tiles, opt);
    ASSERT_FALSE(sheet.has_error()) << sheet.geterror();
    const ReviewStyle st;
    const int m = st.margin, lineH = st.lineHeight();
    // Tallest label strip: tile 3's two lines, a half margin, the colour bar.
    const int labelH = std::max(lineH, 2 * lineH + m / 2 + tiles[2].footer.spec().height);
    EXPECT_EQ(sheet.spec().width, n * w * s + (n + 1) * m);
    EXPECT_EQ(sheet.spec().height, m + lineH + h * s + m / 2 + labelH + m);
    EXPECT_EQ(sheet.spec().get_int_attribute("mcstat:sheet:tiles"), n);
    for (int i = 0; i < n; ++i) {
        const int x0 = sheet.spec().get_int_attribute("mcstat:tile" + std::to_string(i + 1) + ":x");
        const int y0 = sheet.spec().get_int_attribute("mcstat:tile" + std::to_string(i + 1) + ":y");
        EXPECT_EQ(x0, m + i * (w * s + m));
        EXPECT_EQ(y0, m + lineH);
        for (int y = 0; y < h * s; ++y)
            for (int x = 0; x < w * s; ++x) {
                auto src = pixel(tiles[i].image, 100 + x / s, y / s);
                for (float& c : src) c = std::clamp(c, 0.f, 1.f);
                ASSERT_EQ(distance(pixel(sheet, x0 + x, y0 + y), src), 0.0)
                    << "tile " << i << " at " << x << "," << y;
            }
        // The margin between tiles stays background.
        EXPECT_EQ(distance(pixel(sheet, x0 - 1, y0 + 1), st.background), 0.0);
    }
    // The footer sits under tile 3's lines.
    const int fy = m + lineH + h * s + m / 2 + 2 * lineH + m / 2;
    const int x3 = m + 2 * (w * s + m);
    EXPECT_EQ(distance(pixel(sheet, x3 + 5, fy + 2), pixel(tiles[2].footer, 5, 2)), 0.0);

    // Tiles of different sizes are refused, with the error on the destination.
    tiles[1].image = OIIO::ImageBuf(OIIO::ImageSpec(4, 4, 3, OIIO::TypeDesc::FLOAT));
    OIIO::ImageBuf bad;
    EXPECT_FALSE(contactSheet(bad, tiles, opt));
    EXPECT_NE(bad.geterror().find("every tile must be 10x6"), std::string::npos);
}
