// Jung's spatial and 3D filters (thesis chapter 5) against hand-computed windows, and equivalences:
// 1x1 windows, 3DMF(1x1) = MPE, 3DWTMF(1x1, w = 1) = TMPE, alpha = 0 = box mean, thread counts.
// Adaptive M (BufferVotes::PerSample): every sample votes once, by hand and as consequences.
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "filters/pixel/pixel_support.h"
#include "filters/window/window_support.h"
#include "mcstat/filters/pixel/median.h"
#include "mcstat/filters/pixel/tmpe.h"
#include "mcstat/filters/window/filter3d.h"
#include "mcstat/filters/window/mif.h"
#include "mcstat/filters/window/window_rank.h"
#include "mcstat/image/imageops.h"

using namespace mcstat;
using mcstat::testing::filter3D;
using mcstat::testing::kInf;
using mcstat::testing::kLuma;
using mcstat::testing::kNaN;
using mcstat::testing::medianImageFilter;

namespace {

SpatialParams params(int k, int l, int64_t w = 1, double alpha = 0.5,
                     EstimatorMode mode = EstimatorMode::Luminance) {
    SpatialParams p;
    p.luma = kLuma;
    p.windowWidth = k;
    p.windowHeight = l;
    p.centreWeight = w;
    p.alpha = alpha;
    p.mode = mode;
    return p;
}

/// A grey image (R = G = B = v) from rows of values.
std::vector<float> greyImage(const std::vector<std::vector<float>>& rows) {
    std::vector<float> img;
    for (const auto& r : rows)
        for (float v : r) img.insert(img.end(), {v, v, v});
    return img;
}

float wmifAt(const std::vector<float>& img, int w, int h, int x, int y, const SpatialParams& p,
             PixelEstimate* est = nullptr) {
    SpatialScratch s;
    PixelEstimate e;
    wmifPixel({img.data(), w, h}, x, y, p, e, s);
    if (est) *est = e;
    EXPECT_EQ(e.rgb[0], e.rgb[1]);
    EXPECT_EQ(e.rgb[0], e.rgb[2]);
    return e.rgb[0];
}

/// A w x h grid of pixels with M buffers each, grey values and counts given per (pixel, buffer).
struct Grid {
    int width, height, M;
    std::vector<float> mean, count;
    Grid(int w, int h, int m) : width(w), height(h), M(m) {
        mean.assign(size_t(w) * h * m * 3, 0.f);
        count.assign(size_t(w) * h * m, 1.f);
    }
    void set(int x, int y, int j, float v, float n = 1.f) {
        const size_t i = (size_t(y) * width + x) * M + j;
        mean[i * 3] = mean[i * 3 + 1] = mean[i * 3 + 2] = v;
        count[i] = n;
    }
    FixedBufferGrid fixed() const { return {mean.data(), count.data(), width, height, M}; }
};

PixelEstimate filter3DAt(const FixedBufferGrid& g, int x, int y, const SpatialParams& p) {
    SpatialScratch s;
    PixelEstimate e;
    filter3DPixel(g.view(), x, y, p, e, s);
    return e;
}

/// Random statistics image: lognormal-ish means, some fireflies, unequal counts, a few NaN buffers.
StatsImage randomStats(int w, int h, int M, unsigned seed) {
    StatsImage s;
    s.header.width = w;
    s.header.height = h;
    s.header.M = M;
    std::string err;
    EXPECT_TRUE(s.allocate(err)) << err;
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (size_t i = 0; i < s.bufferCount.size(); ++i) {
        const float f = u(rng) < 0.03f ? 300.f : 1.f;
        for (int c = 0; c < 3; ++c) s.bufferMean[i * 3 + c] = (0.1f + u(rng)) * f;
        s.bufferCount[i] = float(1 + int(u(rng) * 4));
        if (u(rng) < 0.01f) s.bufferMean[i * 3 + 1] = kNaN;
        if (u(rng) < 0.01f) s.bufferCount[i] = 0.f;
    }
    return s;
}

}  // namespace

TEST(SpatialFilters, TrimCount) {
    EXPECT_EQ(spatialTrim(0.5, 9), 4);   // median of 9
    EXPECT_EQ(spatialTrim(0.5, 10), 4);  // two middle values of 10 remain
    EXPECT_EQ(spatialTrim(0.0, 9), 0);
    EXPECT_EQ(spatialTrim(0.25, 11), 2);        // floor(2.75)
    EXPECT_EQ(spatialTrim(3.0 / 17.0, 17), 3);  // alpha = i/s survives binary rounding
    EXPECT_EQ(spatialTrim(0.5, 1), 0);
    EXPECT_EQ(spatialTrim(0.5, 2), 0);
}

TEST(SpatialFilters, ValidatesParameters) {
    std::string err;
    EXPECT_TRUE(validateSpatialParams(params(3, 5, 7, 0.1), err)) << err;
    EXPECT_FALSE(validateSpatialParams(params(2, 3), err));
    EXPECT_NE(err.find("width"), std::string::npos) << err;
    EXPECT_FALSE(validateSpatialParams(params(3, 257), err));
    EXPECT_FALSE(validateSpatialParams(params(3, 3, 0), err));
    EXPECT_FALSE(validateSpatialParams(params(3, 3, 1, 0.6), err));
    EXPECT_FALSE(validateSpatialParams(params(3, 3, 1, kNaN), err));
}

