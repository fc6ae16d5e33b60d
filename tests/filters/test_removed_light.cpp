// The removed light's statistics (filters/removed_light.h) on pixels worked by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "filters/pixel/pixel_support.h"
#include "mcstat/filters/removed_light.h"

using namespace mcstat;
using mcstat::testing::grey;
using mcstat::testing::kInf;
using mcstat::testing::kNaN;

namespace {

const std::array<double, 3> kRed{1.0, 0.0, 0.0};  // Y = R: the hand computations stay short

TEST(LumaSpread, LoneFireflyIsOneStandardErrorAboveTheMedian) {
    // 0, 0, 0, 0, F: mean F/5; deviations -F/5 (x4) and 4F/5: ss = 4F^2/25 + 16F^2/25 = 20F^2/25;
    // sigma^2 = ss / 4 = F^2/5; se = sqrt(sigma^2 / 5) = F/5. Removing it (median 0): d = F/5.
    const auto px = grey({0, 0, 0, 0, 40});
    const LumaSpread s = lumaSpread(px.view(), kRed);
    EXPECT_EQ(s.valid, 5);
    EXPECT_DOUBLE_EQ(s.mean, 8.0);
    EXPECT_DOUBLE_EQ(s.se, 8.0);
    EXPECT_DOUBLE_EQ(removedZ(s.mean - 0.0, s.se), 1.0);
}

TEST(LumaSpread, KOfMBuffersGiveTheClosedForm) {
    // 3 of 9 at 10, 6 at 1: mean 4; ss = 3 * 36 + 6 * 9 = 162; sigma^2 = 162 / 8 = 20.25;
    // se = sqrt(20.25 / 9) = 1.5. Median 1: d = 3, z = 2 = sqrt(k (M - 1) / (M - k)).
    const auto px = grey({1, 10, 1, 1, 10, 1, 1, 10, 1});
    const LumaSpread s = lumaSpread(px.view(), kRed);
    EXPECT_DOUBLE_EQ(s.mean, 4.0);
    EXPECT_DOUBLE_EQ(s.se, 1.5);
    EXPECT_DOUBLE_EQ(removedZ(3.0, s.se), std::sqrt(3.0 * 8.0 / 6.0));
}

TEST(LumaSpread, CountsWeighTheMeanAndTheVariance) {
    // Counts 1, 3: mean (2 + 3 * 6) / 4 = 5; ss = 1 * 9 + 3 * 1 = 12; sigma^2 = 12 / 1;
    // se = sqrt(12 / 4) = sqrt(3).
    const auto px = grey({2, 6}, {1, 3});
    const LumaSpread s = lumaSpread(px.view(), kRed);
    EXPECT_DOUBLE_EQ(s.mean, 5.0);
    EXPECT_DOUBLE_EQ(s.se, std::sqrt(3.0));
}

TEST(LumaSpread, LuminanceWeightsTheChannels) {
    mcstat::testing::Pixel px({{1, 0, 0}, {0, 1, 0}}, {1, 1});
    const LumaSpread s = lumaSpread(px.view(), mcstat::testing::kLuma);
    EXPECT_DOUBLE_EQ(s.mean, (0.2126 + 0.7152) / 2);
    const double dev = (0.7152 - 0.2126) / 2;  // sigma^2 = 2 dev^2 / 1; se = sqrt(sigma^2 / 2)
    EXPECT_NEAR(s.se, dev, 1e-15);
}

TEST(LumaSpread, InvalidBuffersAreLeftOut) {
    // NaN, Inf and count 0 are not valid (pixel_estimate.h): 2 and 4 remain, mean 3, se 1.
    const auto px = grey({2, kNaN, 4, kInf, 100}, {1, 1, 1, 1, 0});
    const LumaSpread s = lumaSpread(px.view(), kRed);
    EXPECT_EQ(s.valid, 2);
    EXPECT_DOUBLE_EQ(s.mean, 3.0);
    EXPECT_DOUBLE_EQ(s.se, 1.0);
}

TEST(LumaSpread, OneOrNoValidBufferHasNoStandardError) {
    const LumaSpread one = lumaSpread(grey({7}).view(), kRed);
    EXPECT_EQ(one.valid, 1);
    EXPECT_DOUBLE_EQ(one.mean, 7.0);
    EXPECT_EQ(one.se, 0.0);
    const LumaSpread none = lumaSpread(grey({kNaN, kNaN}).view(), kRed);
    EXPECT_EQ(none.valid, 0);
    EXPECT_EQ(none.mean, 0.0);
    EXPECT_EQ(none.se, 0.0);
}

TEST(LumaSpread, ExtremesStayFinite) {
    // 1e38 and -1e38: mean 0, se = sqrt(2e76 / 1 / 2) = 1e38 in double, no overflow.
    const LumaSpread s = lumaSpread(grey({1e38f, -1e38f}).view(), kRed);
    EXPECT_DOUBLE_EQ(s.mean, 0.0);
    EXPECT_NEAR(s.se / double(1e38f), 1.0, 1e-12);
    // Denormals: a spread of 1e-40 is measured, not flushed to 0.
    const LumaSpread tiny = lumaSpread(grey({0.f, 1e-40f}).view(), kRed);
    EXPECT_GT(tiny.se, 0.0);
    // Identical buffers: no spread, z 0 whatever d.
    EXPECT_EQ(lumaSpread(grey({3, 3, 3}).view(), kRed).se, 0.0);
}

TEST(RemovedZ, UndefinedCasesAreZero) {
    EXPECT_EQ(removedZ(1.0, 0.0), 0.0);
    EXPECT_EQ(removedZ(0.0, 1.0), 0.0);
    EXPECT_EQ(removedZ(std::nan(""), 1.0), 0.0);
    EXPECT_EQ(removedZ(1.0, std::numeric_limits<double>::infinity()), 0.0);
    EXPECT_EQ(removedZ(1.0, std::nan("")), 0.0);
    EXPECT_DOUBLE_EQ(removedZ(-2.0, 4.0), -0.5);  // light added: negative
}

TEST(LocalRemovedZ, PoolsTheWindowClippedToTheImage) {
    // 3 x 2 image. d = 1 2 0 / 3 0 0, se = 1 1 0 / 2 0 0, radius 1.
    const std::vector<float> d = {1, 2, 0, 3, 0, 0}, se = {1, 1, 0, 2, 0, 0};
    std::vector<float> z(6);
    localRemovedZ(d.data(), se.data(), 3, 2, 1, z.data());
    // (0,0): window x 0..1, y 0..1: sum d = 6, sum se^2 = 6 -> 6 / sqrt(6).
    EXPECT_FLOAT_EQ(z[0], float(6.0 / std::sqrt(6.0)));
    // (2,0): window x 1..2: d 2, 0, 0, 0 and se 1: 2 / 1.
    EXPECT_FLOAT_EQ(z[2], 2.f);
    // (2,1): the same window.
    EXPECT_FLOAT_EQ(z[5], 2.f);
    // Radius 0 is each pixel's own z; a pixel with se 0 is 0.
    localRemovedZ(d.data(), se.data(), 3, 2, 0, z.data());
    EXPECT_FLOAT_EQ(z[3], 1.5f);
    EXPECT_EQ(z[2], 0.f);
}

TEST(LocalRemovedZ, LoneFireflyStaysAtOneAndARegionGrowsWithItsArea) {
    // A 9 x 9 image: one pixel with z = 1 (d = se = 5) in the corner region; a 5 x 5 block of
    // pixels with z = 2 (d = 3, se = 1.5) at x, y in 4..8.
    const int W = 9;
    std::vector<float> d(81, 0.f), se(81, 0.f), z(81);
    d[0] = se[0] = 5.f;
    for (int y = 4; y < 9; ++y)
        for (int x = 4; x < 9; ++x) {
            d[size_t(y * W + x)] = 3.f;
            se[size_t(y * W + x)] = 1.5f;
        }
    localRemovedZ(d.data(), se.data(), W, W, 2, z.data());
    EXPECT_FLOAT_EQ(z[0], 1.f);                   // the firefly alone in its window
    EXPECT_FLOAT_EQ(z[size_t(1 * W + 1)], 1.f);   // and in its neighbours'
    EXPECT_FLOAT_EQ(z[size_t(6 * W + 6)], 10.f);  // 25 pixels: 75 / sqrt(25 * 2.25)
    EXPECT_FLOAT_EQ(z[size_t(8 * W + 8)], 6.f);   // corner: 9 pixels: 27 / 4.5
    // NaN d or se are left out of the sums.
    d[size_t(6 * W + 6)] = kNaN;
    localRemovedZ(d.data(), se.data(), W, W, 2, z.data());
    EXPECT_FLOAT_EQ(z[size_t(6 * W + 6)], float(72.0 / std::sqrt(24 * 2.25)));
}

// Every buffer valid takes lumaSpread's shortcut (no per-buffer tests): the same sums in the same
// order as the general rule, checked here against that rule written out (one buffer made invalid
// sends the same pixel through the general path, whose valid buffers then give the reference).
TEST(LumaSpread, TheAllValidShortcutGivesTheGeneralSums) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const std::array<double, 3> luma = mcstat::testing::kLuma;
    for (int M : {1, 2, 5, 21, 64, 70}) {
        std::vector<float> mean(static_cast<size_t>(M) * 3), count(static_cast<size_t>(M));
        for (size_t i = 0; i < mean.size(); ++i)
            mean[i] = (u(rng) - 0.2f) * (u(rng) < 0.05f ? 3e4f : 1.f);
        for (int j = 0; j < M; ++j) count[size_t(j)] = float(1 + int(u(rng) * 50.f));
        const LumaSpread fast = lumaSpread(PixelBuffers{mean.data(), count.data(), M}, luma);
        double n = 0.0, sum = 0.0;
        std::vector<double> y(static_cast<size_t>(M));
        for (int j = 0; j < M; ++j) {
            const float* m = mean.data() + 3 * j;
            y[size_t(j)] = luma[0] * double(m[0]) + luma[1] * double(m[1]) + luma[2] * double(m[2]);
            n += double(count[size_t(j)]);
            sum += double(count[size_t(j)]) * y[size_t(j)];
        }
        const double expMean = sum / n;
        double ss = 0.0;
        for (int j = 0; j < M; ++j) {
            const double dev = y[size_t(j)] - expMean;
            ss += double(count[size_t(j)]) * dev * dev;
        }
        EXPECT_EQ(fast.valid, M);
        EXPECT_EQ(fast.mean, expMean) << M;
        EXPECT_EQ(fast.se, M < 2 ? 0.0 : std::sqrt(ss / double(M - 1) / n)) << M;
        // The general path on the same buffers plus an invalid one gives the same bits.
        mean.insert(mean.end(), {kNaN, 0.f, 0.f});
        count.push_back(4.f);
        const LumaSpread general = lumaSpread(PixelBuffers{mean.data(), count.data(), M + 1}, luma);
        EXPECT_EQ(general.valid, M);
        EXPECT_EQ(general.mean, fast.mean);
        EXPECT_EQ(general.se, fast.se);
    }
}

