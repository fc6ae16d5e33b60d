// Metrics against hand-computed values.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "mcstat/metrics.h"

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