TEST(SpatialFilters, WeightedTrimmedMeanHandComputed) {
    // values 1, 5, 2, 9, 3 with weights 1, 1, 1, 3, 1: duplicated and sorted
    // 1 2 3 5 9 9 9 (s = 7): median rank 4 = 5
    const float v[5][3] = {{1, 1, 1}, {5, 5, 5}, {2, 2, 2}, {9, 9, 9}, {3, 3, 3}};
    std::vector<WindowElement> e;
    const int64_t w[5] = {1, 1, 1, 3, 1};
    for (int i = 0; i < 5; ++i) e.push_back({v[i], 1.0, w[i]});
    SpatialScratch s;
    PixelEstimate out;
    weightedTrimmedMean(e.data(), 5, params(1, 1), out, s);
    EXPECT_EQ(out.rgb[0], 5.f);
    EXPECT_EQ(out.kept[0], 1);
    // alpha = 2/7: trim 2 copies per side: 3 5 9 -> (3 + 5 + 9) / 3
    weightedTrimmedMean(e.data(), 5, params(1, 1, 1, 2.0 / 7.0), out, s);
    EXPECT_FLOAT_EQ(out.rgb[0], 17.f / 3.f);
    EXPECT_EQ(out.kept[0], 3);
    // alpha = 1/7: 2 3 5 9 9 -> the two kept copies of 9 both count
    weightedTrimmedMean(e.data(), 5, params(1, 1, 1, 1.0 / 7.0), out, s);
    EXPECT_FLOAT_EQ(out.rgb[0], (2.f + 3.f + 5.f + 18.f) / 5.f);
    // counts weight the average, not the ranks: 9 with count 4 -> (2 + 3 + 5 + 2*4*9) / (3 + 8)
    e[3].count = 4.0;
    weightedTrimmedMean(e.data(), 5, params(1, 1, 1, 1.0 / 7.0), out, s);
    EXPECT_FLOAT_EQ(out.rgb[0], (2.f + 3.f + 5.f + 72.f) / 11.f);
    weightedTrimmedMean(e.data(), 5, params(1, 1), out, s);
    EXPECT_EQ(out.rgb[0], 5.f);  // the median's rank did not move
    // no element: black
    weightedTrimmedMean(e.data(), 0, params(1, 1), out, s);
    EXPECT_EQ(out.rgb[0], 0.f);
    EXPECT_EQ(out.kept[0], 0);
}

TEST(SpatialFilters, MedianImageFilterInteriorEdgeAndCorner) {
    // 4 x 3 image
    const std::vector<float> img = greyImage({{1, 2, 3, 4},  //
                                              {8, 7, 6, 5},
                                              {9, 10, 11, 12}});
    const SpatialParams p = params(3, 3);
    // interior (1, 1): 1 2 3 8 7 6 9 10 11 -> sorted 1 2 3 6 7 8 9 10 11 -> 7
    EXPECT_EQ(wmifAt(img, 4, 3, 1, 1, p), 7.f);
    // interior (2, 1): 2 3 4 7 6 5 10 11 12 -> 6
    EXPECT_EQ(wmifAt(img, 4, 3, 2, 1, p), 6.f);
    // corner (0, 0), clipped to 2 x 2: 1 2 8 7 -> even s = 4: (2 + 7) / 2
    PixelEstimate e;
    EXPECT_EQ(wmifAt(img, 4, 3, 0, 0, p, &e), 4.5f);
    EXPECT_EQ(e.kept[0], 2);
    // corner (3, 2): 6 5 11 12 -> (6 + 11) / 2
    EXPECT_EQ(wmifAt(img, 4, 3, 3, 2, p), 8.5f);
    // top edge (1, 0), 3 x 2: 1 2 3 8 7 6 -> (3 + 6) / 2
    EXPECT_EQ(wmifAt(img, 4, 3, 1, 0, p), 4.5f);
    // left edge (0, 1), 2 x 3: 1 2 8 7 9 10 -> (7 + 8) / 2
    EXPECT_EQ(wmifAt(img, 4, 3, 0, 1, p), 7.5f);
    // 3 x 1 window (k = width): row 1 at x = 2: 7 6 5 -> 6; 1 x 3 at (2, 1): 3 6 11 -> 6
    EXPECT_EQ(wmifAt(img, 4, 3, 2, 1, params(3, 1)), 6.f);
    EXPECT_EQ(wmifAt(img, 4, 3, 3, 1, params(1, 3)), 5.f);  // 4 5 12
    // a window larger than the image: the whole image, 12 values -> (6 + 7) / 2
    EXPECT_EQ(wmifAt(img, 4, 3, 0, 0, params(9, 9)), 6.5f);
}

TEST(SpatialFilters, CentreWeightOfEq528) {
    const std::vector<float> img = greyImage({{1, 2, 3},  //
                                              {4, 100, 5},
                                              {6, 7, 8}});
    // MIF: 1..8 and 100 -> median 5
    EXPECT_EQ(wmifAt(img, 3, 3, 1, 1, params(3, 3, 1)), 5.f);
    // w = 3: s = 11, 1 2 3 4 5 6 7 8 100 100 100 -> rank 6 = 6
    EXPECT_EQ(wmifAt(img, 3, 3, 1, 1, params(3, 3, 3)), 6.f);
    // w = 7: s = 15, rank 8 -> 8 (eight neighbours 1..8, then 100 x 7)
    EXPECT_EQ(wmifAt(img, 3, 3, 1, 1, params(3, 3, 7)), 8.f);
    // w = 9 >= the other weights + 1: the centre itself (an infinite weight is no filter)
    EXPECT_EQ(wmifAt(img, 3, 3, 1, 1, params(3, 3, 9)), 100.f);
    // w = 8: s = 16, the two middle copies are 8 and 100
    EXPECT_EQ(wmifAt(img, 3, 3, 1, 1, params(3, 3, 8)), 54.f);
    // at a corner the centre weight still applies: (0,0) w = 3: 1 1 1 2 4 100 -> (1 + 2) / 2
    EXPECT_EQ(wmifAt(img, 3, 3, 0, 0, params(3, 3, 3)), 1.5f);
}

TEST(SpatialFilters, OneByOneWindowIsIdentity) {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(-1.f, 50.f);
    std::vector<float> img(7 * 5 * 3);
    for (float& v : img) v = u(rng);
    std::vector<float> out(img.size());
    for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel})
        for (int64_t w : {1, 5}) {
            wmifImage({img.data(), 7, 5}, params(1, 1, w, 0.5, mode), out.data());
            EXPECT_EQ(out, img);
        }
}

