// Confidence intervals per pixel (filters/pixel/confidence.h, core/location_stats.h) against
// values computed by hand, and through each estimator's registry entry (PixelKernel::interval).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <random>
#include <vector>

#include "mcstat/core/location_stats.h"
#include "mcstat/filters/pixel/confidence.h"
#include "mcstat/filters/pixel/detail/rank_keys.h"
#include "pixel_support.h"

using namespace mcstat;
using namespace mcstat::testing;

namespace {

// M = 9 buffer means; sorted: 1 1 2 3 4 5 5 6 9.
const std::vector<double> kNine = {3, 1, 4, 1, 5, 9, 2, 6, 5};

ValueInterval kernelInterval(const std::string& name, std::vector<double> v, double level,
                             std::map<std::string, std::string> kv = {}) {
    const PixelKernel k = kernelOf(name, EstimatorMode::Luminance, std::move(kv));
    EXPECT_TRUE(bool(k.interval)) << name;
    const std::vector<double> n(v.size(), 1.0);
    return k.interval(v.data(), n.data(), int(v.size()), level);
}

}  // namespace

TEST(Confidence, BinomialRanks) {
    // P(k <= Bin(9, 1/2) <= 9 - k) = 1 - 2 sum_{i<k} C(9, i) / 512:
    // k = 1: 1 - 2/512 = 0.99609; k = 2: 1 - 2 (1 + 9)/512 = 0.96094; k = 3: 1 - 2 * 46/512 =
    // 0.82031.
    EXPECT_NEAR(medianIntervalCoverage(9, 1), 1.0 - 2.0 / 512, 1e-12);
    EXPECT_NEAR(medianIntervalCoverage(9, 2), 1.0 - 20.0 / 512, 1e-12);
    EXPECT_NEAR(medianIntervalCoverage(9, 3), 1.0 - 92.0 / 512, 1e-12);
    EXPECT_EQ(medianIntervalRank(9, 0.95), 2);
    EXPECT_EQ(medianIntervalRank(9, 0.99), 1);
    EXPECT_EQ(medianIntervalRank(9, 0.80), 3);
    // The full range of m buffers covers with 1 - 2^(1-m): 0.9375 for m = 5, 0.96875 for m = 6.
    EXPECT_EQ(medianIntervalRank(5, 0.95), 0);
    EXPECT_EQ(medianIntervalRank(6, 0.95), 1);
    EXPECT_EQ(medianIntervalRank(7, 0.99), 0);
    EXPECT_EQ(medianIntervalRank(8, 0.99), 1);
    // M = 15: P(Bin <= 3) = (1 + 15 + 105 + 455) / 32768, so k = 4 covers 0.96484.
    EXPECT_EQ(medianIntervalRank(15, 0.95), 4);
    EXPECT_NEAR(medianIntervalCoverage(15, 4), 1.0 - 2.0 * 576 / 32768, 1e-12);
}

TEST(Confidence, MedianOfNineByHand) {
    // k = 2 at 0.95: [x_(2), x_(8)] = [1, 6]; at 0.99 k = 1: [x_(1), x_(9)] = [1, 9].
    for (const char* name : {"mon", "median", "gmon", "gmonb"}) {
        const ValueInterval a = kernelInterval(name, kNine, 0.95);
        EXPECT_EQ(a.low, 1.0) << name;
        EXPECT_EQ(a.high, 6.0) << name;
        EXPECT_FALSE(a.full) << name;
        const ValueInterval b = kernelInterval(name, kNine, 0.99);
        EXPECT_EQ(b.low, 1.0) << name;
        EXPECT_EQ(b.high, 9.0) << name;
    }
    // Too few buffers for the level: the range, flagged (M = 5 at 0.95).
    std::vector<double> five = {2, 8, 4, 6, 5};
    const ValueInterval r = medianInterval(five.data(), 5, 0.95);
    EXPECT_EQ(r.low, 2.0);
    EXPECT_EQ(r.high, 8.0);
    EXPECT_TRUE(r.full);
}

