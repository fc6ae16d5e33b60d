// Working spaces: the luma weights computed from chromaticities (SMPTE RP 177) against the values
// the standards and their technical bulletins publish, and the lookups by name and chromaticities.
#include <gtest/gtest.h>

#include "mcstat/core/color_space.h"

namespace mcstat {
namespace {

struct Published {
    const char* name;
    std::array<double, 3> y;  // the Y row of the published RGB -> XYZ matrix
};

// Rec.709: the sRGB matrix of IEC 61966-2-1 at full precision (BT.709's 0.2126, 0.7152, 0.0722
// are these rounded to 4 digits); AP1 and AP0: ACES TB-2014-004 (AP1 to XYZ, AP0 to XYZ);
// Display P3: the NPM of SMPTE EG 432-1 with D65; Rec.2020: BT.2020 (0.2627, 0.6780, 0.0593
// rounded).
const Published kPublished[] = {
    {"lin_rec709", {0.2126390059, 0.7151686788, 0.0721923154}},
    {"ACEScg", {0.2722287168, 0.6740817658, 0.0536895174}},
    {"ACES2065-1", {0.3439664498, 0.7281660966, -0.0721325464}},
    {"lin_p3d65", {0.2289745641, 0.6917385218, 0.0792869141}},
    {"lin_rec2020", {0.2627002120, 0.6779980715, 0.0593017165}},
};

TEST(ColorSpace, LumaFromChromaticitiesMatchesPublishedValues) {
    for (const Published& p : kPublished) {
        const WorkingSpace* s = findWorkingSpace(p.name);
        ASSERT_NE(s, nullptr) << p.name;
        std::array<double, 3> w{};
        ASSERT_TRUE(lumaFromChromaticities(s->xy, w)) << p.name;
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(w[size_t(c)], p.y[size_t(c)], 1e-6) << p.name << c;
        EXPECT_NEAR(w[0] + w[1] + w[2], 1.0, 1e-12) << p.name;  // white has Y = 1
    }
}

TEST(ColorSpace, Ap1MatrixMatchesAcesBulletin) {
    // TB-2014-004 AP1 to XYZ, all three rows.
    const double published[3][3] = {{0.6624541811, 0.1340042065, 0.1561876870},
                                    {0.2722287168, 0.6740817658, 0.0536895174},
                                    {-0.0055746495, 0.0040607335, 1.0103391003}};
    std::array<std::array<double, 3>, 3> m{};
    ASSERT_TRUE(rgbToXyz(findWorkingSpace("ACEScg")->xy, m));
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(m[size_t(r)][size_t(c)], published[r][c], 1e-6) << r << c;
}

TEST(ColorSpace, Rec709ToAp1MatchesTheAcesConfigsMatrix) {
    // The ACES reference configs' Rec.709 -> ACEScg (Bradford D65 -> ACES white).
    const double published[3][3] = {{0.6130974024, 0.3395231462, 0.0473794514},
                                    {0.0701937225, 0.9163538791, 0.0134523985},
                                    {0.0206155929, 0.1095697729, 0.8698146342}};
    std::array<std::array<double, 3>, 3> m{};
    ASSERT_TRUE(rgbToRgb(findWorkingSpace("lin_rec709")->xy, findWorkingSpace("ACEScg")->xy, m));
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(m[size_t(r)][size_t(c)], published[r][c], 1e-6) << r << c;
    // Same white: no adaptation, and the identity for a space to itself.
    ASSERT_TRUE(rgbToRgb(findWorkingSpace("ACEScg")->xy, findWorkingSpace("ACEScg")->xy, m));
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(m[size_t(r)][size_t(c)], r == c, 1e-12);
}

TEST(ColorSpace, DegenerateChromaticitiesAreRefused) {
    std::array<double, 3> w{};
    Chromaticities zeroY = findWorkingSpace("lin_rec709")->xy;
    zeroY.gy = 0.0;
    EXPECT_FALSE(lumaFromChromaticities(zeroY, w));
    Chromaticities same{0.3, 0.3, 0.3, 0.3, 0.3, 0.3, 0.3127, 0.329};  // one point three times
    EXPECT_FALSE(lumaFromChromaticities(same, w));
}

TEST(ColorSpace, NamesInteropIdsAndAliases) {
    EXPECT_STREQ(findWorkingSpace("lin_ap1_scene")->name, "ACEScg");
    EXPECT_STREQ(findWorkingSpace("acescg")->name, "ACEScg");
    EXPECT_STREQ(findWorkingSpace("AP0")->name, "ACES2065-1");
    EXPECT_STREQ(findWorkingSpace("lin_rec709_scene")->name, "lin_rec709");
    EXPECT_STREQ(findWorkingSpace("Linear")->name, "lin_rec709");
    EXPECT_STREQ(findWorkingSpace("lin_rec2020")->interopID, "lin_rec2020_scene");
    EXPECT_EQ(findWorkingSpace("sRGB"), nullptr);  // display-encoded, not a working space
    EXPECT_EQ(findWorkingSpace("ACEScct"), nullptr);
}

TEST(ColorSpace, MatchChromaticitiesAsFilesStoreThem) {
    // As float, the way the attribute holds them.
    const Chromaticities ap1{float(0.713), float(0.293), float(0.165),   float(0.830),
                             float(0.128), float(0.044), float(0.32168), float(0.33767)};
    ASSERT_NE(matchChromaticities(ap1), nullptr);
    EXPECT_STREQ(matchChromaticities(ap1)->name, "ACEScg");
    Chromaticities other = ap1;
    other.rx = 0.70;
    EXPECT_EQ(matchChromaticities(other), nullptr);
    EXPECT_EQ(chromaticitiesText(findWorkingSpace("ACEScg")->xy),
              "R 0.713 0.293, G 0.165 0.83, B 0.128 0.044, W 0.32168 0.33767");
}

}  // namespace
}  // namespace mcstat