TEST(SpatialFilters, LuminanceModeReturnsAPixelsColorChannelModeMixes) {
    // three pixels in a row; luminance ranks B < A < C; channels rank differently
    const std::vector<float> img = {0.9f, 0.1f, 0.1f,   // A: Y = 0.2709
                                    0.0f, 0.2f, 0.0f,   // B: Y = 0.1430
                                    0.1f, 0.9f, 0.5f};  // C: Y = 0.7014
    SpatialScratch s;
    PixelEstimate e;
    wmifPixel({img.data(), 3, 1}, 1, 0, params(3, 1), e, s);
    EXPECT_EQ(e.rgb, (std::array<float, 3>{0.9f, 0.1f, 0.1f}));  // A, whole
    wmifPixel({img.data(), 3, 1}, 1, 0, params(3, 1, 1, 0.5, EstimatorMode::PerChannel), e, s);
    EXPECT_EQ(e.rgb, (std::array<float, 3>{0.1f, 0.2f, 0.1f}));  // no pixel's colour
    EXPECT_EQ(e.kept, (std::array<int, 3>{1, 1, 1}));
}

TEST(SpatialFilters, TiesAreBrokenByWindowOrder) {
    // luma 1,1,1: all three pixels have Y = 3; the median rank is the second in row-major order
    const std::vector<float> img = {1, 2, 0, 2, 1, 0, 0, 0, 3};
    SpatialParams p = params(3, 1);
    p.luma = {1.0, 1.0, 1.0};
    SpatialScratch s;
    PixelEstimate e;
    wmifPixel({img.data(), 3, 1}, 1, 0, p, e, s);
    EXPECT_EQ(e.rgb, (std::array<float, 3>{2, 1, 0}));
    // at x = 0 only pixels 0, 1 (s = 2): their average
    wmifPixel({img.data(), 3, 1}, 0, 0, p, e, s);
    EXPECT_EQ(e.rgb, (std::array<float, 3>{1.5f, 1.5f, 0.f}));
}

TEST(SpatialFilters, NonFinitePixelsAreLeftOut) {
    std::vector<float> img = greyImage({{1, 2, 3},  //
                                        {4, 0, 5},
                                        {6, 7, 8}});
    img[4 * 3 + 1] = kNaN;  // centre G
    img[0] = kInf;          // (0,0) R
    PixelEstimate e;
    // centre: 2 3 4 5 6 7 8 (7 valid) -> 5
    EXPECT_EQ(wmifAt(img, 3, 3, 1, 1, params(3, 3, 5), &e), 5.f);
    EXPECT_EQ(e.excluded, 2);
    EXPECT_EQ(e.kept[0], 1);
    // (0, 0): 2 4 (NaN centre pixel and Inf corner left out) -> 3
    EXPECT_EQ(wmifAt(img, 3, 3, 0, 0, params(3, 3)), 3.f);
    // a window with nothing valid is black
    std::vector<float> bad(3 * 3 * 3, kNaN);
    EXPECT_EQ(wmifAt(bad, 3, 3, 1, 1, params(3, 3), &e), 0.f);
    EXPECT_EQ(e.kept[0], 0);
    EXPECT_EQ(e.excluded, 9);
}

TEST(SpatialFilters, Filter3DHandComputed) {
    // 3 x 2 pixels, M = 2
    Grid g(3, 2, 2);
    const float v[2][3][2] = {{{1, 2}, {3, 40}, {5, 6}}, {{7, 8}, {9, 10}, {11, 12}}};
    for (int y = 0; y < 2; ++y)
        for (int x = 0; x < 3; ++x)
            for (int j = 0; j < 2; ++j) g.set(x, y, j, v[y][x][j]);
    const FixedBufferGrid f = g.fixed();
    // (1, 0), window 3 x 2 (all 12 buffers): 1 2 3 5 6 7 8 9 10 11 12 40 -> (7 + 8) / 2
    EXPECT_EQ(filter3DAt(f, 1, 0, params(3, 3)).rgb[0], 7.5f);
    // 3DWMF w = 3: the centre's 3 and 40 count 3 times: s = 16, ranks 8, 9 (1-based) of
    // 1 2 3 3 3 5 6 7 8 9 10 11 12 40 40 40 -> (7 + 8) / 2
    EXPECT_EQ(filter3DAt(f, 1, 0, params(3, 3, 3)).rgb[0], 7.5f);
    // (the centre's buffers sit at both ends, so any w keeps 7.5 here); at (1, 1) the centre holds
    // 9 and 10: w = 3 gives s = 16, 1 2 3 5 6 7 8 9 9 9 10 10 10 11 12 40 -> ranks 8, 9 = 9, 9
    EXPECT_EQ(filter3DAt(f, 1, 0, params(3, 3, 5)).rgb[0], 7.5f);
    EXPECT_EQ(filter3DAt(f, 1, 1, params(3, 3, 1)).rgb[0], 7.5f);
    EXPECT_EQ(filter3DAt(f, 1, 1, params(3, 3, 3)).rgb[0], 9.f);
    // corner (0, 0), clipped window 2 x 2: 1 2 3 40 7 8 9 10 -> (7 + 8) / 2
    EXPECT_EQ(filter3DAt(f, 0, 0, params(3, 3)).rgb[0], 7.5f);
    // 3DWTMF alpha = 0.25, w = 1 at (0, 0): s = 8, trim 2: 3 7 8 9 -> 6.75
    EXPECT_EQ(filter3DAt(f, 0, 0, params(3, 3, 1, 0.25)).rgb[0], 6.75f);
    // counts: buffer (0,0,0) holds 3 samples of 1, kept only at alpha = 0 -> the window's
    // sample mean (1*3 + 2 + 3 + 40 + 7 + 8 + 9 + 10) / 10
    g.set(0, 0, 0, 1.f, 3.f);
    const FixedBufferGrid f2 = g.fixed();
    EXPECT_FLOAT_EQ(filter3DAt(f2, 0, 0, params(3, 3, 1, 0.0)).rgb[0], 82.f / 10.f);
    EXPECT_EQ(filter3DAt(f2, 0, 0, params(3, 3)).rgb[0], 7.5f);  // ranks unchanged
}