TEST(Confidence, StudentMeanOfNineByHand) {
    // mean = 36 / 9 = 4; squared deviations 9 9 4 1 0 1 1 4 25 sum to 54; s^2 = 54 / 8 = 6.75;
    // SE = sqrt(6.75 / 9) = sqrt(0.75) = 0.8660254; t_{0.975, 8} = 2.3060041;
    // half width 1.9970582: [2.0029418, 5.9970582].
    const ValueInterval a = kernelInterval("mean", kNine, 0.95);
    EXPECT_NEAR(a.low, 2.0029418, 1e-6);
    EXPECT_NEAR(a.high, 5.9970582, 1e-6);
    EXPECT_FALSE(a.full);
    // Counts weigh the mean and the standard error (the batch-means SE, meanSummary's):
    // values 1, 3 with counts 3, 1: mean 1.5; s^2 = (3 * 0.25 + 1 * 2.25) / 1 = 3; var = 3 / 4;
    // t_{0.975, 1} = 12.706205; half = 12.706205 * sqrt(0.75) = 11.003896.
    const double v[2] = {1, 3}, n[2] = {3, 1};
    const ValueInterval w = meanInterval(v, n, 2, 0.95);
    EXPECT_NEAR(w.low, 1.5 - 11.003896, 1e-5);
    EXPECT_NEAR(w.high, 1.5 + 11.003896, 1e-5);
}

TEST(Confidence, FromAStoredSpreadByHand) {
    // A compact file's buffer-free pixel: mean 2, per-sample s^2 = 4 over 5 buffers of N = 16
    // samples in all: 2 +- t_{0.975, 4} sqrt(4 / 16), t_{0.975, 4} = 2.7764451 (tables).
    ValueInterval iv = spreadInterval(2.0, 4.0, 16.0, 5, 0.95);
    EXPECT_NEAR(iv.low, 2.0 - 2.7764451 * 0.5, 1e-6);
    EXPECT_NEAR(iv.high, 2.0 + 2.7764451 * 0.5, 1e-6);
    EXPECT_FALSE(iv.full);
    // The same as meanInterval over buffers with that spread: 5 buffers of 16/5 samples.
    const double v[5] = {0.0, 1.0, 2.0, 3.0, 4.0};  // mean 2, sum (v - 2)^2 = 10
    const double n[5] = {3.2, 3.2, 3.2, 3.2, 3.2};  // s^2 = 3.2 * 10 / 4 = 8
    const ValueInterval fromBuffers = meanInterval(v, n, 5, 0.95);
    iv = spreadInterval(2.0, 8.0, 16.0, 5, 0.95);
    EXPECT_NEAR(iv.low, fromBuffers.low, 1e-12);
    EXPECT_NEAR(iv.high, fromBuffers.high, 1e-12);
    // Zero spread: zero width. One buffer, a NaN or negative spread, no samples: unbounded.
    iv = spreadInterval(3.0, 0.0, 16.0, 5, 0.95);
    EXPECT_EQ(iv.low, 3.0);
    EXPECT_EQ(iv.high, 3.0);
    const double inf = std::numeric_limits<double>::infinity();
    for (const ValueInterval& u :
         {spreadInterval(3.0, 1.0, 16.0, 1, 0.95), spreadInterval(3.0, std::nan(""), 16.0, 5, 0.95),
          spreadInterval(3.0, -1.0, 16.0, 5, 0.95), spreadInterval(3.0, 1.0, 0.0, 5, 0.95),
          spreadInterval(3.0, inf, 16.0, 5, 0.95)}) {
        EXPECT_EQ(u.low, -inf);
        EXPECT_EQ(u.high, inf);
        EXPECT_TRUE(u.full);
    }
    iv = spreadInterval(std::nan(""), 1.0, 16.0, 5, 0.95);
    EXPECT_TRUE(std::isnan(iv.low) && std::isnan(iv.high));
    // 1e38 means with a 1e76 spread: finite in double.
    iv = spreadInterval(1e38, 1e76, 16.0, 5, 0.95);
    EXPECT_TRUE(std::isfinite(iv.low) && std::isfinite(iv.high));
}

