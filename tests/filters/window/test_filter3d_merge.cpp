// Differential test of the 3D filters (3DMF, 3DWMF, 3DWTMF; Jung eq. 5.19-5.21): the library's
// pre-sort-and-merge path (eq. 5.24) against a reference that builds every window's m x n elements
// and sorts them all, as the filters did before the merge. Results must be bit-identical: the same
// total order (ascending key, ties by window element order), the same kept copies and the same
// summation order. Random windows over fixed M in {1, 2, 3, 7, 17} and adaptive M (1..17 per
// pixel; buffers voting per sample, BufferVotes::PerSample, and per buffer), ties, all-equal
// values, zeros of both signs, NaN/Inf buffers and counts, empty buffers, huge ranges (1e-6..1e38),
// windows 1x1..7x7 clipped at borders, centre weights 1..5, alpha in [0, 0.5], luminance and
// per-channel modes, one and two threads, tiles.
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "filters/pixel/pixel_support.h"
#include "filters/window/window_support.h"
#include "mcstat/filters/window/filter3d.h"
#include "mcstat/filters/window/mif.h"
#include "mcstat/filters/window/window_rank.h"
#include "mcstat/image/imageops.h"

using namespace mcstat;
using mcstat::testing::filter3D;
using mcstat::testing::kInf;
using mcstat::testing::kLuma;
using mcstat::testing::kNaN;

namespace {

// ---- the reference: one full sort of the window's elements per pixel (and per channel) --------
// A verbatim copy of the full-sort implementation the merge replaced, kept here independent of the
// library so that the library can change without changing what it is compared with. The one
// addition is the per-sample vote of adaptive M (BufferVotes::PerSample) in filter3DPixel: buffer j
// of pixel q becomes the element (x_j, count 1, weight w_q n_j): n_j copies of one sample each, so
// the average counts every kept copy once; n_j must be an integer in [1, 2^24] (any
// other count makes the buffer invalid); with per-buffer votes the elements are as before.
namespace reference {

struct Scratch {
    std::vector<WindowElement> elems;
    std::vector<std::pair<double, int>> ranked;  // (rank key, element index)
    std::vector<int> valid;
};

int trimmedAverage(const WindowElement* e, const Scratch& s, int64_t lo, int64_t hi, int c0, int c1,
                   PixelEstimate& out) {
    double sum[3] = {0.0, 0.0, 0.0}, wsum = 0.0;
    int kept = 0;
    int64_t pos = 0;
    for (const auto& ki : s.ranked) {
        const WindowElement& el = e[ki.second];
        const int64_t a = std::max(pos, lo), b = std::min(pos + el.weight, hi);
        pos += el.weight;
        if (b <= a) {
            if (pos >= hi) break;
            continue;
        }
        const double w = double(b - a) * el.count;
        wsum += w;
        for (int c = c0; c < c1; ++c) sum[c] += w * double(el.rgb[c]);
        ++kept;
    }
    for (int c = c0; c < c1; ++c) out.rgb[size_t(c)] = float(sum[c] / wsum);
    return kept;
}

void weightedTrimmedMean(const WindowElement* elems, int n, const SpatialParams& p,
                         PixelEstimate& out, Scratch& s) {
    out.rgb = {0.f, 0.f, 0.f};
    out.gini = {0.f, 0.f, 0.f};
    out.kept = {0, 0, 0};
    if (n <= 0) return;
    int64_t total = 0;
    for (int i = 0; i < n; ++i) total += elems[i].weight;
    const int64_t c = spatialTrim(p.alpha, total);
    s.ranked.resize(size_t(n));
    if (p.mode == EstimatorMode::Luminance) {
        for (int i = 0; i < n; ++i) {
            const float* v = elems[i].rgb;
            s.ranked[size_t(i)] = {p.luma[0] * v[0] + p.luma[1] * v[1] + p.luma[2] * v[2], i};
        }
        std::sort(s.ranked.begin(), s.ranked.end());
        out.kept.fill(trimmedAverage(elems, s, c, total - c, 0, 3, out));
        return;
    }
    for (int ch = 0; ch < 3; ++ch) {
        for (int i = 0; i < n; ++i) s.ranked[size_t(i)] = {double(elems[i].rgb[ch]), i};
        std::sort(s.ranked.begin(), s.ranked.end());
        out.kept[size_t(ch)] = trimmedAverage(elems, s, c, total - c, ch, ch + 1, out);
    }
}

void filter3DPixel(const BufferView& v, int x, int y, const SpatialParams& p, PixelEstimate& out,
                   Scratch& s) {
    const int rx = p.windowWidth / 2, ry = p.windowHeight / 2;
    const int x0 = std::max(0, x - rx), x1 = std::min(v.width - 1, x + rx);
    const int y0 = std::max(0, y - ry), y1 = std::min(v.height - 1, y + ry);
    s.elems.clear();
    out.excluded = 0;
    for (int yy = y0; yy <= y1; ++yy)
        for (int xx = x0; xx <= x1; ++xx) {
            const PixelBuffers px = v.at(xx, yy);
            int excluded = 0;
            collectValidBuffers(px, s.valid, excluded);
            out.excluded += excluded;
            const int64_t w = (xx == x && yy == y) ? p.centreWeight : int64_t(1);
            for (int j : s.valid) {
                const float n = px.count[j];
                if (v.votes == BufferVotes::PerBuffer) {
                    s.elems.push_back({px.mean + 3 * size_t(j), double(n), w});
                } else if (n == std::floor(n) && n <= 16777216.f) {
                    s.elems.push_back({px.mean + 3 * size_t(j), 1.0, w * int64_t(n)});
                } else {
                    ++out.excluded;  // a count that cannot vote per sample
                }
            }
        }
    weightedTrimmedMean(s.elems.data(), int(s.elems.size()), p, out, s);
}

}  // namespace reference

// ---- random inputs ---------------------------------------------------------------------------

/// How the buffer values of one random image are drawn.
enum class Values { Smooth, Ties, AllEqual, Zeros, Huge, Fireflies, kCount };

struct Generator {
    std::mt19937 rng;
    explicit Generator(unsigned seed) : rng(seed) {}
    double u() { return std::uniform_real_distribution<double>(0.0, 1.0)(rng); }
    int pick(int n) { return std::uniform_int_distribution<int>(0, n - 1)(rng); }

