// The estimators' buffer weights and the shared step that applies them to AOVs
// (include/mcstat/filters/aov_weights.h, docs/aovs.md): weights reproduce the beauty, asking for
// them changes no bit of it, and AOVs that sum to the beauty in every buffer sum to the estimate.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "filters/pixel/pixel_support.h"
#include "mcstat/filters/aov_weights.h"
#include "mcstat/filters/registry.h"
#include "mcstat/filters/window/filter3d.h"
#include "mcstat/filters/window/mif.h"
#include "mcstat/filters/window/window_rank.h"

namespace mcstat {
namespace {

using testing::grey;
using testing::kInf;
using testing::kLuma;
using testing::kNaN;
using testing::Pixel;

using testing::kernelOf;

/// `est` bound to its defaults in luminance mode (or `mode`), luma kLuma.
PixelKernel kernel(const Operation& est, EstimatorMode mode = EstimatorMode::Luminance) {
    return kernelOf(est.name, mode);
}

/// Random pixels with the extremes: fireflies, zero counts (spp < M), NaN/Inf buffers,
/// negative means, denormals, 1e38.
Pixel randomPixel(std::mt19937& rng, int M) {
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::vector<std::array<float, 3>> rgb;
    std::vector<float> n;
    for (int j = 0; j < M; ++j) {
        const float r = u(rng);
        std::array<float, 3> c{u(rng), u(rng), u(rng)};
        if (r < 0.08f) c = {c[0] * 1e4f, c[1] * 1e4f, c[2] * 1e4f};  // firefly
        if (r > 0.97f) c[1] = kNaN;
        if (r > 0.95f && r <= 0.97f) c[0] = kInf;
        if (r > 0.93f && r <= 0.95f) c = {-c[0], -c[1], c[2]};
        if (r > 0.92f && r <= 0.93f) c = {1e-40f, 1e-41f, 1e-39f};
        if (r > 0.91f && r <= 0.92f) c = {1e38f, 1e38f, 1e38f};
        rgb.push_back(c);
        n.push_back(u(rng) < 0.1f ? 0.f : float(1 + int(u(rng) * 4)));
    }
    return Pixel(rgb, n);
}

TEST(BufferWeights, EveryEstimatorReproducesItsBeautyAndChangesNoBit) {
    std::mt19937 rng(7);
    for (const Operation& est : estimatorRegistry()) {
        for (int trial = 0; trial < 600; ++trial) {
            const int M = 1 + trial % 40;
            const Pixel px = randomPixel(rng, M);
            const PixelKernel k = kernel(est);
            EstimatorScratch plain, weighted;
            weighted.wantWeights = true;
            PixelEstimate a, b;
            k.estimate(px.view(), a, plain);
            k.estimate(px.view(), b, weighted);
            for (int c = 0; c < 3; ++c)
                ASSERT_EQ(std::memcmp(&a.rgb[c], &b.rgb[c], sizeof(float)), 0)
                    << est.name << " M=" << M << " trial " << trial;
            ASSERT_EQ(weighted.bufferWeight.size(), size_t(M)) << est.name;
            double sumW = 0.0, rgb[3] = {0, 0, 0};
            for (int j = 0; j < M; ++j) {
                const double w = weighted.bufferWeight[size_t(j)];
                ASSERT_GE(w, 0.0) << est.name;
                sumW += w;
                if (w > 0)
                    for (int c = 0; c < 3; ++c) rgb[c] += w * double(px.mean[size_t(j) * 3 + c]);
            }
            if (b.kept[0] == 0) {
                EXPECT_EQ(sumW, 0.0) << est.name;  // no valid buffer: black, no weight
                continue;
            }
            ASSERT_NEAR(sumW, 1.0, 1e-12) << est.name;
            for (int c = 0; c < 3; ++c) {
                const double scale = std::max(1e-30, std::abs(double(b.rgb[c])));
                EXPECT_NEAR(rgb[c], double(b.rgb[c]), 2e-6 * scale + 1e-37)
                    << est.name << " M=" << M << " c=" << c << " trial " << trial;
            }
        }
    }
}

TEST(BufferWeights, ChannelModeGivesNone) {
    // Ranked per channel, R, G and B may come from different buffers: no one weight per buffer.
    // The mean has no mode (every channel is the count-weighted mean): its weights exist.
    const Pixel px = grey({1, 2, 3, 100, 5});
    for (const Operation& est : estimatorRegistry()) {
        EstimatorScratch s;
        s.wantWeights = true;
        PixelEstimate e;
        kernel(est, EstimatorMode::PerChannel).estimate(px.view(), e, s);
        EXPECT_EQ(s.bufferWeight.empty(), est.name != "mean") << est.name;
        EXPECT_EQ(est.param("mode") == nullptr, est.name == "mean") << est.name;
    }
}

TEST(BufferWeights, HandComputed) {
    // Grey means 1, 2, 3, 100, 5 with counts 1: sorted 1, 2, 3, 5, 100, MoN is the middle
    // value 3, buffer 2.
    const Pixel px = grey({1, 2, 3, 100, 5});
    EstimatorScratch s;
    s.wantWeights = true;
    PixelEstimate e;
    kernelOf("mon").estimate(px.view(), e, s);
    EXPECT_EQ(s.bufferWeight, (std::vector<double>{0, 0, 1, 0, 0}));
    // The mean: counts as weights.
    const Pixel counted = grey({1, 2, 4}, {1, 2, 1});
    kernelOf("mean").estimate(counted.view(), e, s);
    EXPECT_EQ(s.bufferWeight, (std::vector<double>{0.25, 0.5, 0.25}));
    EXPECT_FLOAT_EQ(e.rgb[0], 2.25f);
    // TMPE alpha 0.25 over 8 equal-count buffers trims 2 from each side (values 1, 2 in buffers
    // 1, 3 and 8, 7 in buffers 0, 2): buffers 4..7 (values 6, 3, 5, 4) get 1/4 each.
    const Pixel eight = grey({8, 1, 7, 2, 6, 3, 5, 4});
    kernelOf("tmpe", EstimatorMode::Luminance, {{"alpha", "0.25"}}).estimate(eight.view(), e, s);
    EXPECT_EQ(s.bufferWeight, (std::vector<double>{0, 0, 0, 0, 0.25, 0.25, 0.25, 0.25}));
    // A buffer holding NaN gets no weight; an empty buffer neither.
    const Pixel broken = grey({1, kNaN, 3}, {1, 1, 0});
    kernelOf("mean").estimate(broken.view(), e, s);
    EXPECT_EQ(s.bufferWeight, (std::vector<double>{1, 0, 0}));
}

TEST(ApplyAovWeights, ClassesAndNonFiniteValues) {
    // Three inputs, two AOVs per class tested: light (weighted), id (largest weight).
    const double w[3] = {0.25, 0.5, 0.25};
    const float aov[3 * 2] = {4, 10, 8, 20, 12, 30};
    const AovClass cls[2] = {AovClass::Light, AovClass::Id};
    float out[2];
    AovScratch s;
    applyAovWeights(w, 3, aov, 2, cls, out, s);
    EXPECT_FLOAT_EQ(out[0], 0.25f * 4 + 0.5f * 8 + 0.25f * 12);
    EXPECT_EQ(out[1], 20.f);  // the label of input 1, never an average
    // A NaN in one input of one channel: left out there, the rest renormalised; the other
    // channel keeps every input.
    const float withNaN[3 * 2] = {4, 1, kNaN, 1, 12, 1};
    const AovClass light2[2] = {AovClass::Light, AovClass::Data};
    applyAovWeights(w, 3, withNaN, 2, light2, out, s);
    EXPECT_FLOAT_EQ(out[0], (0.25f * 4 + 0.25f * 12) / 0.5f);
    EXPECT_FLOAT_EQ(out[1], 1.f);
    // No weight at all (no valid beauty buffer): 0 for weighted classes, input 0 for ids.
    const double none[3] = {0, 0, 0};
    applyAovWeights(none, 3, aov, 2, cls, out, s);
    EXPECT_EQ(out[0], 0.f);
    EXPECT_EQ(out[1], 10.f);
    // Ties in weight: the lowest index.
    const double tie[3] = {0.5, 0.5, 0};
    applyAovWeights(tie, 3, aov, 2, cls, out, s);
    EXPECT_EQ(out[1], 10.f);
}

TEST(ApplyAovWeights, LightGroupsKeepSummingToTheBeauty) {
    // Per buffer the beauty is key + fill + sky exactly (grey, so luminance = value); a firefly
    // in the key light of one buffer. Every estimator's result keeps the sum.
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (const Operation& est : estimatorRegistry()) {
        for (int trial = 0; trial < 100; ++trial) {
            const int M = 2 + trial % 30;
            std::vector<float> beauty, aov;
            for (int j = 0; j < M; ++j) {
                const float key = u(rng) < 0.1f ? 5000.f * u(rng) : u(rng);
                const float fill = u(rng), sky = 0.1f * u(rng);
                const float b = key + fill + sky;
                beauty.push_back(b);
                aov.insert(aov.end(), {key, fill, sky});
            }
            const Pixel px = grey(beauty);
            EstimatorScratch s;
            s.wantWeights = true;
            PixelEstimate e;
            kernel(est).estimate(px.view(), e, s);
            const AovClass cls[3] = {AovClass::Light, AovClass::Light, AovClass::Light};
            float out[3];
            AovScratch as;
            applyAovWeights(s.bufferWeight.data(), size_t(M), aov.data(), 3, cls, out, as);
            const double sum = double(out[0]) + out[1] + out[2];
            EXPECT_NEAR(sum, double(e.rgb[0]), 4e-6 * std::max(1.0, double(e.rgb[0])))
                << est.name << " M=" << M;
        }
    }
}

// The window filters: every element's share of the beauty's average, applied to the element's
// values, reproduces the beauty; asking for the weights changes no bit.
TEST(WindowWeights, ThreeDFiltersAndMedianImageFilterReproduceTheirBeauty) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const int W = 9, H = 7, M = 6;
    std::vector<float> mean(size_t(W) * H * M * 3), count(size_t(W) * H * M);
    for (size_t k = 0; k < count.size(); ++k) {
        count[k] = u(rng) < 0.05f ? 0.f : float(1 + int(u(rng) * 3));
        for (int c = 0; c < 3; ++c)
            mean[k * 3 + size_t(c)] = u(rng) < 0.05f ? 1000.f * u(rng) : u(rng);
        if (u(rng) < 0.02f) mean[k * 3] = kNaN;
    }
    const FixedBufferGrid grid{mean.data(), count.data(), W, H, M};
    std::vector<float> image(size_t(W) * H * 3);
    for (size_t i = 0; i < image.size(); ++i) image[i] = u(rng) < 0.05f ? 50.f : u(rng);
    const RGBImageView img{image.data(), W, H};
    for (const double alpha : {0.0, 0.25, 0.5})
        for (const int64_t centre : {int64_t(1), int64_t(3)}) {
            SpatialParams p;
            p.luma = kLuma;
            p.alpha = alpha;
            p.centreWeight = centre;
            for (int y = 0; y < H; ++y)
                for (int x = 0; x < W; ++x) {
                    SpatialScratch plain, weighted;
                    weighted.wantWeights = true;
                    PixelEstimate a, b;
                    filter3DPixel(grid.view(), x, y, p, a, plain);
                    filter3DPixel(grid.view(), x, y, p, b, weighted);
                    ASSERT_EQ(a.rgb, b.rgb);
                    double rgb[3] = {0, 0, 0}, sum = 0;
                    for (const auto& e : weighted.weights) {
                        const auto [xx, yy] = weighted.source[size_t(e.element)];
                        const PixelBuffers px = grid.at(xx, yy);
                        for (int c = 0; c < 3; ++c)
                            rgb[c] += e.weight * double(px.mean[size_t(e.buffer) * 3 + size_t(c)]);
                        sum += e.weight;
                    }
                    ASSERT_NEAR(sum, 1.0, 1e-12);
                    for (int c = 0; c < 3; ++c)
                        EXPECT_NEAR(rgb[c], b.rgb[size_t(c)],
                                    2e-6 * std::max(1.f, std::abs(b.rgb[size_t(c)])));
                    // MIF / WMIF over the image: weights per window pixel.
                    SpatialScratch mp, mw;
                    mw.wantWeights = true;
                    wmifPixel(img, x, y, p, a, mp);
                    wmifPixel(img, x, y, p, b, mw);
                    ASSERT_EQ(a.rgb, b.rgb);
                    double m[3] = {0, 0, 0};
                    for (const auto& e : mw.weights) {
                        const auto [xx, yy] = mw.source[size_t(e.element)];
                        for (int c = 0; c < 3; ++c)
                            m[c] += e.weight *
                                    double(image[(size_t(yy) * W + size_t(xx)) * 3 + size_t(c)]);
                    }
                    for (int c = 0; c < 3; ++c)
                        EXPECT_NEAR(m[c], b.rgb[size_t(c)],
                                    2e-6 * std::max(1.f, std::abs(b.rgb[size_t(c)])));
                }
        }
}

TEST(SmallestRobustM, MatchesTheTrimRules) {
    EXPECT_EQ(kernelOf("gmon").smallestRobustM, 4);
    EXPECT_EQ(kernelOf("mon").smallestRobustM, 3);
    EXPECT_EQ(kernelOf("mean").smallestRobustM, 1);
    // floor(0.25 * 4) = 1
    EXPECT_EQ(kernelOf("tmpe", EstimatorMode::Luminance, {{"alpha", "0.25"}}).smallestRobustM, 4);
    // G-MoN at M = 3 is the mean whatever the values (the Gini coefficient stays below 1).
    for (const auto& v : {std::vector<float>{0, 0, 1000}, {1, 2, 3}, {0, 1e30f, 1e30f}}) {
        const Pixel px = grey(v);
        EstimatorScratch s1, s2;
        PixelEstimate g, m;
        kernelOf("gmon").estimate(px.view(), g, s1);
        kernelOf("mean").estimate(px.view(), m, s2);
        EXPECT_EQ(g.rgb[0], m.rgb[0]);
    }
}

}  // namespace
}  // namespace mcstat
