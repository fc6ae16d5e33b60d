// Metrics against hand-computed values.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "mcstat/analysis/metrics.h"

using namespace mcstat;

namespace {
DiffOptions options() {
    DiffOptions o;
    o.luma = {0.2126, 0.7152, 0.0722};
    return o;
}
}  // namespace

TEST(Metrics, IdenticalImages) {
    std::vector<float> a(16 * 12 * 3);
    for (size_t i = 0; i < a.size(); ++i) a[i] = float(i % 7) * 0.1f;
    DiffMetrics m = compareImages(a.data(), a.data(), a.data(), a.data(), 16, 12, options());
    EXPECT_EQ(m.relMSE, 0.0);
    EXPECT_NEAR(m.ssim, 1.0, 1e-12);
    EXPECT_TRUE(std::isinf(m.psnr));
    EXPECT_EQ(m.fireflies, 0);
    EXPECT_EQ(m.pixels, 16 * 12);
}

TEST(Metrics, OneFireflyHandComputed) {
    const int w = 16, h = 16;
    std::vector<float> ref(w * h * 3, 0.5f), img = ref;
    for (int c = 0; c < 3; ++c) img[(3 * w + 3) * 3 + c] = 10.f;
    DiffMetrics m = compareImages(img.data(), ref.data(), img.data(), ref.data(), w, h, options());
    // 3 channels of (9.5^2 / (0.25 + 0.01)) over 3 * 256 values
    EXPECT_NEAR(m.relMSE, (90.25 / 0.26) / 256.0, 1e-12);
    EXPECT_EQ(m.fireflies, 1);
    // display values clamp at 1: MSE = 3 * 0.5^2 / 768
    EXPECT_NEAR(m.psnr, 10.0 * std::log10(1.0 / (0.75 / 768.0)), 1e-9);
    EXPECT_LT(m.ssim, 1.0);
}

TEST(Metrics, FireflyNeedsBothRatioAndFloor) {
    std::vector<float> ref = {0.01f, 0.01f, 0.01f, 5.f, 5.f, 5.f},
                       img = {0.05f, 0.05f, 0.05f, 7.f, 7.f, 7.f};
    // pixel 0: 5x brighter but only 0.04 above; pixel 1: 2 above but only 1.4x
    DiffMetrics m = compareImages(img.data(), ref.data(), img.data(), ref.data(), 2, 1, options());
    EXPECT_EQ(m.fireflies, 0);
    DiffOptions o = options();
    o.fireflyFloor = 0.03;
    EXPECT_EQ(compareImages(img.data(), ref.data(), img.data(), ref.data(), 2, 1, o).fireflies, 1);
}

TEST(Metrics, SsimOfConstantImages) {
    // constant a and b: luminance term only, (2ab + C1) / (a^2 + b^2 + C1)
    std::vector<float> a(20 * 20, 0.5f), b(20 * 20, 0.25f);
    const double C1 = 1e-4;
    EXPECT_NEAR(ssimChannel(a.data(), b.data(), 1, 20, 20, nullptr),
                (2 * 0.5 * 0.25 + C1) / (0.25 + 0.0625 + C1), 1e-12);
}

TEST(Metrics, NonFinitePixelsAreCountedAndLeftOut) {
    std::vector<float> ref(4 * 4 * 3, 1.f), img = ref;
    img[0] = std::numeric_limits<float>::quiet_NaN();
    img[5] = std::numeric_limits<float>::infinity();
    DiffMetrics m = compareImages(img.data(), ref.data(), img.data(), ref.data(), 4, 4, options());
    EXPECT_EQ(m.nonFinite, 2);
    EXPECT_EQ(m.pixels, 14);
    EXPECT_EQ(m.relMSE, 0.0);
}