TEST(Confidence, ExpectedValueIntervalByHand) {
    // The larger of the pixel's per-sample variance (4) and its neighbourhood's (9): 2 +- t_{0.975,
    // 4} sqrt(9 / 16); the pixel's when larger; either alone when the other is unknown (NaN).
    const double t4 = 2.7764451;
    ValueInterval iv = expectedInterval(2.0, 4.0, 9.0, 16.0, 5, 0.95);
    EXPECT_NEAR(iv.low, 2.0 - t4 * 0.75, 1e-6);
    EXPECT_NEAR(iv.high, 2.0 + t4 * 0.75, 1e-6);
    iv = expectedInterval(2.0, 9.0, 4.0, 16.0, 5, 0.95);
    EXPECT_NEAR(iv.high, 2.0 + t4 * 0.75, 1e-6);
    iv = expectedInterval(2.0, std::nan(""), 4.0, 16.0, 5, 0.95);
    EXPECT_NEAR(iv.high, 2.0 + t4 * 0.5, 1e-6);
    iv = expectedInterval(2.0, 4.0, std::nan(""), 16.0, 5, 0.95);
    EXPECT_NEAR(iv.high, 2.0 + t4 * 0.5, 1e-6);
    iv = expectedInterval(2.0, std::nan(""), std::nan(""), 16.0, 5, 0.95);
    EXPECT_TRUE(iv.full);
    EXPECT_TRUE(std::isinf(iv.low) && std::isinf(iv.high));
    iv = expectedInterval(2.0, 4.0, 9.0, 16.0, 1, 0.95);  // one buffer: no degrees of freedom
    EXPECT_TRUE(iv.full);
}

TEST(Confidence, YuenForTmpeByHand) {
    // TMPE alpha = 0.25, M = 9: g = floor(2.25) = 2 cut per side, h = 5: 2 3 4 5 5, mean 3.8.
    // Winsorised: 2 2 2 3 4 5 5 5 5, mean 33/9; sum of squared deviations 16; variance
    // 16 / (5 * 4) = 0.8, SE 0.8944272; t_{0.975, 4} = 2.7764451; half 2.4833280:
    // [1.3166720, 6.2833280].
    const ValueInterval a = kernelInterval("tmpe", kNine, 0.95, {{"alpha", "0.25"}});
    EXPECT_NEAR(a.low, 1.3166720, 1e-6);
    EXPECT_NEAR(a.high, 6.2833280, 1e-6);
    // alpha = 0 is the mean: the t interval.
    const ValueInterval m = kernelInterval("tmpe", kNine, 0.95, {{"alpha", "0"}});
    EXPECT_NEAR(m.low, 2.0029418, 1e-6);
    // alpha = 0.5 is the median (one value left): the order-statistic interval.
    const ValueInterval d = kernelInterval("tmpe", kNine, 0.95, {{"alpha", "0.5"}});
    EXPECT_EQ(d.low, 1.0);
    EXPECT_EQ(d.high, 6.0);
}

TEST(Confidence, Extremes) {
    const double inf = std::numeric_limits<double>::infinity();
    for (const char* name : {"mean", "mon", "gmon", "gmonb", "tmpe"}) {
        // No buffer: NaN; one: anything, [-inf, inf], flagged.
        const ValueInterval none = kernelInterval(name, {}, 0.95);
        EXPECT_TRUE(std::isnan(none.low) && std::isnan(none.high)) << name;
        const ValueInterval one = kernelInterval(name, {7}, 0.95);
        EXPECT_EQ(one.low, -inf) << name;
        EXPECT_EQ(one.high, inf) << name;
        EXPECT_TRUE(one.full) << name;
        // All equal: zero width.
        const ValueInterval eq = kernelInterval(name, std::vector<double>(9, 0.25), 0.95);
        EXPECT_EQ(eq.low, 0.25) << name;
        EXPECT_EQ(eq.high, 0.25) << name;
        // Negatives and float's largest values: finite, ordered, no overflow in the SE.
        const ValueInterval big =
            kernelInterval(name, {3e38, -3e38, 1e38, 2e38, -1e38, 0, 3e38, -2e38, 1e38}, 0.95);
        EXPECT_TRUE(std::isfinite(big.low) && std::isfinite(big.high)) << name;
        EXPECT_LE(big.low, big.high) << name;
        const ValueInterval neg = kernelInterval(name, {-3, -1, -4, -1, -5, -9, -2, -6, -5}, 0.95);
        EXPECT_LT(neg.low, -3.0) << name;
        EXPECT_GT(neg.high, -5.0) << name;
    }
    // The estimators without an interval say so.
    EXPECT_FALSE(bool(kernelOf("myriad").interval));
    EXPECT_FALSE(bool(kernelOf("meridian").interval));
}

TEST(Confidence, StudentQuantile) {
    EXPECT_NEAR(studentQuantile(0.975, 8), 2.3060041, 1e-6);
    EXPECT_NEAR(studentQuantile(0.975, 1e9), 1.9599640, 1e-6);  // the normal
    EXPECT_TRUE(std::isnan(studentQuantile(1.0, 5)));
    EXPECT_TRUE(std::isnan(studentQuantile(0.9, 0)));
}