TEST(SpatialFilters, Filter3DOneByOneIsMPEAndTMPE) {
    const StatsImage s = randomStats(9, 7, 6, 11);  // even M; unequal counts; NaN and empty buffers
    const FixedBufferGrid g{s.bufferMean.data(), s.bufferCount.data(), 9, 7, 6};
    EstimatorScratch es;
    for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
        TmpeParams ep;  // MPE takes its PixelParams part
        ep.luma = kLuma;
        ep.mode = mode;
        for (int y = 0; y < 7; ++y)
            for (int x = 0; x < 9; ++x) {
                PixelEstimate mpe, tm, out;
                estimateMoN(g.at(x, y), ep, mpe, es);
                for (int64_t w : {1, 4}) {  // any centre weight: 1x1 holds only the centre
                    out = filter3DAt(g, x, y, params(1, 1, w, 0.5, mode));
                    EXPECT_EQ(out.rgb, mpe.rgb) << x << "," << y << " w " << w;
                    EXPECT_EQ(out.excluded, mpe.excluded);
                }
                for (double a : {0.0, 1.0 / 6.0, 0.2, 0.34}) {
                    ep.alpha = a;
                    estimateTMPE(g.at(x, y), ep, tm, es);
                    out = filter3DAt(g, x, y, params(1, 1, 1, a, mode));
                    // same kept set and weights; the sums run in another order
                    for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(out.rgb[c], tm.rgb[c]) << a;
                    EXPECT_EQ(out.kept, tm.kept) << a;
                }
            }
    }
}

TEST(SpatialFilters, Filter3DAlphaZeroIsTheWindowsSampleMean) {
    const StatsImage s = randomStats(6, 5, 3, 5);
    const FixedBufferGrid g{s.bufferMean.data(), s.bufferCount.data(), 6, 5, 3};
    for (int y = 0; y < 5; ++y)
        for (int x = 0; x < 6; ++x) {
            double sum[3] = {0, 0, 0}, n = 0;
            for (int yy = std::max(0, y - 1); yy <= std::min(4, y + 1); ++yy)
                for (int xx = std::max(0, x - 1); xx <= std::min(5, x + 1); ++xx) {
                    const PixelBuffers px = g.at(xx, yy);
                    for (int j = 0; j < 3; ++j) {
                        const float* m = px.mean + 3 * j;
                        if (!std::isfinite(m[1]) || px.count[j] == 0.f) continue;
                        n += px.count[j];
                        for (int c = 0; c < 3; ++c) sum[c] += px.count[j] * double(m[c]);
                    }
                }
            const PixelEstimate e = filter3DAt(g, x, y, params(3, 3, 1, 0.0));
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(e.rgb[c], sum[c] / n, 1e-5 * sum[c] / n);
        }
}

TEST(SpatialFilters, Filter3DWithVariableBuffersPerPixel) {
    // 3 x 1 pixels holding 1, 3 and 2 buffers: the view's accessor decides M per pixel
    struct Var {
        std::vector<std::vector<float>> mean, count;
    } var;
    var.mean = {{4, 4, 4}, {1, 1, 1, 2, 2, 2, 100, 100, 100}, {3, 3, 3, 5, 5, 5}};
    var.count = {{2}, {1, 1, 1}, {1, 1}};
    BufferView v{3, 1, &var, [](const void* ctx, int x, int) {
                     const Var& d = *static_cast<const Var*>(ctx);
                     return PixelBuffers{d.mean[size_t(x)].data(), d.count[size_t(x)].data(),
                                         int(d.count[size_t(x)].size())};
                 }};
    SpatialScratch s;
    PixelEstimate e;
    // centre x = 1, window 3 x 1: 4 | 1 2 100 | 3 5 -> 1 2 3 4 5 100 -> (3 + 4) / 2 count-weighted
    // (3 * 1 + 4 * 2) / 3
    filter3DPixel(v, 1, 0, params(3, 1), e, s);
    EXPECT_FLOAT_EQ(e.rgb[0], 11.f / 3.f);
    // w = 2 on the centre: 1 1 2 2 3 4 5 100 100 -> rank 5 = 3
    filter3DPixel(v, 1, 0, params(3, 1, 2), e, s);
    EXPECT_EQ(e.rgb[0], 3.f);
    // x = 0: 4 (w) | 1 2 100 -> s = 4 + w - 1 ... w = 1: 1 2 4 100 -> (2 + 4 * 2) / 3
    filter3DPixel(v, 0, 0, params(3, 1), e, s);
    EXPECT_FLOAT_EQ(e.rgb[0], 10.f / 3.f);
}

TEST(SpatialFilters, Filter3DNaNBuffersAndEmptyWindows) {
    Grid g(2, 1, 3);
    g.set(0, 0, 0, 1.f);
    g.set(0, 0, 1, kNaN);
    g.set(0, 0, 2, 3.f, 0.f);  // empty buffer: no information
    g.set(1, 0, 0, 5.f);
    g.set(1, 0, 1, kInf);
    g.set(1, 0, 2, 2.f);
    const FixedBufferGrid f = g.fixed();
    // 1 | 5 2 -> 2
    PixelEstimate e = filter3DAt(f, 0, 0, params(3, 3));
    EXPECT_EQ(e.rgb[0], 2.f);
    EXPECT_EQ(e.excluded, 2);
    Grid bad(1, 1, 2);
    bad.set(0, 0, 0, kNaN);
    bad.set(0, 0, 1, 1.f, 0.f);
    e = filter3DAt(bad.fixed(), 0, 0, params(3, 3));
    EXPECT_EQ(e.rgb, (std::array<float, 3>{0.f, 0.f, 0.f}));
    EXPECT_EQ(e.kept[0], 0);
    EXPECT_EQ(e.excluded, 1);
}

