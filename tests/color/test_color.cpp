// The built-in OCIO config: luma coefficients and the sRGB display view.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include "mcstat/color.h"

using namespace mcstat;

namespace {
double srgbEncode(double x) {  // IEC 61966-2-1, for checking OCIO's result
    return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1.0 / 2.4) - 0.055;
}
}  // namespace

TEST(Color, LumaComesFromTheConfig) {
    if (std::getenv("OCIO")) GTEST_SKIP() << "$OCIO is set; the built-in config is not active";
    std::string warning;
    auto luma = lumaCoefficients(&warning);
    EXPECT_TRUE(warning.empty());
    EXPECT_DOUBLE_EQ(luma[0], 0.2126);
    EXPECT_DOUBLE_EQ(luma[1], 0.7152);
    EXPECT_DOUBLE_EQ(luma[2], 0.0722);
    EXPECT_NE(std::string(builtinOcioConfig()).find("luma: [0.2126, 0.7152, 0.0722]"),
              std::string::npos);
}

TEST(Color, DisplayViewIsSrgb) {
    if (std::getenv("OCIO")) GTEST_SKIP() << "$OCIO is set; the built-in config is not active";
    float px[] = {0.18f, 0.001f, 1.0f, 0.0f, 0.5f, 4.0f};
    std::string err;
    ASSERT_TRUE(applyDisplayTransform(px, 2, err)) << err;
    const double in[] = {0.18, 0.001, 1.0, 0.0, 0.5, 4.0};
    for (int i = 0; i < 6; ++i) EXPECT_NEAR(px[i], srgbEncode(in[i]), 2e-4) << i;
}

TEST(Color, UnknownDisplayIsAnError) {
    float px[] = {0.5f, 0.5f, 0.5f};
    std::string err;
    EXPECT_FALSE(applyDisplayTransform(px, 1, err, "NoSuchDisplay"));
    EXPECT_FALSE(err.empty());
}