    float value(Values kind) {
        switch (kind) {
            case Values::Smooth:
                return float(0.1 + u());
            case Values::Ties: {  // few distinct values, both zeros
                const float t[] = {0.f, -0.f, 1.f, 2.f, 0.5f, 3.f};
                return t[pick(6)];
            }
            case Values::AllEqual:
                return 0.75f;
            case Values::Zeros:
                return pick(2) ? 0.f : -0.f;
            case Values::Huge: {  // 1e-6 .. 1e38, either sign, some zeros
                if (pick(10) == 0) return 0.f;
                const float m = float(std::pow(10.0, -6.0 + 44.0 * u()));
                return pick(4) == 0 ? -m : m;
            }
            case Values::Fireflies:
            default:
                return float((0.1 + u()) * (pick(20) == 0 ? 1000.0 : 1.0));
        }
    }

    /// Fills one buffer: RGB means (grey or not), a count, now and then invalid or empty. `share`
    /// > 0 (adaptive grids): integral counts, mostly `share` (the pixel's samples split over its
    /// buffers as a render does), else 1..5, 1..2000 or 2^24.
    void buffer(float* mean, float* count, Values kind, bool grey, int invalidPercent,
                int share = 0) {
        const float g = value(kind);
        for (int c = 0; c < 3; ++c) mean[c] = grey ? g : value(kind);
        if (share > 0) {
            switch (pick(12)) {
                case 0:
                    *count = float(1 + pick(5));
                    break;
                case 1:
                    *count = float(1 + pick(2000));
                    break;
                case 2:
                    *count = 16777216.f;  // 2^24: the largest count that votes
                    break;
                default:
                    *count = float(share);
            }
        } else {
            switch (pick(6)) {
                case 0:
                    *count = float(1 + pick(5));
                    break;
                case 1:
                    *count = float(0.25 + 4.0 * u());
                    break;
                default:
                    *count = 1.f;
            }
        }
        if (pick(100) < invalidPercent) {
            switch (pick(8)) {
                case 0:
                    mean[pick(3)] = kNaN;
                    break;
                case 1:
                    mean[pick(3)] = pick(2) ? kInf : -kInf;
                    break;
                case 2:
                    *count = kNaN;
                    break;
                case 3:
                    *count = kInf;
                    break;
                case 4:
                    *count = -1.f;
                    break;
                case 5:  // valid per buffer, not per sample: not an integer, above 2^24
                    *count = pick(2) ? 2.5f : 16777218.f;
                    break;
                default:
                    *count = 0.f;  // empty buffer (spp < M): left out silently
            }
        }
    }
};

/// A grid of pixels with per-pixel buffer counts (fixed M when all equal).
struct RandomGrid {
    int width = 0, height = 0;
    BufferVotes votes = BufferVotes::PerBuffer;  // what filter3D takes for its layout
    std::vector<int> m;                          // buffers of pixel y*width + x
    std::vector<size_t> offset;                  // first buffer of each pixel, pixels + 1 entries
    std::vector<float> mean;                     // [k*3 + c]
    std::vector<float> count;                    // [k]
    BufferView view() const {
        return {width, height, this,
                [](const void* ctx, int x, int y) {
                    const auto* g = static_cast<const RandomGrid*>(ctx);
                    const size_t p = size_t(y) * size_t(g->width) + size_t(x);
                    const size_t k = g->offset[p];
                    return PixelBuffers{g->mean.data() + 3 * k, g->count.data() + k, g->m[p]};
                },
                votes};
    }
};

/// fixedM = 0: adaptive M, buffers voting per sample (as filter3D for an adaptive file), integral
/// counts. kind < 0: random values of a random kind.
RandomGrid randomGrid(Generator& g, int width, int height, int fixedM /* 0: adaptive */,
                      int forcedKind = -1) {
    RandomGrid r;
    r.width = width;
    r.height = height;
    r.votes = fixedM > 0 ? BufferVotes::PerBuffer : BufferVotes::PerSample;
    const Values kind = Values(forcedKind >= 0 ? forcedKind : g.pick(int(Values::kCount)));
    const bool grey = g.pick(3) == 0;
    const int invalidPercent = g.pick(3) == 0 ? 0 : g.pick(40);
    r.offset.push_back(0);
    for (int p = 0; p < width * height; ++p) {
        // adaptive: 1 buffer often (as in Jung's eq. 4.15 files), else up to 17
        const int m = fixedM > 0 ? fixedM : (g.pick(3) == 0 ? 1 : 1 + g.pick(17));
        r.m.push_back(m);
        r.offset.push_back(r.offset.back() + size_t(m));
    }
    r.mean.resize(r.offset.back() * 3);
    r.count.resize(r.offset.back());
    for (size_t p = 0; p + 1 < r.offset.size(); ++p) {
        const int n = 1 + g.pick(1000);  // adaptive: the pixel's samples, n / m per buffer
        for (size_t k = r.offset[p]; k < r.offset[p + 1]; ++k) {
            const int j = int(k - r.offset[p]), m = r.m[p];
            const int share = fixedM > 0 ? 0 : std::max(1, n / m + (j < n % m ? 1 : 0));
            g.buffer(&r.mean[3 * k], &r.count[k], kind, grey, invalidPercent, share);
        }
    }
    return r;
}

SpatialParams randomParams(Generator& g) {
    SpatialParams p;
    p.mode = g.pick(2) ? EstimatorMode::Luminance : EstimatorMode::PerChannel;
    switch (g.pick(4)) {
        case 0:
            p.luma = {1.0, 1.0, 1.0};  // more luminance ties
            break;
        case 1:
            p.luma = {0.25, 0.5, 0.25};
            break;
        default:
            p.luma = kLuma;
    }
    p.windowWidth = 1 + 2 * g.pick(4);  // 1, 3, 5, 7
    p.windowHeight = 1 + 2 * g.pick(4);
    p.centreWeight = 1 + g.pick(5);
    switch (g.pick(5)) {
        case 0:
            p.alpha = 0.0;
            break;
        case 1:
            p.alpha = 0.5;  // 3DMF / 3DWMF
            break;
        case 2:  // i / s for a plausible s: exercises the 1e-9 of spatialTrim
            p.alpha = double(g.pick(10)) / double(2 * (1 + g.pick(40)) + 1);
            p.alpha = std::min(p.alpha, 0.5);
            break;
        default:
            p.alpha = 0.5 * g.u();
    }
    return p;
}

std::string describe(const SpatialParams& p, int x, int y) {
    std::ostringstream os;
    os << "pixel (" << x << ", " << y << ") window " << p.windowWidth << "x" << p.windowHeight
       << " w " << p.centreWeight << " alpha " << p.alpha << " mode "
       << (p.mode == EstimatorMode::Luminance ? "lum" : "channel") << " luma " << p.luma[0] << ","
       << p.luma[1] << "," << p.luma[2];
    return os.str();
}

uint32_t bits(float f) {
    uint32_t b;
    std::memcpy(&b, &f, sizeof b);
    return b;
}

/// Bit-exact comparison of two estimates (rgb, kept, excluded).
::testing::AssertionResult sameEstimate(const PixelEstimate& a, const PixelEstimate& b) {
    for (int c = 0; c < 3; ++c)
        if (bits(a.rgb[size_t(c)]) != bits(b.rgb[size_t(c)]))
            return ::testing::AssertionFailure()
                   << "rgb[" << c << "] " << a.rgb[size_t(c)] << " vs " << b.rgb[size_t(c)];
    if (a.kept != b.kept)
        return ::testing::AssertionFailure()
               << "kept " << a.kept[0] << "," << a.kept[1] << "," << a.kept[2] << " vs "
               << b.kept[0] << "," << b.kept[1] << "," << b.kept[2];
    if (a.excluded != b.excluded)
        return ::testing::AssertionFailure() << "excluded " << a.excluded << " vs " << b.excluded;
    return ::testing::AssertionSuccess();
}

/// The reference over every pixel of the grid: out[(y*width + x)].
std::vector<PixelEstimate> referenceImage(const RandomGrid& grid, const SpatialParams& p) {
    reference::Scratch s;
    std::vector<PixelEstimate> out(size_t(grid.width) * size_t(grid.height));
    for (int y = 0; y < grid.height; ++y)
        for (int x = 0; x < grid.width; ++x)
            reference::filter3DPixel(grid.view(), x, y, p, out[size_t(y * grid.width + x)], s);
    return out;
}

/// Checks filter3DPixel and filter3DImage against the reference; returns the number of failures.
int comparePure(const RandomGrid& grid, const SpatialParams& p) {
    const std::vector<PixelEstimate> ref = referenceImage(grid, p);
    SpatialScratch s;
    int failures = 0;
    for (int y = 0; y < grid.height; ++y)
        for (int x = 0; x < grid.width; ++x) {
            PixelEstimate e;
            e.rgb = {-7.f, -7.f, -7.f};  // stale values must be overwritten
            e.kept = {-1, -1, -1};
            filter3DPixel(grid.view(), x, y, p, e, s);
            const auto r = sameEstimate(e, ref[size_t(y * grid.width + x)]);
            EXPECT_TRUE(r) << describe(p, x, y) << " of " << grid.width << "x" << grid.height;
            if (!r) ++failures;
        }
    std::vector<float> img(size_t(grid.width) * size_t(grid.height) * 3, -7.f);
    filter3DImage(grid.view(), p, img.data());
    for (size_t i = 0; i < ref.size(); ++i)
        for (int c = 0; c < 3; ++c)
            if (bits(img[3 * i + size_t(c)]) != bits(ref[i].rgb[size_t(c)])) {
                ADD_FAILURE() << "filter3DImage "
                              << describe(p, int(i) % grid.width, int(i) / grid.width);
                ++failures;
            }
    return failures;
}

}  // namespace