TEST(SpatialFilters, HugeCentreWeightIsMPEOfTheCentre) {
    // "for an infinite weight for the pixel that needs to be estimated, 3DWTMF becomes MPE"
    StatsImage s = randomStats(5, 5, 7, 23);
    for (int j = 0; j < 7; ++j) {  // a centre with 7 valid buffers (odd: one median buffer)
        const size_t i = size_t(2 * 5 + 2) * 7 + size_t(j);
        s.bufferCount[i] = float(1 + j % 3);
        s.bufferMean[i * 3 + 1] = 0.5f + float(j);
    }
    const FixedBufferGrid g{s.bufferMean.data(), s.bufferCount.data(), 5, 5, 7};
    PixelParams ep;
    ep.luma = kLuma;
    EstimatorScratch es;
    PixelEstimate mpe;
    estimateMoN(g.at(2, 2), ep, mpe, es);
    // the 8 neighbours hold at most 56 buffers; w = 1000 makes the centre's copies dominate
    EXPECT_EQ(filter3DAt(g, 2, 2, params(3, 3, 1000)).rgb, mpe.rgb);
}

TEST(SpatialFilters, ImageBufFormsAreThreadCountIndependent) {
    const int w = 37, h = 23;
    const StatsImage s = randomStats(w, h, 5, 99);
    for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
        const SpatialParams p = params(3, 5, 3, 0.2, mode);
        OIIO::ImageBuf a = filter3D(s, p, {}, 1), b = filter3D(s, p, {}, 3);
        ASSERT_FALSE(a.has_error()) << a.geterror();
        std::vector<float> pa(size_t(w) * h * 3), pb(pa.size()), pure(pa.size());
        a.get_pixels(a.roi(), OIIO::TypeDesc::FLOAT, pa.data());
        b.get_pixels(b.roi(), OIIO::TypeDesc::FLOAT, pb.data());
        EXPECT_EQ(pa, pb);
        const FixedBufferGrid g{s.bufferMean.data(), s.bufferCount.data(), w, h, 5};
        filter3DImage(g.view(), p, pure.data());
        EXPECT_EQ(pa, pure);
        // MIF over that result, as an image
        OIIO::ImageBuf m1 = medianImageFilter(a, p, {}, 1), m3 = medianImageFilter(a, p, {}, 3);
        ASSERT_FALSE(m1.has_error()) << m1.geterror();
        m1.get_pixels(m1.roi(), OIIO::TypeDesc::FLOAT, pa.data());
        m3.get_pixels(m3.roi(), OIIO::TypeDesc::FLOAT, pb.data());
        EXPECT_EQ(pa, pb);
        wmifImage({pure.data(), w, h}, p, pb.data());
        EXPECT_EQ(pa, pb);
        // a tile sees the whole image: its pixels equal those of the full result
        OIIO::ImageBuf tile = filter3D(s, p, OIIO::ROI(10, 20, 5, 9), 2);
        ASSERT_EQ(tile.roi(), OIIO::ROI(10, 20, 5, 9, 0, 1, 0, 3));
        for (int y = 5; y < 9; ++y)
            for (int x = 10; x < 20; ++x)
                for (int c = 0; c < 3; ++c)
                    EXPECT_EQ(tile.getchannel(x, y, 0, c), a.getchannel(x, y, 0, c));
    }
}

TEST(SpatialFilters, ImageBufFormsReportErrors) {
    const StatsImage s = randomStats(4, 4, 3, 1);
    OIIO::ImageBuf bad = filter3D(s, params(2, 3));
    EXPECT_TRUE(bad.has_error());
    OIIO::ImageBuf grey(OIIO::ImageSpec(4, 4, 1, OIIO::TypeDesc::FLOAT));
    OIIO::ImageBuf m = medianImageFilter(grey, params(3, 3));
    EXPECT_NE(m.geterror().find("R, G, B"), std::string::npos);
}

TEST(SpatialFilters, ImageBufFormOnAdaptiveBufferCounts) {
    // the same 3 x 1 pixels as Filter3DWithVariableBuffersPerPixel, stored with adaptive M
    StatsImage s;
    s.header.width = 3;
    s.header.height = 1;
    s.header.M = 3;
    s.header.formatVersion = 2;
    std::string err;
    ASSERT_TRUE(s.allocateAdaptive({1, 3, 2}, err)) << err;
    const float means[6] = {4, 1, 2, 100, 3, 5}, counts[6] = {2, 1, 1, 1, 1, 1};
    for (int k = 0; k < 6; ++k) {
        for (int c = 0; c < 3; ++c) s.bufferMean[size_t(k) * 3 + size_t(c)] = means[k];
        s.bufferCount[size_t(k)] = counts[k];
    }
    // an adaptive file votes per sample: the 4 of count 2 is two copies (per buffer the results
    // would be 11/3 and 10/3, Filter3DWithVariableBuffersPerPixel)
    OIIO::ImageBuf out = filter3D(s, params(3, 1), {}, 2);
    ASSERT_FALSE(out.has_error()) << out.geterror();
    // x = 1: 4 4 | 1 2 100 | 3 5 -> 1 2 3 4 4 5 100 -> 4
    EXPECT_EQ(out.getchannel(1, 0, 0, 0), 4.f);
    // x = 0: 4 4 | 1 2 100 -> 1 2 4 4 100 -> 4
    EXPECT_EQ(out.getchannel(0, 0, 0, 0), 4.f);
    // x = 2: 1 2 100 | 3 5 -> 3
    EXPECT_EQ(out.getchannel(2, 0, 0, 0), 3.f);
}

// ---- adaptive M: every sample votes once (BufferVotes::PerSample) -------------------------------