namespace {

/// Equal as the image writes them: the same float, or two zeros (a sort may trade -0 and +0).
bool sameBound(double a, double b) {
    const float fa = float(a), fb = float(b);
    if (fa == 0.f && fb == 0.f) return true;
    if (std::isnan(fa) || std::isnan(fb)) return std::isnan(fa) && std::isnan(fb);
    return std::memcmp(&fa, &fb, sizeof fa) == 0 && a == b;
}

}  // namespace

// PixelKernel::pixelInterval (three channels at once: one sorting network, sums side by side)
// gives per channel what PixelKernel::interval gives on that channel's values, bit for bit, for
// every m from 0 to 70 (the network's largest m is 64; above it the per-channel path), with ties,
// negatives, zeros of both signs, denormals, float's largest values, unequal counts and
// invalid buffers. A network missing one comparator leaves some m unsorted and fails here. The
// mean's estimatesWithIntervals (one pass for both) gives the estimate's bits and these intervals.
TEST(Confidence, PixelIntervalsEqualThePerChannelOnes) {
    std::mt19937 rng(2026);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const float kinds[] = {0.f, -0.f, 1e-40f, -1e-40f, 3e38f, -3e38f, 0.5f, 0.5f, 2.f};
    for (const char* name : {"mean", "mon", "gmon", "gmonb", "tmpe"})
        for (const char* alpha : {"0.1", "0.25", "0.5"}) {
            if (std::string(name) != "tmpe" && std::string(alpha) != "0.1") continue;
            std::map<std::string, std::string> kv;
            if (std::string(name) == "tmpe") kv["alpha"] = alpha;
            const PixelKernel k = kernelOf(name, EstimatorMode::Luminance, kv);
            ASSERT_TRUE(bool(k.pixelInterval)) << name;
            for (int M = 0; M <= 70; ++M)
                for (int trial = 0; trial < 12; ++trial) {
                    std::vector<float> mean(static_cast<size_t>(M) * 3),
                        count(static_cast<size_t>(M));
                    for (int j = 0; j < M; ++j) {
                        for (int c = 0; c < 3; ++c) {
                            const float r = u(rng);
                            float v = trial % 3 == 0   ? kinds[size_t(r * 9.f) % 9]
                                      : trial % 3 == 1 ? float(int(r * 4.f))  // many ties
                                                       : (r - 0.3f) * 100.f;
                            if (u(rng) < 0.03f) v = std::numeric_limits<float>::infinity();
                            mean[size_t(j) * 3 + size_t(c)] = v;
                        }
                        count[size_t(j)] = trial % 2 ? 16.f : float(1 + int(u(rng) * 40.f));
                        if (u(rng) < 0.05f) count[size_t(j)] = 0.f;
                    }
                    const PixelBuffers px{mean.data(), count.data(), M};
                    std::vector<int> valid;
                    int excluded = 0;
                    const int m = collectValidBuffers(px, valid, excluded);
                    for (double level : {0.9, 0.95}) {
                        ValueInterval fast[3];
                        k.pixelInterval(px, valid.data(), m, level, fast);
                        if (k.estimatesWithIntervals) {  // the mean: estimate and interval in one
                            PixelEstimate alone, shared;
                            EstimatorScratch s1;
                            k.estimate(px, alone, s1);
                            ValueInterval both[3];
                            k.estimatesWithIntervals(&px, 1, level, &shared, both);
                            for (int c = 0; c < 3; ++c) {
                                EXPECT_EQ(std::memcmp(&alone.rgb[size_t(c)], &shared.rgb[size_t(c)],
                                                      sizeof(float)),
                                          0)
                                    << name << " M " << M << " trial " << trial;
                                EXPECT_TRUE(std::memcmp(&both[c], &fast[c], sizeof(double) * 2) ==
                                                0 ||
                                            (std::isnan(both[c].low) && std::isnan(fast[c].low)))
                                    << name << " M " << M << " trial " << trial;
                            }
                            EXPECT_EQ(alone.kept, shared.kept);
                            EXPECT_EQ(alone.excluded, shared.excluded);
                        }
                        for (int c = 0; c < 3; ++c) {
                            std::vector<double> v(static_cast<size_t>(m)),
                                n(static_cast<size_t>(m));
                            for (int i = 0; i < m; ++i) {
                                v[size_t(i)] = mean[size_t(valid[size_t(i)]) * 3 + size_t(c)];
                                n[size_t(i)] = count[size_t(valid[size_t(i)])];
                            }
                            const ValueInterval slow = k.interval(v.data(), n.data(), m, level);
                            EXPECT_TRUE(sameBound(fast[c].low, slow.low) &&
                                        sameBound(fast[c].high, slow.high) &&
                                        fast[c].full == slow.full)
                                << name << " alpha " << alpha << " M " << M << " trial " << trial
                                << " c " << c << ": [" << fast[c].low << ", " << fast[c].high
                                << "] against [" << slow.low << ", " << slow.high << "]";
                        }
                    }
                }
        }
}