TEST(Filter3DMerge, FixedMMatchesFullSort) {
    Generator g(20240611);
    int failures = 0;
    for (int M : {1, 2, 3, 7, 17})
        for (int trial = 0; trial < 200 && failures < 20; ++trial) {
            const int w = 1 + g.pick(9), h = 1 + g.pick(9);
            const RandomGrid grid = randomGrid(g, w, h, M);
            failures += comparePure(grid, randomParams(g));
        }
    EXPECT_EQ(failures, 0);
}

TEST(Filter3DMerge, AdaptiveMMatchesFullSort) {
    // per-sample votes (what filter3D takes for adaptive files), and per-buffer votes over the
    // same buffers (a hand-built view may still choose them)
    Generator g(7);
    int failures = 0;
    for (int trial = 0; trial < 800 && failures < 20; ++trial) {
        const int w = 1 + g.pick(9), h = 1 + g.pick(9);
        RandomGrid grid = randomGrid(g, w, h, 0);
        const SpatialParams p = randomParams(g);
        failures += comparePure(grid, p);
        grid.votes = BufferVotes::PerBuffer;
        failures += comparePure(grid, p);
    }
    EXPECT_EQ(failures, 0);
}

TEST(Filter3DMerge, PerSampleVotesWithUnitCountsArePerBufferVotes) {
    // every count 1: w_q n_j = w_q copies, bit for bit
    Generator g(11);
    int failures = 0;
    for (int trial = 0; trial < 200 && failures < 20; ++trial) {
        RandomGrid grid = randomGrid(g, 1 + g.pick(9), 1 + g.pick(9), 0);
        for (float& n : grid.count)
            if (std::isfinite(n) && n > 0.f) n = 1.f;
        const SpatialParams p = randomParams(g);
        for (int y = 0; y < grid.height; ++y)
            for (int x = 0; x < grid.width; ++x) {
                SpatialScratch s;
                PixelEstimate a, b;
                grid.votes = BufferVotes::PerSample;
                filter3DPixel(grid.view(), x, y, p, a, s);
                grid.votes = BufferVotes::PerBuffer;
                filter3DPixel(grid.view(), x, y, p, b, s);
                const auto r = sameEstimate(a, b);
                EXPECT_TRUE(r) << describe(p, x, y);
                if (!r) ++failures;
            }
    }
    EXPECT_EQ(failures, 0);
}