namespace {

/// A width x height grid of pixels with their own buffers (adaptive M), added in row order.
struct VarGrid {
    int width = 0, height = 0;
    std::vector<std::vector<float>> mean, count;  // per pixel: [j*3 + c], [j]
    VarGrid(int w, int h) : width(w), height(h) {}
    void add(const std::vector<std::array<float, 3>>& rgb, const std::vector<float>& n) {
        mean.emplace_back();
        for (const auto& c : rgb) mean.back().insert(mean.back().end(), c.begin(), c.end());
        count.push_back(n);
    }
    void addGrey(const std::vector<float>& v, const std::vector<float>& n) {
        std::vector<std::array<float, 3>> rgb;
        for (float x : v) rgb.push_back({x, x, x});
        add(rgb, n);
    }
    BufferView view(BufferVotes votes) const {
        return {
            width, height, this,
            [](const void* ctx, int x, int y) {
                const auto* g = static_cast<const VarGrid*>(ctx);
                const size_t p = size_t(y) * size_t(g->width) + size_t(x);
                return PixelBuffers{g->mean[p].data(), g->count[p].data(), int(g->count[p].size())};
            },
            votes};
    }
};

PixelEstimate filter3DAt(const VarGrid& g, BufferVotes votes, int x, int y,
                         const SpatialParams& p) {
    SpatialScratch s;
    PixelEstimate e;
    filter3DPixel(g.view(votes), x, y, p, e, s);
    // the whole-image path (RankedBufferGrid) agrees
    std::vector<float> img(size_t(g.width) * size_t(g.height) * 3);
    filter3DImage(g.view(votes), p, img.data());
    for (int c = 0; c < 3; ++c)
        EXPECT_EQ(img[(size_t(y) * size_t(g.width) + size_t(x)) * 3 + size_t(c)], e.rgb[c]);
    return e;
}

constexpr BufferVotes kPerBuffer = BufferVotes::PerBuffer, kPerSample = BufferVotes::PerSample;

/// The 3 x 1 row of the brief: a one-buffer centre (90 samples of 1) between a 9-buffer pixel (10
/// samples each: eight of 100, one of 0.5) and a one-buffer pixel (90 samples of 2).
VarGrid noisyNeighbourRow() {
    VarGrid g(3, 1);
    g.addGrey({100, 100, 100, 0.5f, 100, 100, 100, 100, 100}, std::vector<float>(9, 10.f));
    g.addGrey({1}, {90});
    g.addGrey({2}, {90});
    return g;
}

}  // namespace

TEST(SpatialFilters, Filter3DPerSampleVotesHandComputed) {
    const VarGrid g = noisyNeighbourRow();
    // 3DMF at x = 1. Per buffer: 0.5 1 2 100 x 8, s = 11 -> rank 5 (0-based) = 100: the noisy pixel
    // outvotes both one-buffer pixels.
    PixelEstimate e = filter3DAt(g, kPerBuffer, 1, 0, params(3, 1));
    EXPECT_EQ(e.rgb[0], 100.f);
    // Per sample: 0.5 x 10, 1 x 90, 2 x 90, 100 x 80, s = 270, c = 134: copies 134 and 135 are 2.
    e = filter3DAt(g, kPerSample, 1, 0, params(3, 1));
    EXPECT_EQ(e.rgb, (std::array<float, 3>{2.f, 2.f, 2.f}));
    EXPECT_EQ(e.kept[0], 1);
    EXPECT_EQ(e.excluded, 0);
    // border x = 0: 0.5 x 10, 1 x 90, 100 x 80, s = 180, c = 89: copies 89, 90 are 1 (per buffer:
    // 0.5 1 100 x 8 -> 100)
    EXPECT_EQ(filter3DAt(g, kPerSample, 0, 0, params(3, 1)).rgb[0], 1.f);
    EXPECT_EQ(filter3DAt(g, kPerBuffer, 0, 0, params(3, 1)).rgb[0], 100.f);
    // 3DWMF w = 2: the centre's 90 samples are 180 copies, s = 360, c = 179: copies 179, 180 in
    // 10..189 = 1 (per buffer: s = 12, ranks 5, 6 = 100, 100)
    EXPECT_EQ(filter3DAt(g, kPerSample, 1, 0, params(3, 1, 2)).rgb[0], 1.f);
    EXPECT_EQ(filter3DAt(g, kPerBuffer, 1, 0, params(3, 1, 2)).rgb[0], 100.f);
    // 3DWTMF alpha = 0.25: c = floor(67.5) = 67, copies 67..202 kept: 33 of the 90 copies of 1
    // (partly trimmed), all of 2, the first 100-buffer whole and 3 copies of the second; every kept
    // copy is one sample: (33 + 180 + 1300) / 136
    e = filter3DAt(g, kPerSample, 1, 0, params(3, 1, 1, 0.25));
    EXPECT_EQ(e.rgb[0], float((33.0 * 1.0 + 90.0 * 2.0 + 13.0 * 100.0) / 136.0));
    EXPECT_EQ(e.kept[0], 4);
    // per buffer: s = 11, c = 2: 2 and six 100-buffers, count-weighted (180 + 6000) / 150
    EXPECT_FLOAT_EQ(filter3DAt(g, kPerBuffer, 1, 0, params(3, 1, 1, 0.25)).rgb[0], 41.2f);
    // the same with w = 3 per sample: s = 450, c = 112, copies 112..337 kept: 1 x 168 (the centre's
    // 270 copies are 10..279), 2 x 58 (280..337) -> (168 + 116) / 226
    e = filter3DAt(g, kPerSample, 1, 0, params(3, 1, 3, 0.25));
    EXPECT_FLOAT_EQ(e.rgb[0], (168.f + 116.f) / 226.f);
    EXPECT_EQ(e.kept[0], 2);
    // alpha = 0, nothing trimmed: the window's sample mean (w = 1), the centre's samples counted w
    // times (w = 2), whether buffers vote per buffer or per sample.
    EXPECT_FLOAT_EQ(filter3DAt(g, kPerBuffer, 1, 0, params(3, 1, 1, 0.0)).rgb[0],
                    (10.f * 0.5f + 80.f * 100.f + 90.f * 1.f + 90.f * 2.f) / 270.f);
    EXPECT_FLOAT_EQ(filter3DAt(g, kPerBuffer, 1, 0, params(3, 1, 2, 0.0)).rgb[0],
                    (10.f * 0.5f + 80.f * 100.f + 180.f * 1.f + 90.f * 2.f) / 360.f);
    EXPECT_FLOAT_EQ(filter3DAt(g, kPerSample, 1, 0, params(3, 1, 1, 0.0)).rgb[0],
                    (10.f * 0.5f + 80.f * 100.f + 90.f * 1.f + 90.f * 2.f) / 270.f);
    EXPECT_FLOAT_EQ(filter3DAt(g, kPerSample, 1, 0, params(3, 1, 2, 0.0)).rgb[0],
                    (10.f * 0.5f + 80.f * 100.f + 180.f * 1.f + 90.f * 2.f) / 360.f);
}