// runIntervals (MoN, G-MoN, G-MoN_b: two pixels of equal M per eight-float network) gives each
// pixel pixelInterval's bits, sign of zero included: runs of pairs and of lone pixels, M = 1 to 40
// and 64, 65 (past the unrolled networks), zeros of both signs, denormals, +-3e38 and ties.
TEST(Confidence, RunIntervalsEqualThePixelOnes) {
    std::mt19937 rng(52);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const float kinds[] = {0.f, -0.f, 1e-40f, -1e-40f, 3e38f, -3e38f, 0.5f, 0.5f, 2.f};
    std::vector<int> ms;
    for (int M = 1; M <= 40; ++M) ms.insert(ms.end(), {M, M, M});  // a pair, then one left over
    ms.insert(ms.end(), {64, 64, 65, 65, 7, 8, 7, 8});
    std::vector<std::vector<float>> means, counts;
    for (size_t i = 0; i < ms.size(); ++i) {
        const int M = ms[i];
        std::vector<float> mean(static_cast<size_t>(M) * 3), count(static_cast<size_t>(M));
        for (size_t v = 0; v < mean.size(); ++v) {
            const float r = u(rng);
            mean[v] = i % 3 == 0   ? kinds[size_t(r * 9.f) % 9]
                      : i % 3 == 1 ? float(int(r * 4.f))  // many ties
                                   : (r - 0.3f) * 100.f;
        }
        for (float& n : count) n = float(1 + int(u(rng) * 40.f));
        means.push_back(std::move(mean));
        counts.push_back(std::move(count));
    }
    std::vector<PixelBuffers> px;
    for (size_t i = 0; i < ms.size(); ++i) px.push_back({means[i].data(), counts[i].data(), ms[i]});
    // TMPE: its default trim, none (h = M), and the most (h down to 1 or 2: the median's path).
    const std::vector<std::pair<const char*, std::map<std::string, std::string>>> kernels = {
        {"mon", {}},
        {"gmon", {}},
        {"gmonb", {}},
        {"tmpe", {}},
        {"tmpe", {{"alpha", "0"}}},
        {"tmpe", {{"alpha", "0.45"}}}};
    for (const auto& [name, kv] : kernels) {
        const PixelKernel k = kernelOf(name, EstimatorMode::Luminance, kv);
        ASSERT_TRUE(bool(k.runIntervals)) << name;
        for (double level : {0.5, 0.9, 0.95}) {
            std::vector<ValueInterval> run(3 * px.size());
            k.runIntervals(px.data(), int(px.size()), level, run.data());
            for (size_t i = 0; i < px.size(); ++i) {
                std::vector<int> valid;
                int excluded = 0;
                const int m = collectValidBuffers(px[i], valid, excluded);
                ASSERT_EQ(m, px[i].M);
                ValueInterval one[3];
                k.pixelInterval(px[i], valid.data(), m, level, one);
                for (int c = 0; c < 3; ++c) {
                    const ValueInterval& r = run[3 * i + size_t(c)];
                    EXPECT_TRUE(std::memcmp(&r.low, &one[c].low, sizeof(double)) == 0 &&
                                std::memcmp(&r.high, &one[c].high, sizeof(double)) == 0 &&
                                r.full == one[c].full)
                        << name << " level " << level << " pixel " << i << " M " << px[i].M << " c "
                        << c << ": [" << r.low << ", " << r.high << "] against [" << one[c].low
                        << ", " << one[c].high << "]";
                }
            }
        }
    }
}

