// Compact statistics files against full ones (include/mcstat/compact/compact.h, FORMAT.md
// "Version 6"): G-MoN bit for bit in both modes, with AOVs; every other per-pixel estimator equal
// to the full file's where the buffers are kept and to the pixel's mean where not; at the
// extremes (issue: NaN, Inf, 0, negatives, denormals, FLT_MAX, spp < M, M = 1..4 and 999, heavy
// tails).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <random>

#include "mcstat/compact/compact.h"
#include "mcstat/filters/aov_weights.h"
#include "mcstat/filters/operation.h"
#include "mcstat/filters/registry.h"

namespace mcstat {
namespace {

const std::array<double, 3> kLuma{0.2126, 0.7152, 0.0722};

/// One pixel's buffers: M means (RGB) and counts, and A AOV values per buffer.
struct Pixel {
    std::vector<float> mean, count, aov;
};

/// A full image of `pixels` given as buffers (every pixel with the same M), moments consistent.
StatsImage fullImage(const std::vector<Pixel>& pixels, int M, const std::vector<AovChannel>& aovs) {
    StatsImage img;
    img.header.width = int(pixels.size());
    img.header.height = 1;
    img.header.M = M;
    img.header.spp = 0;
    img.header.aovs = aovs;
    img.header.formatVersion = requiredFormatVersion(img.header);
    std::string err;
    EXPECT_TRUE(img.allocate(err)) << err;
    const size_t A = aovs.size();
    for (size_t p = 0; p < pixels.size(); ++p) {
        double n = 0.0, s[3] = {0, 0, 0};
        for (int j = 0; j < M; ++j) {
            const size_t k = p * size_t(M) + size_t(j);
            for (int c = 0; c < 3; ++c)
                img.bufferMean[k * 3 + c] = pixels[p].mean[size_t(j) * 3 + c];
            img.bufferCount[k] = pixels[p].count[size_t(j)];
            for (size_t a = 0; a < A; ++a) img.aov[k * A + a] = pixels[p].aov[size_t(j) * A + a];
            n += img.bufferCount[k];
            for (int c = 0; c < 3; ++c)
                s[c] += img.bufferCount[k] * double(img.bufferMean[k * 3 + c]);
        }
        img.count[p] = float(n);
        for (int c = 0; c < 3; ++c) {
            img.mean[p * 3 + c] = n > 0 ? float(s[c] / n) : 0.f;
            img.beauty[p * 3 + c] = img.mean[p * 3 + c];
        }
    }
    return img;
}

/// A pixel of M buffers with count n each, channel values f(j, c).
Pixel makePixel(int M, float n, const std::function<float(int, int)>& f, size_t A = 0) {
    Pixel px;
    for (int j = 0; j < M; ++j) {
        for (int c = 0; c < 3; ++c) px.mean.push_back(f(j, c));
        px.count.push_back(n);
        for (size_t a = 0; a < A; ++a) px.aov.push_back(f(j, int(a % 3)) * float(a + 1) * 0.25f);
    }
    return px;
}

bool sameBits(const float* a, const float* b, size_t n) {
    return n == 0 || std::memcmp(a, b, n * sizeof(float)) == 0;  // no AOVs: empty, null data
}

/// Every per-pixel estimator of the registry, on the full and the compact image, pixel by pixel;
/// G-MoN and G-MoN_b with both Gini inputs (gini=abs, the default, and gini=shift).
void expectEstimatorsAgree(const StatsImage& full, const StatsImage& small) {
    ASSERT_EQ(full.pixelCount(), small.pixelCount());
    const size_t A = full.header.aovs.size();
    const std::vector<AovClass> classes = aovClasses(full.header.aovs);
    for (const Operation& op : operationRegistry()) {
        if (op.input != InputKind::BufferMeans) continue;
        for (const char* gini : {"", "shift"}) {
            if (*gini != '\0' && op.param("gini") == nullptr) continue;
            for (const char* mode : {"lum", "channel"}) {
                PixelKernel kernel;
                std::string err;
                std::map<std::string, std::string> kv;
                if (*gini != '\0') kv["gini"] = gini;
                const ParamSpec* modeParam = op.param("mode");
                if (modeParam != nullptr && !modeParam->fixed)
                    kv["mode"] = mode;
                else if (std::string(mode) == "channel")
                    continue;
                ASSERT_TRUE(bindPixelKernel(op, kv, kLuma, kernel, err)) << err;
                EstimatorScratch sf, sc;
                sf.wantWeights = sc.wantWeights = kernel.mode == EstimatorMode::Luminance && A > 0;
                AovScratch as;
                for (size_t p = 0; p < full.pixelCount(); ++p) {
                    PixelEstimate ef, ec;
                    kernel.estimate(full.pixelBuffers(p), ef, sf);
                    kernel.estimate(small.pixelBuffers(p), ec, sc);
                    const bool kept = small.buffersOf(p) == full.header.M && full.header.M > 1;
                    const std::string where = op.name + ":mode=" + mode +
                                              (*gini ? ":gini=shift" : "") + " pixel " +
                                              std::to_string(p) + (kept ? " (kept)" : " (mean)");
                    std::vector<float> af(A), ac(A);
                    if (sf.wantWeights) {
                        applyAovWeights(sf.bufferWeight.data(), sf.bufferWeight.size(),
                                        full.aov.data() + full.bufferBegin(p) * A, A,
                                        classes.data(), af.data(), as);
                        applyAovWeights(sc.bufferWeight.data(), sc.bufferWeight.size(),
                                        small.aov.data() + small.bufferBegin(p) * A, A,
                                        classes.data(), ac.data(), as);
                    }
                    if (kept || op.name == "gmon") {
                        // The same buffers (kept), or G-MoN's own value (exact by construction).
                        EXPECT_TRUE(sameBits(ef.rgb.data(), ec.rgb.data(), 3))
                            << where << ": " << ef.rgb[0] << " vs " << ec.rgb[0];
                        EXPECT_TRUE(sameBits(af.data(), ac.data(), A)) << where << " AOVs";
                    } else {
                        // One buffer: every estimator returns it, G-MoN's mean of the full buffers.
                        const PixelBuffers one = small.pixelBuffers(p);
                        ASSERT_EQ(one.M, 1) << where;
                        if (one.count[0] > 0.f)
                            EXPECT_TRUE(sameBits(ec.rgb.data(), one.mean, 3))
                                << where << ": " << ec.rgb[0] << " vs " << one.mean[0];
                        else
                            EXPECT_EQ(ec.rgb, (std::array<float, 3>{0.f, 0.f, 0.f})) << where;
                    }
                }
            }
        }
    }
}

/// Compacts `pixels` and checks every estimator; returns the compact image.
StatsImage compactAndCheck(const std::vector<Pixel>& pixels, int M,
                           const std::vector<AovChannel>& aovs = {}) {
    const StatsImage full = fullImage(pixels, M, aovs);
    StatsImage small;
    std::string err;
    CompactRule rule;
    rule.luma = kLuma;
    EXPECT_TRUE(compactStats(full, rule, small, err, 1)) << err;
    EXPECT_TRUE(small.header.compact);
    EXPECT_TRUE(validateStats(small, "compact", err)) << err;
    expectEstimatorsAgree(full, small);
    return small;
}

TEST(Compact, LightTailedPixelsKeepOneBufferHoldingGMoNsMean) {
    // Equal buffers, gentle noise: G < 1/k, G-MoN trims nothing.
    std::mt19937 rng(7);
    std::normal_distribution<float> noise(1.f, 0.02f);
    std::vector<Pixel> px;
    px.push_back(makePixel(21, 3, [](int, int c) { return 0.25f * float(c + 1); }));
    px.push_back(makePixel(21, 3, [&](int, int) { return noise(rng); }));
    const StatsImage small = compactAndCheck(px, 21);
    EXPECT_EQ(small.buffersOf(0), 1);
    EXPECT_EQ(small.buffersOf(1), 1);
    EXPECT_EQ(small.bufferCount[0], 63.f);  // every sample of the pixel
    EXPECT_EQ(small.bufferMean[0], 0.25f);
    EXPECT_EQ(small.bufferMean[2], 0.75f);
}

TEST(Compact, AFireflyKeepsEveryBuffer) {
    std::vector<Pixel> px;
    px.push_back(makePixel(21, 4, [](int j, int) { return j == 5 ? 1000.f : 0.5f; }));
    const StatsImage small = compactAndCheck(px, 21);
    EXPECT_EQ(small.buffersOf(0), 21);
    EXPECT_EQ(small.bufferMean[5 * 3], 1000.f);
}

TEST(Compact, ChannelModeDecidesToo) {
    // Luminance flat, but R and B trade places buffer by buffer: only channel mode trims.
    std::vector<Pixel> px;
    px.push_back(makePixel(9, 2, [](int j, int c) {
        if (c == 1) return 1.f;
        const bool odd = j % 2 == 1;
        const float r = odd ? 4.f : 0.f;
        return c == 0 ? r : (4.f - r) * float(0.2126 / 0.0722);
    }));
    const StatsImage small = compactAndCheck(px, 9);
    EXPECT_EQ(small.buffersOf(0), 9);
}

TEST(Compact, Extremes) {
    const float inf = std::numeric_limits<float>::infinity();
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float big = std::numeric_limits<float>::max();
    const float den = std::numeric_limits<float>::denorm_min();
    std::vector<Pixel> px;
    px.push_back(makePixel(7, 5, [](int, int) { return 0.f; }));                      // all zero
    px.push_back(makePixel(7, 5, [&](int j, int) { return j == 2 ? inf : 0.25f; }));  // one Inf
    px.push_back(makePixel(7, 5, [&](int j, int) { return j == 3 ? nan : 0.25f; }));  // one NaN
    px.push_back(makePixel(7, 5, [](int j, int) { return j == 1 ? -5.f : 0.25f; }));  // negative
    px.push_back(makePixel(7, 5, [](int j, int) { return -0.25f - 0.001f * float(j); }));
    px.push_back(makePixel(7, 5, [&](int j, int) { return den * float(j + 1); }));  // denormal
    px.push_back(makePixel(7, 5, [&](int j, int) { return big * (0.5f + 0.01f * float(j)); }));
    px.push_back(makePixel(7, 5, [&](int, int) { return big; }));                   // FLT_MAX
    Pixel sparse = makePixel(7, 0, [](int j, int) { return j < 3 ? 0.5f : 0.f; });  // spp < M
    for (int j = 0; j < 3; ++j) sparse.count[size_t(j)] = 1.f;
    px.push_back(sparse);
    px.push_back(makePixel(7, 0, [](int, int) { return 0.f; }));  // no sample at all
    const StatsImage small = compactAndCheck(px, 7);
    EXPECT_EQ(small.buffersOf(1), 7) << "a buffer holding Inf keeps the pixel's buffers";
    EXPECT_EQ(small.buffersOf(2), 7) << "a buffer holding NaN keeps the pixel's buffers";
    EXPECT_EQ(small.buffersOf(0), 1);
    // G-MoN's default Gini of magnitudes trims the buffer of -5 among 0.25s (G = 0.63; the shifted
    // form saw G = 1/7 and kept the mean); the smooth mirror of a positive pixel (-0.25 - 0.001 j)
    // is the mean by default, but gini=shift would trim it (G = 56/147 from its spread over its
    // minimum, c = 1), so it keeps its buffers for G-MoN to stay exact in both forms.
    EXPECT_EQ(small.buffersOf(3), 7);
    EXPECT_EQ(small.buffersOf(4), 7);
    EXPECT_EQ(small.buffersOf(7), 1);
    const size_t k = small.bufferBegin(7);
    EXPECT_EQ(small.bufferMean[k * 3], big) << "FLT_MAX buffers average to FLT_MAX, not Inf";
    EXPECT_EQ(small.buffersOf(8), 1);
    EXPECT_EQ(small.bufferCount[small.bufferBegin(8)], 3.f);
    EXPECT_EQ(small.bufferMean[small.bufferBegin(8) * 3], 0.5f) << "empty buffers carry no weight";
    EXPECT_EQ(small.bufferCount[small.bufferBegin(9)], 0.f);
}

TEST(Compact, EverySmallMAndAThousandBuffers) {
    std::mt19937 rng(11);
    std::exponential_distribution<float> expo(2.f);
    for (int M : {1, 2, 3, 4, 5, 999}) {
        std::vector<Pixel> px;
        for (int i = 0; i < 6; ++i)
            px.push_back(makePixel(M, float(1 + i), [&](int, int) { return expo(rng); }));
        px.push_back(makePixel(M, 2, [](int j, int) { return j == 0 ? 1e6f : 1.f; }));
        SCOPED_TRACE("M = " + std::to_string(M));
        const StatsImage small = compactAndCheck(px, M);
        if (M <= 3) {
            // G-MoN cannot trim below M = 4 (floor(G floor(M/2)) = 0 for G < 1): all are means.
            for (size_t p = 0; p < small.pixelCount(); ++p) EXPECT_EQ(small.buffersOf(p), 1);
        } else {
            EXPECT_EQ(small.buffersOf(px.size() - 1), M) << "the firefly keeps the buffers";
        }
    }
}

TEST(Compact, ParetoTailsWithAovsAndLabels) {
    // Heavy tails, alpha 1.1 .. 2: some pixels trim, some not; AOVs of every class follow.
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::vector<AovChannel> aovs = {{"A", AovClass::Alpha, ""},
                                    {"diffuse.R", AovClass::Light, ""},
                                    {"N.X", AovClass::Data, ""},
                                    {"IndexOB", AovClass::Id, ""}};
    std::vector<Pixel> px;
    for (double alpha : {1.1, 1.3, 1.5, 1.7, 2.0})
        for (int i = 0; i < 40; ++i)
            px.push_back(makePixel(
                21, 64,
                [&](int, int) {  // a buffer: the mean of its 64 Pareto samples
                    double sum = 0.0;
                    for (int s = 0; s < 64; ++s)
                        sum += 0.1 * std::pow(1.0 - double(u(rng)), -1.0 / alpha);
                    return float(sum / 64.0);
                },
                aovs.size()));
    const StatsImage small = compactAndCheck(px, 21, aovs);
    size_t kept = 0;
    for (size_t p = 0; p < small.pixelCount(); ++p) kept += small.buffersOf(p) == 21;
    EXPECT_GT(kept, 0u);
    EXPECT_LT(kept, small.pixelCount());
}

TEST(Compact, MarginAndZKeepMore) {
    std::mt19937 rng(5);
    std::normal_distribution<float> noise(1.f, 0.04f);  // G about 0.02: no trim (1/k = 0.1)
    std::vector<Pixel> px;
    for (int i = 0; i < 200; ++i)
        px.push_back(makePixel(21, 2, [&](int, int) { return noise(rng); }));
    const StatsImage full = fullImage(px, 21, {});
    const auto keptWith = [&](double margin, double z) {
        CompactRule rule;
        rule.luma = kLuma;
        rule.margin = margin;
        rule.z = z;
        StatsImage small;
        std::string err;
        EXPECT_TRUE(compactStats(full, rule, small, err, 1)) << err;
        size_t kept = 0;
        for (size_t p = 0; p < small.pixelCount(); ++p) kept += small.buffersOf(p) == 21;
        return kept;
    };
    const size_t base = keptWith(0, 0);
    EXPECT_EQ(base, 0u);
    EXPECT_GT(keptWith(0.78, 0), base);
    EXPECT_LT(keptWith(0.78, 0), px.size());
    EXPECT_EQ(keptWith(1.0, 0), px.size()) << "margin 1 keeps every pixel with G > 0";
    EXPECT_GT(keptWith(0, 2.0), base);
    StatsImage small;
    std::string err;
    CompactRule bad;
    bad.margin = 1.5;
    EXPECT_FALSE(compactStats(full, bad, small, err, 1));
    EXPECT_NE(err.find("margin"), std::string::npos) << err;
}

TEST(Compact, SpreadIsTheBetweenBufferCovariance) {
    // Hand-computed: 3 buffers, counts 1, 2, 1; R = 0, 1, 2 and G = 2, 1, 0; B = 1.
    Pixel one;
    one.mean = {0, 2, 1, 1, 1, 1, 2, 0, 1};
    one.count = {1, 2, 1};
    const PixelBuffers three{one.mean.data(), one.count.data(), 3};
    std::vector<int> valid;
    int excluded = 0;
    collectValidBuffers(three, valid, excluded);
    float s[kSpreadFloats];
    bufferSpread(three, valid, s);
    // mean R = (0 + 2 + 2) / 4 = 1; sum n (x - 1)^2 = 1 + 0 + 1 = 2; / (3 - 1) = 1.
    EXPECT_EQ(s[0], 3.f);
    EXPECT_FLOAT_EQ(s[spreadIndex(0, 0)], 1.f);
    EXPECT_FLOAT_EQ(s[spreadIndex(1, 1)], 1.f);
    EXPECT_FLOAT_EQ(s[spreadIndex(0, 1)], -1.f);
    EXPECT_FLOAT_EQ(s[spreadIndex(2, 2)], 0.f);
    EXPECT_FLOAT_EQ(s[spreadIndex(0, 2)], 0.f);
    const PixelBuffers first{one.mean.data(), one.count.data(), 1};
    collectValidBuffers(first, valid, excluded);
    float t[kSpreadFloats];
    bufferSpread(first, valid, t);
    EXPECT_EQ(t[0], 1.f);
    EXPECT_TRUE(std::isnan(t[1])) << "one buffer has no spread";
}

TEST(Compact, RefusesAdaptiveAndCompactInputs) {
    std::vector<Pixel> px = {makePixel(5, 1, [](int, int) { return 1.f; })};
    const StatsImage full = fullImage(px, 5, {});
    CompactRule rule;
    rule.luma = kLuma;
    StatsImage small, again;
    std::string err;
    ASSERT_TRUE(compactStats(full, rule, small, err, 1)) << err;
    EXPECT_FALSE(compactStats(small, rule, again, err, 1));
    EXPECT_NE(err.find("already compact"), std::string::npos) << err;
    StatsImage merged;
    EXPECT_FALSE(mergeStats(small, small, merged, err));
    EXPECT_NE(err.find("compact"), std::string::npos) << err;
}

TEST(Compact, ResultDoesNotDependOnThreads) {
    std::mt19937 rng(9);
    std::lognormal_distribution<float> ln(0.f, 1.5f);
    std::vector<Pixel> px;
    for (int i = 0; i < 3000; ++i) px.push_back(makePixel(8, 3, [&](int, int) { return ln(rng); }));
    const StatsImage full = fullImage(px, 8, {});
    CompactRule rule;
    rule.luma = kLuma;
    StatsImage a, b;
    std::string err;
    ASSERT_TRUE(compactStats(full, rule, a, err, 1)) << err;
    ASSERT_TRUE(compactStats(full, rule, b, err, 4)) << err;
    EXPECT_EQ(a.bufferOffset, b.bufferOffset);
    EXPECT_TRUE(sameBits(a.bufferMean.data(), b.bufferMean.data(), a.bufferMean.size()));
    EXPECT_TRUE(sameBits(a.spread.data(), b.spread.data(), a.spread.size()));
}

}  // namespace
}  // namespace mcstat