TEST(Filter3DMerge, EveryWindowShapeWeightAndMode) {
    // exhaustive over the small parameters, random values: windows 1x1..7x7, w 1..5, both modes
    Generator g(99);
    int failures = 0;
    for (int k = 1; k <= 7 && failures < 20; k += 2)
        for (int l = 1; l <= 7; l += 2)
            for (int64_t w = 1; w <= 5; ++w)
                for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
                    const int M = std::array<int, 5>{1, 2, 3, 7, 17}[size_t(g.pick(5))];
                    const RandomGrid grid =
                        randomGrid(g, 1 + g.pick(8), 1 + g.pick(8), g.pick(4) ? M : 0);
                    SpatialParams p = randomParams(g);
                    p.windowWidth = k;
                    p.windowHeight = l;
                    p.centreWeight = w;
                    p.mode = mode;
                    failures += comparePure(grid, p);
                }
    EXPECT_EQ(failures, 0);
}

TEST(Filter3DMerge, ImageBufFormMatchesFullSortForAnyThreadCountAndTile) {
    // the StatsImage path (fixed and adaptive M), whole image and tiles, 1 and 2 threads
    Generator g(5);
    for (int trial = 0; trial < 120; ++trial) {
        const bool adaptive = trial % 2 == 1;
        const int w = 1 + g.pick(12), h = 1 + g.pick(12);
        const int M = std::array<int, 5>{1, 2, 3, 7, 17}[size_t(g.pick(5))];
        const RandomGrid grid = randomGrid(g, w, h, adaptive ? 0 : M);
        StatsImage s;
        s.header.width = w;
        s.header.height = h;
        s.header.originX = g.pick(5) - 2;
        s.header.originY = g.pick(5) - 2;
        std::string err;
        if (adaptive) {
            s.header.M = 17;
            s.header.formatVersion = 2;
            std::vector<uint32_t> perPixel(grid.m.begin(), grid.m.end());
            ASSERT_TRUE(s.allocateAdaptive(perPixel, err)) << err;
        } else {
            s.header.M = M;
            ASSERT_TRUE(s.allocate(err)) << err;
        }
        ASSERT_EQ(s.bufferMean.size(), grid.mean.size());
        s.bufferMean = grid.mean;
        s.bufferCount = grid.count;
        const SpatialParams p = randomParams(g);
        const std::vector<PixelEstimate> ref = referenceImage(grid, p);
        const OIIO::ROI full(s.header.originX, s.header.originX + w, s.header.originY,
                             s.header.originY + h);
        const int tx0 = full.xbegin + g.pick(w), ty0 = full.ybegin + g.pick(h);
        const OIIO::ROI tile(tx0, tx0 + 1 + g.pick(full.xend - tx0), ty0,
                             ty0 + 1 + g.pick(full.yend - ty0));
        for (const OIIO::ROI& roi : {full, tile})
            for (int threads : {1, 2}) {
                const OIIO::ImageBuf out = filter3D(s, p, roi, threads);
                ASSERT_FALSE(out.has_error()) << out.geterror();
                for (int y = roi.ybegin; y < roi.yend; ++y)
                    for (int x = roi.xbegin; x < roi.xend; ++x) {
                        const PixelEstimate& r =
                            ref[size_t((y - full.ybegin) * w + (x - full.xbegin))];
                        for (int c = 0; c < 3; ++c)
                            ASSERT_EQ(bits(out.getchannel(x, y, 0, c)), bits(r.rgb[size_t(c)]))
                                << describe(p, x, y) << " threads " << threads << " adaptive "
                                << adaptive;
                    }
            }
    }
}

