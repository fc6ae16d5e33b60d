// The built-in OCIO config: luma coefficients and the sRGB display view.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include "mcstat/color/color.h"

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

TEST(Color, Ap1PixelsAreShownAsTheSameLightAsRec709Ones) {
    if (std::getenv("OCIO")) GTEST_SKIP() << "$OCIO is set; the built-in config is not active";
    // Rec.709 values and the same light in ACEScg (the ACES configs' matrix): the same display
    // values, the AP1 ones through a matrix back to Rec.709 first, with a note.
    const double toAp1[3][3] = {{0.6130974024, 0.3395231462, 0.0473794514},
                                {0.0701937225, 0.9163538791, 0.0134523985},
                                {0.0206155929, 0.1095697729, 0.8698146342}};
    float rec709[] = {0.18f, 0.05f, 0.6f, 1.0f, 0.5f, 0.02f};
    float ap1[6];
    for (int p = 0; p < 2; ++p)
        for (int r = 0; r < 3; ++r)
            ap1[p * 3 + r] = float(toAp1[r][0] * rec709[p * 3] + toAp1[r][1] * rec709[p * 3 + 1] +
                                   toAp1[r][2] * rec709[p * 3 + 2]);
    std::string err, note;
    ASSERT_TRUE(applyDisplayTransform(rec709, 2, err, "", "", "lin_rec709", &note)) << err;
    EXPECT_EQ(note, "");
    ASSERT_TRUE(applyDisplayTransform(ap1, 2, err, "", "", "ACEScg", &note)) << err;
    EXPECT_NE(note.find("ACEScg shown through a matrix to lin_rec709"), std::string::npos) << note;
    for (int i = 0; i < 6; ++i) EXPECT_NEAR(ap1[i], rec709[i], 1e-5) << i;
}

TEST(Color, LumaOfAFilesSpace) {
    if (std::getenv("OCIO")) GTEST_SKIP() << "$OCIO is set; the built-in config is not active";
    std::array<double, 3> w{};
    std::string err, warning;
    // The built-in config's scene_linear is lin_rec709: its luma.
    ASSERT_TRUE(lumaCoefficients("lin_rec709", w, err, &warning)) << err;
    EXPECT_DOUBLE_EQ(w[0], 0.2126);
    // ACEScg: the Y row of AP1's RGB->XYZ (ACES TB-2014-004), whatever the config says.
    ASSERT_TRUE(lumaCoefficients("lin_ap1_scene", w, err, &warning)) << err;
    EXPECT_NEAR(w[0], 0.2722287168, 1e-9);
    EXPECT_NEAR(w[1], 0.6740817658, 1e-9);
    EXPECT_NEAR(w[2], 0.0536895174, 1e-9);
    EXPECT_TRUE(warning.empty());
    EXPECT_FALSE(lumaCoefficients("ACEScct", w, err));
    EXPECT_EQ(err.substr(0, 36), "colour space 'ACEScct' is unknown (k");
}

TEST(Color, OcioUrisNeedOcio22) {
    std::string err;
    const bool ok = setColorConfig("ocio://default", err);
    if (ocioVersion() < "2.2") {
        EXPECT_FALSE(ok);
        EXPECT_EQ(err.find('\n'), std::string::npos);
        EXPECT_NE(
            err.find("need OpenColorIO 2.2 or later; this mcstat is built with " + ocioVersion()),
            std::string::npos)
            << err;
    }
    EXPECT_FALSE(setColorConfig("/no/such/config.ocio", err));
    EXPECT_NE(err.find("colour config '/no/such/config.ocio' unusable"), std::string::npos) << err;
}