TEST(SpatialFilters, Filter3DPerSampleVotesInvalidAndEmptyBuffers) {
    VarGrid g(3, 1);
    // left: empty, NaN mean, Inf count, count 2.5, count 2^24 + 2, then 4 samples of 3
    g.addGrey({100, kNaN, 50, 60, 70, 3}, {0, 5, kInf, 2.5f, 16777218.f, 4});
    g.addGrey({1}, {2});
    g.addGrey({5}, {3});
    // per sample: counts that are no integer or above 2^24 cannot vote: 1 1 3 3 3 3 5 5 5 -> 3
    PixelEstimate e = filter3DAt(g, kPerSample, 1, 0, params(3, 1));
    EXPECT_EQ(e.rgb[0], 3.f);
    EXPECT_EQ(e.excluded, 4);
    EXPECT_EQ(e.kept[0], 1);
    // per buffer they are elements: 1 3 5 60 70 -> 5; only NaN and Inf are excluded
    e = filter3DAt(g, kPerBuffer, 1, 0, params(3, 1));
    EXPECT_EQ(e.rgb[0], 5.f);
    EXPECT_EQ(e.excluded, 2);
    // a pixel with no voting buffer is no element; alone it gives black
    VarGrid none(1, 1);
    none.addGrey({7, 8, kNaN}, {0, 1.5f, 1});
    e = filter3DAt(none, kPerSample, 0, 0, params(3, 3));
    EXPECT_EQ(e.rgb, (std::array<float, 3>{0.f, 0.f, 0.f}));
    EXPECT_EQ(e.kept[0], 0);
    EXPECT_EQ(e.excluded, 2);
}

TEST(SpatialFilters, Filter3DPerSampleVotesLargeCountsAndWeights) {
    // counts up to 2^24 vote, even with the largest centre weight: copies of the order of
    // 10^6 * 2^25 stay exact
    VarGrid g(3, 1);
    g.addGrey({5}, {16777216.f});
    g.addGrey({9, 1}, {16777216.f, 16777215.f});
    g.addGrey({6}, {16777216.f});
    // 1x1: 1 x (2^24 - 1), 9 x 2^24: s odd, the middle copy is the first 9 (MPE: the two buffers
    // averaged by count, about 5)
    EXPECT_EQ(filter3DAt(g, kPerSample, 1, 0, params(1, 1)).rgb[0], 9.f);
    EXPECT_FLOAT_EQ(filter3DAt(g, kPerBuffer, 1, 0, params(1, 1)).rgb[0],
                    float((16777215.0 + 9.0 * 16777216.0) / 33554431.0));
    // 3x1: 1 x (2^24 - 1), 5, 6, 9 x 2^24 each: s = 2^26 - 1, median copy 2^25 - 1 is the first 6
    EXPECT_EQ(filter3DAt(g, kPerSample, 1, 0, params(3, 1)).rgb[0], 6.f);
    // w = 10^6: s = 10^6 (2^25 - 1) + 2^25 (about 3.4e13). The centre's own median sits one sample
    // from the boundary between its 1s and 9s, so even this weight leaves the median copy
    // (index 10^6 (2^24 - 1/2) + 2^24 - 1/2) among the 6s, 5 * 10^5 copies past the 5s
    EXPECT_EQ(filter3DAt(g, kPerSample, 1, 0, params(3, 1, kMaxCentreWeight)).rgb[0], 6.f);
    // with 10^6 more samples of 9 in the centre its median copy wins
    VarGrid g2 = g;
    g2.count[1] = {16777216.f, 15777215.f};
    EXPECT_EQ(filter3DAt(g2, kPerSample, 1, 0, params(3, 1, kMaxCentreWeight)).rgb[0], 9.f);
    EXPECT_EQ(filter3DAt(g2, kPerSample, 1, 0, params(3, 1, 1)).rgb[0], 6.f);
    // alpha = 0.25 of s = 2^26 - 1: c = floor(2^24 - 1/4) = 2^24 - 1 copies per side, exactly the
    // 1s; copies up to 3 * 2^24 - 1 kept: every 5 and 6 and the first 9, each weighing 2^24
    const double n = 16777216.0;
    const double expect = (5.0 * n * n + 6.0 * n * n + 9.0 * n) / (2.0 * n * n + n);
    PixelEstimate e = filter3DAt(g, kPerSample, 1, 0, params(3, 1, 1, 0.25));
    EXPECT_FLOAT_EQ(e.rgb[0], float(expect));
    EXPECT_EQ(e.kept[0], 3);
}