TEST(Metrics, NormalisedBiasAndNoiseHandComputed) {
    // Jung eq. 5.25-5.27 on luminance; grey pixels so Y = the value (luma sums to 1)
    // ref 1, 2, 0 (black), 4; image 1.5, 1, 0.02, 4
    // E' = 0.5, -0.5, 0.02 / eps = 2 (eps = 0.01), 0 -> B = 2 / 4 = 0.5
    // N = (0^2 + (-1)^2 + 1.5^2 + (-0.5)^2) / 4 = 3.5 / 4 = 0.875
    const std::vector<float> ref = {1, 1, 1, 2, 2, 2, 0, 0, 0, 4, 4, 4},
                             img = {1.5f, 1.5f, 1.5f, 1, 1, 1, 0.02f, 0.02f, 0.02f, 4, 4, 4};
    DiffMetrics m = compareImages(img.data(), ref.data(), img.data(), ref.data(), 4, 1, options());
    EXPECT_NEAR(m.normBias, 0.5, 1e-7);
    EXPECT_NEAR(m.normNoise, 0.875, 1e-6);
    EXPECT_EQ(m.normFloored, 1);
    // a larger epsilon changes only the black pixel's term: E' = 0.02 / 0.1 = 0.2
    // B = 0.2 / 4 = 0.05; N = (0.45^2 + 0.55^2 + 0.15^2 + 0.05^2) / 4 = 0.53 / 4 = 0.1325
    DiffOptions o = options();
    o.normEpsilon = 0.1;
    m = compareImages(img.data(), ref.data(), img.data(), ref.data(), 4, 1, o);
    EXPECT_NEAR(m.normBias, 0.05, 1e-7);
    EXPECT_NEAR(m.normNoise, 0.1325, 1e-6);
    // identical images: no bias, no noise
    m = compareImages(ref.data(), ref.data(), ref.data(), ref.data(), 4, 1, options());
    EXPECT_EQ(m.normBias, 0.0);
    EXPECT_EQ(m.normNoise, 0.0);
}

TEST(Metrics, NormalisedErrorUsesLuminanceAndSkipsNonFinite) {
    // the thesis' pixel value is a scalar: luminance. A colour error with the reference's luminance
    // (pure red against green of equal Y) has E' = 0; twice the reference has E' = 1.
    const DiffOptions o = options();
    const float g = float(o.luma[0] / o.luma[1]);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const std::vector<float> ref = {1, 0, 0, 1, 1, 1, 1, 1, 1},  //
        img = {0, g, 0, 2, 2, 2, nan, 1, 1};
    DiffMetrics m = compareImages(img.data(), ref.data(), img.data(), ref.data(), 3, 1, o);
    EXPECT_EQ(m.pixels, 2);
    EXPECT_EQ(m.nonFinite, 1);
    // E' = 0 and 1: B = 0.5, N = ((0 - 0.5)^2 + (1 - 0.5)^2) / 2 = 0.25
    EXPECT_NEAR(m.normBias, 0.5, 1e-6);
    EXPECT_NEAR(m.normNoise, 0.25, 1e-6);
    EXPECT_EQ(m.normFloored, 0);
}

TEST(Metrics, DetailHandComputed) {
    // 3 x 1 grey images, ref 0, 0.6, 0 (one bright line of pixel width), image 0, 0.3, 0.
    // 3x3 neighbourhoods cut at the borders: pixel 0 sees {0, 1}, pixel 1 all three, pixel 2 {1,
    // 2}. ref high pass: 0 - 0.3 = -0.3, 0.6 - 0.2 = 0.4, -0.3; the image's is half of it: detail =
    // sum h(x) h(r) / sum h(r)^2 = 0.5.
    const std::vector<float> ref = {0, 0, 0, 0.6f, 0.6f, 0.6f, 0, 0, 0},
                             img = {0, 0, 0, 0.3f, 0.3f, 0.3f, 0, 0, 0};
    DiffMetrics m = compareImages(img.data(), ref.data(), img.data(), ref.data(), 3, 1, options());
    EXPECT_NEAR(m.detail, 0.5, 1e-7);
    // identical: 1; an image shifted by a constant keeps every bit of the detail
    std::vector<float> up = ref;
    for (float& v : up) v += 0.2f;
    EXPECT_NEAR(
        compareImages(ref.data(), ref.data(), ref.data(), ref.data(), 3, 1, options()).detail, 1.0,
        1e-12);
    EXPECT_NEAR(compareImages(up.data(), ref.data(), up.data(), ref.data(), 3, 1, options()).detail,
                1.0, 1e-6);
    // a flat reference has no detail to keep: undefined, not 1
    const std::vector<float> flat(9, 0.5f);
    EXPECT_TRUE(std::isnan(
        compareImages(img.data(), flat.data(), img.data(), flat.data(), 3, 1, options()).detail));
}