TEST(Filter3DMerge, LargeWindowAndManyBuffers) {
    // a window wider than the image and more buffers than the random tests use
    Generator g(3);
    for (int M : {31, 64}) {
        const RandomGrid grid = randomGrid(g, 5, 4, M);
        for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel})
            for (double alpha : {0.0, 0.1, 0.5}) {
                SpatialParams p;
                p.luma = kLuma;
                p.mode = mode;
                p.windowWidth = 11;
                p.windowHeight = 9;
                p.centreWeight = 3;
                p.alpha = alpha;
                EXPECT_EQ(comparePure(grid, p), 0);
            }
    }
}

TEST(Filter3DMerge, ImagesLargeEnoughToSplitOverThreads) {
    // OIIO gives a thread no fewer than 16k pixels: 41k pixels really run on several threads, for
    // the sorting pass and the filtering pass alike
    Generator g(17);
    for (bool adaptive : {false, true}) {
        const int w = 256, h = 160;
        // fireflies: windows whose results depend on every rule (ranks, votes, weights)
        RandomGrid grid = randomGrid(g, w, h, adaptive ? 0 : 3, int(Values::Fireflies));
        if (adaptive) {  // at most 5 buffers per pixel keeps the reference quick
            for (int& m : grid.m) m = std::min(m, 5);
            grid.offset.assign(1, 0);
            for (int m : grid.m) grid.offset.push_back(grid.offset.back() + size_t(m));
            grid.mean.resize(grid.offset.back() * 3);
            grid.count.resize(grid.offset.back());
        }
        StatsImage s;
        s.header.width = w;
        s.header.height = h;
        s.header.M = adaptive ? 5 : 3;
        std::string err;
        if (adaptive) {
            s.header.formatVersion = 2;
            ASSERT_TRUE(
                s.allocateAdaptive(std::vector<uint32_t>(grid.m.begin(), grid.m.end()), err))
                << err;
        } else {
            ASSERT_TRUE(s.allocate(err)) << err;
        }
        ASSERT_EQ(s.bufferCount.size(), grid.count.size());
        s.bufferMean = grid.mean;  // the same layout: pixel p's buffers from the sum of earlier m
        s.bufferCount = grid.count;
        for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
            SpatialParams p = randomParams(g);
            p.mode = mode;
            const std::vector<PixelEstimate> ref = referenceImage(grid, p);
            std::vector<float> one(size_t(w) * h * 3), four(one.size());
            const OIIO::ImageBuf a = filter3D(s, p, {}, 1), b = filter3D(s, p, {}, 4);
            ASSERT_FALSE(a.has_error()) << a.geterror();
            a.get_pixels(a.roi(), OIIO::TypeDesc::FLOAT, one.data());
            b.get_pixels(b.roi(), OIIO::TypeDesc::FLOAT, four.data());
            EXPECT_EQ(0, std::memcmp(one.data(), four.data(), one.size() * sizeof(float)));
            int failures = 0;
            for (size_t i = 0; i < ref.size() && failures < 10; ++i)
                for (int c = 0; c < 3; ++c)
                    if (bits(one[3 * i + size_t(c)]) != bits(ref[i].rgb[size_t(c)])) {
                        ADD_FAILURE()
                            << describe(p, int(i) % w, int(i) / w) << " adaptive " << adaptive;
                        ++failures;
                    }
        }
    }
}