TEST(SpatialFilters, Filter3DPerSampleVotesChannelAndLuminanceModes) {
    VarGrid g(3, 1);
    // left: three one-sample buffers; centre: one buffer of 3 samples; right: one sample
    g.add({{4, 0, 9}, {5, 1, 9}, {6, 2, 9}}, {1, 1, 1});
    g.add({{1, 10, 5}}, {3});
    g.add({{0, 20, 0}}, {1});
    // per sample s = 7, median copy 3 (0-based). R: 0 1 1 1 4 5 6 -> 1; G: 0 1 2 10 10 10 20 -> 10;
    // B: 0 5 5 5 9 9 9 -> 5: the centre's three samples win every channel
    PixelEstimate e =
        filter3DAt(g, kPerSample, 1, 0, params(3, 1, 1, 0.5, EstimatorMode::PerChannel));
    EXPECT_EQ(e.rgb, (std::array<float, 3>{1.f, 10.f, 5.f}));
    EXPECT_EQ(e.kept, (std::array<int, 3>{1, 1, 1}));
    // per buffer s = 5, rank 2. R: 0 1 4 5 6 -> 4; G: 0 1 2 10 20 -> 2; B: 0 5 9 9 9 -> 9
    e = filter3DAt(g, kPerBuffer, 1, 0, params(3, 1, 1, 0.5, EstimatorMode::PerChannel));
    EXPECT_EQ(e.rgb, (std::array<float, 3>{4.f, 2.f, 9.f}));
    // luminance (Rec.709): left 1.50, 2.43, 3.36, centre 7.73 x 3, right 14.30 -> the centre
    e = filter3DAt(g, kPerSample, 1, 0, params(3, 1));
    EXPECT_EQ(e.rgb, (std::array<float, 3>{1.f, 10.f, 5.f}));
    // per buffer: 1.50 2.43 3.36 7.73 14.30 -> the third left buffer, whole
    e = filter3DAt(g, kPerBuffer, 1, 0, params(3, 1));
    EXPECT_EQ(e.rgb, (std::array<float, 3>{6.f, 2.f, 9.f}));
    // channel mode with alpha = 2/7 per sample: copies 2..4 kept, the centre's three copies partly
    // trimmed in every channel (2 kept), each copy one sample. R: 0 1 [1 1 4] 5 6 -> 6 / 3;
    // G: 0 1 [2 10 10] 10 20 -> 22 / 3; B: 0 5 [5 5 9] 9 9 -> 19 / 3
    e = filter3DAt(g, kPerSample, 1, 0, params(3, 1, 1, 2.0 / 7.0, EstimatorMode::PerChannel));
    EXPECT_FLOAT_EQ(e.rgb[0], 2.f);
    EXPECT_FLOAT_EQ(e.rgb[1], 22.f / 3.f);
    EXPECT_FLOAT_EQ(e.rgb[2], 19.f / 3.f);
    EXPECT_EQ(e.kept, (std::array<int, 3>{2, 2, 2}));
}

TEST(SpatialFilters, Filter3DOneByOnePerSampleIsTheCountWeightedMedian) {
    // 3DMF(1x1) on an adaptive pixel: the median of its samples' buffer means; MPE when the counts
    // are equal, not otherwise
    const struct {
        std::vector<float> v, n;
        float perSample, mpe;
    } cases[] = {
        {{1, 2, 10}, {3, 1, 1}, 1.f, 2.f},  // 1 1 1 2 10
        {{1, 2, 10}, {1, 3, 1}, 2.f, 2.f},  // 1 2 2 2 10
        {{1, 2, 10}, {2, 2, 2}, 2.f, 2.f},  // equal counts
        {{1, 3}, {3, 1}, 1.f, 1.5f},        // 1 1 1 3: copies 1, 2 are 1; MPE (3 + 3) / 4
        {{1, 3}, {2, 2}, 2.f, 2.f},         // 1 1 3 3: (1 + 3) / 2
        {{4, 1, 3, 2, 5}, {5, 5, 6, 5, 5}, 3.f, 3.f},
    };
    PixelParams ep;
    ep.luma = kLuma;
    EstimatorScratch es;
    for (const auto& c : cases) {
        VarGrid g(1, 1);
        g.addGrey(c.v, c.n);
        EXPECT_EQ(filter3DAt(g, kPerSample, 0, 0, params(1, 1)).rgb[0], c.perSample);
        for (int64_t w : {2, 7})  // a 1x1 window holds the centre only: any weight
            EXPECT_EQ(filter3DAt(g, kPerSample, 0, 0, params(1, 1, w)).rgb[0], c.perSample);
        PixelEstimate mpe;
        estimateMoN(g.view(kPerSample).at(0, 0), ep, mpe, es);
        EXPECT_EQ(mpe.rgb[0], c.mpe);
        EXPECT_EQ(filter3DAt(g, kPerBuffer, 0, 0, params(1, 1)).rgb[0], c.mpe);
    }
}

TEST(SpatialFilters, Filter3DPerSampleEqualCountsIsMPEOnRandomPixels) {
    // every buffer of a pixel holding n samples (n varies by pixel): 3DMF(1x1) per sample = MPE,
    // bit for bit (the kept copies are one buffer's, or one of each middle buffer), odd and even M,
    // both modes, NaN and empty buffers
    std::mt19937 rng(41);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    EstimatorScratch es;
    for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel})
        for (int trial = 0; trial < 300; ++trial) {
            VarGrid g(1, 1);
            const int m = 1 + int(u(rng) * 9.f);
            const float n = float(1 + int(u(rng) * 500.f));
            std::vector<std::array<float, 3>> rgb;
            std::vector<float> cnt;
            for (int j = 0; j < m; ++j) {
                const float f = u(rng) < 0.1f ? 300.f : 1.f;
                rgb.push_back({u(rng) * f, u(rng) * f, u(rng) * f});
                cnt.push_back(u(rng) < 0.05f ? 0.f : n);
                if (u(rng) < 0.05f) rgb.back()[1] = kNaN;
            }
            g.add(rgb, cnt);
            PixelParams ep;
            ep.luma = kLuma;
            ep.mode = mode;
            PixelEstimate mpe;
            estimateMoN(g.view(kPerSample).at(0, 0), ep, mpe, es);
            const PixelEstimate e = filter3DAt(g, kPerSample, 0, 0, params(1, 1, 1, 0.5, mode));
            EXPECT_EQ(e.rgb, mpe.rgb) << trial;
            EXPECT_EQ(e.excluded, mpe.excluded);
        }
}