// The mean's estimatesWithIntervals over a run (four or two pixels of equal M side by side)
// gives each pixel what estimate and pixelInterval give it alone, bit for bit: seven pixels of
// each M (four, two and one side by side), M = 0 to 66 (past the side-by-side passes' 64),
// neighbours of unequal M, invalid buffers (Inf, NaN, negative and zero counts: unequal numbers
// of valid buffers side by side), zeros of both signs, denormals, +-3e38.
TEST(Confidence, MeanRunEstimatesEqualThePixelOnes) {
    std::mt19937 rng(53);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const float kinds[] = {0.f, -0.f, 1e-40f, -1e-40f, 3e38f, -3e38f, 0.5f, 0.5f, 2.f};
    std::vector<int> ms;
    for (int M = 0; M <= 66; ++M) ms.insert(ms.end(), {M, M, M, M, M, M, M});
    ms.insert(ms.end(), {7, 8, 21, 20, 1, 2});
    std::vector<std::vector<float>> means, counts;
    for (size_t i = 0; i < ms.size(); ++i) {
        const int M = ms[i];
        std::vector<float> mean(static_cast<size_t>(M) * 3), count(static_cast<size_t>(M));
        for (float& v : mean) {
            const float r = u(rng);
            v = i % 3 == 0 ? kinds[size_t(r * 9.f) % 9] : (r - 0.3f) * 100.f;
            if (u(rng) < 0.03f)
                v = u(rng) < 0.5f ? std::numeric_limits<float>::infinity()
                                  : std::numeric_limits<float>::quiet_NaN();
        }
        for (float& n : count) {
            n = float(1 + int(u(rng) * 40.f));
            if (u(rng) < 0.05f) n = u(rng) < 0.5f ? 0.f : -1.f;
        }
        means.push_back(std::move(mean));
        counts.push_back(std::move(count));
    }
    std::vector<PixelBuffers> px;
    for (size_t i = 0; i < ms.size(); ++i) px.push_back({means[i].data(), counts[i].data(), ms[i]});
    const PixelKernel k = kernelOf("mean", EstimatorMode::Luminance, {});
    ASSERT_TRUE(bool(k.estimatesWithIntervals));
    const double levels[] = {0.5, 0.95};
    // Each pixel alone, as the processor computes it (pixelInterval is checked against the
    // per-channel intervals above, estimate against the oracle in test_bit_identity.cpp).
    std::vector<PixelEstimate> alone(px.size());
    std::vector<ValueInterval> one(2 * 3 * px.size());
    for (size_t i = 0; i < px.size(); ++i) {
        EstimatorScratch s;
        k.estimate(px[i], alone[i], s);
        std::vector<int> valid;
        int excluded = 0;
        const int m = collectValidBuffers(px[i], valid, excluded);
        for (int l = 0; l < 2; ++l)
            k.pixelInterval(px[i], valid.data(), m, levels[l],
                            one.data() + 3 * (l * px.size() + i));
    }
    // The run, with the AVX2 passes and with the portable ones.
    for (bool avx2 : {true, false})
        for (int l = 0; l < 2; ++l) {
            const bool before = detail::setUseAvx2(avx2);
            std::vector<PixelEstimate> e(px.size());
            std::vector<ValueInterval> run(3 * px.size());
            k.estimatesWithIntervals(px.data(), int(px.size()), levels[l], e.data(), run.data());
            detail::setUseAvx2(before);
            for (size_t i = 0; i < px.size(); ++i) {
                EXPECT_EQ(std::memcmp(alone[i].rgb.data(), e[i].rgb.data(), sizeof(float) * 3), 0)
                    << "avx2 " << avx2 << " pixel " << i << " M " << px[i].M;
                EXPECT_EQ(alone[i].kept, e[i].kept) << "pixel " << i;
                EXPECT_EQ(alone[i].excluded, e[i].excluded) << "pixel " << i;
                for (int c = 0; c < 3; ++c) {
                    const ValueInterval& r = run[3 * i + size_t(c)];
                    const ValueInterval& o = one[3 * (size_t(l) * px.size() + i) + size_t(c)];
                    EXPECT_TRUE((std::memcmp(&r.low, &o.low, sizeof(double)) == 0 &&
                                 std::memcmp(&r.high, &o.high, sizeof(double)) == 0 &&
                                 r.full == o.full) ||
                                (std::isnan(r.low) && std::isnan(o.low)))
                        << "avx2 " << avx2 << " level " << levels[l] << " pixel " << i << " M "
                        << px[i].M << " c " << c << ": [" << r.low << ", " << r.high
                        << "] against [" << o.low << ", " << o.high << "]";
                }
            }
        }
}