TEST(Metrics, DetailFallsWithBlurNotWithNoise) {
    // A one-pixel checker (the finest detail an image holds) at 0.2 / 0.8.
    const int w = 32, h = 32;
    std::vector<float> ref(w * h * 3), blur(w * h * 3), noisy(w * h * 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) ref[(y * w + x) * 3 + c] = ((x + y) % 2) ? 0.8f : 0.2f;
    // 3x3 box blur (cut at borders): the checker's contrast drops to a ninth inside
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) {
                double s = 0;
                int n = 0;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx)
                        if (x + dx >= 0 && x + dx < w && y + dy >= 0 && y + dy < h) {
                            s += ref[((y + dy) * w + x + dx) * 3 + c];
                            ++n;
                        }
                blur[(y * w + x) * 3 + c] = float(s / n);
            }
    const DiffMetrics b =
        compareImages(blur.data(), ref.data(), blur.data(), ref.data(), w, h, options());
    EXPECT_LT(b.detail, 0.2);
    EXPECT_GT(b.detail, -0.2);
    // Independent noise of standard deviation 0.1 on every value: its expectation stays 1
    // (the spread of the slope over 3,072 values is about 0.1 / 0.3 / sqrt(3072 * 8 / 9) = 0.006).
    uint32_t state = 12345;
    auto uniform = [&] {
        state = state * 1664525u + 1013904223u;
        return (state >> 8) * (1.0 / 16777216.0);
    };
    for (size_t i = 0; i < ref.size(); ++i)
        noisy[i] = ref[i] + float(0.1 * std::sqrt(12.0) * (uniform() - 0.5));
    const DiffMetrics n =
        compareImages(noisy.data(), ref.data(), noisy.data(), ref.data(), w, h, options());
    EXPECT_NEAR(n.detail, 1.0, 0.03);
    EXPECT_GT(n.detail - b.detail, 0.8);
}

TEST(Metrics, DetailLeavesOutNonFinitePixels) {
    // A NaN pixel is neither a centre nor a neighbour: the rest is compared as if it were absent.
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const std::vector<float> ref = {0, 0, 0, 0.6f, 0.6f, 0.6f, 0, 0, 0, 0.9f, 0.9f, 0.9f},
                             img = {0, 0, 0, 0.3f, 0.3f, 0.3f, 0, 0, 0, nan, 0, 0};
    DiffMetrics m = compareImages(img.data(), ref.data(), img.data(), ref.data(), 4, 1, options());
    EXPECT_EQ(m.pixels, 3);
    EXPECT_NEAR(m.detail, 0.5, 1e-7);
}

TEST(Metrics, EnergyHandComputed) {
    // Grey pixels (Y = the value; luma sums to 1): ref 1, 2, 0, 1 (sum 4), image 1, 1, 0.5, 0.5
    // (sum 3): a quarter of the light gone. A NaN pixel counts in neither sum.
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const std::vector<float> ref = {1, 1, 1, 2, 2, 2, 0, 0, 0, 1, 1, 1, 7, 7, 7},
                             img = {1,    1,    1,    1,    1,   1, 0.5f, 0.5f,
                                    0.5f, 0.5f, 0.5f, 0.5f, nan, 0, 0};
    DiffMetrics m = compareImages(img.data(), ref.data(), img.data(), ref.data(), 5, 1, options());
    EXPECT_EQ(m.pixels, 4);
    EXPECT_NEAR(m.energy, -0.25, 1e-6);
    // the same image is 0; a black reference has no light to compare with
    EXPECT_EQ(compareImages(ref.data(), ref.data(), ref.data(), ref.data(), 4, 1, options()).energy,
              0.0);
    const std::vector<float> black(12, 0.f);
    EXPECT_TRUE(std::isnan(
        compareImages(img.data(), black.data(), img.data(), black.data(), 4, 1, options()).energy));
}