// lumaSpreads (four pixels per AVX2 register where all four share M and are all valid) gives
// lumaSpread's bits for every pixel of a run that mixes runs of four, leftovers, other M, invalid
// buffers (NaN, +inf, count 0), M = 1 and M over the stack size, and the extremes: 1e38 (squares
// near 1e77, finite in double), denormals, negatives and zeros.
TEST(LumaSpread, FourPixelsAtOnceGiveEachPixelsBits) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const std::array<double, 3> luma = mcstat::testing::kLuma;
    const float kDenormal = std::numeric_limits<float>::denorm_min() * 7.f;
    std::vector<std::vector<float>> means, counts;
    auto add = [&](int M, int kind) {
        std::vector<float> mean(static_cast<size_t>(M) * 3), count(static_cast<size_t>(M));
        for (size_t i = 0; i < mean.size(); ++i) {
            const float r = u(rng);
            mean[i] = kind == 1   ? (r < 0.3f ? 1e38f : -r)
                      : kind == 2 ? (r < 0.5f ? kDenormal : 0.f)
                                  : (r - 0.2f) * (r < 0.05f ? 3e4f : 1.f);
        }
        for (int j = 0; j < M; ++j) count[size_t(j)] = float(1 + int(u(rng) * 50.f));
        if (kind == 3) mean[size_t(3 * (M - 1))] = kNaN;
        if (kind == 4) mean[1] = kInf;
        if (kind == 5) count[0] = 0.f;
        if (kind == 6) count[M - 1] = -1.f;
        if (kind == 7) count[1] = kInf;
        if (kind == 8) count[2] = -0.f;
        means.push_back(std::move(mean));
        counts.push_back(std::move(count));
    };
    for (int M :
         {21, 21, 21, 21, 21, 21, 21, 2, 2, 2, 2, 64, 64, 64, 64, 1, 1, 1, 1, 70, 70, 70, 70, 5})
        add(M, 0);
    for (int kind = 1; kind <= 8; ++kind)
        for (int i = 0; i < 4; ++i) add(9, kind == 3 && i == 2 ? 0 : kind);
    for (int i = 0; i < 4; ++i) add(i % 2 ? 8 : 9, 0);  // alternating M: never four alike
    std::vector<PixelBuffers> px;
    for (size_t i = 0; i < means.size(); ++i)
        px.push_back({means[i].data(), counts[i].data(), int(counts[i].size())});
    std::vector<LumaSpread> batch(px.size());
    lumaSpreads(px.data(), int(px.size()), luma, batch.data());
    for (size_t i = 0; i < px.size(); ++i) {
        const LumaSpread one = lumaSpread(px[i], luma);
        EXPECT_EQ(batch[i].valid, one.valid) << i;
        // Bit for bit, NaN included (memcmp: NaN != NaN).
        EXPECT_EQ(std::memcmp(&batch[i].mean, &one.mean, sizeof(double)), 0)
            << i << ": " << batch[i].mean << " vs " << one.mean;
        EXPECT_EQ(std::memcmp(&batch[i].se, &one.se, sizeof(double)), 0)
            << i << ": " << batch[i].se << " vs " << one.se;
    }
    // The extremes went through the four-pixel path and stayed finite: 1e38 among small values.
    EXPECT_EQ(batch[24].valid, 9);
    EXPECT_TRUE(std::isfinite(batch[24].mean));
    EXPECT_TRUE(std::isfinite(batch[24].se) && batch[24].se > 1e36) << batch[24].se;
}

// Rows on any number of threads: the same bits.
TEST(LocalRemovedZ, SameOnAnyThreadCount) {
    const int W = 67, H = 41;
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::vector<float> d(size_t(W * H)), se(d.size()), one(d.size()), four(d.size());
    for (size_t i = 0; i < d.size(); ++i) {
        d[i] = u(rng) < 0.1f ? 50.f * u(rng) : 0.f;
        se[i] = u(rng);
    }
    localRemovedZ(d.data(), se.data(), W, H, 3, one.data(), 1);
    localRemovedZ(d.data(), se.data(), W, H, 3, four.data(), 4);
    EXPECT_EQ(std::memcmp(one.data(), four.data(), one.size() * sizeof(float)), 0);
}

}  // namespace
