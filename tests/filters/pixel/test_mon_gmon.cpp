// Estimators against hand-computed values and Buisine et al.'s equations 2, 4, 5, 6.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "mcstat/filters/pixel/gmon.h"
#include "mcstat/filters/pixel/ranking.h"
#include "pixel_support.h"

using namespace mcstat;

namespace {

using namespace mcstat::testing;

/// The registry's operation `name` (mean, mon, gmon, gmonb) on one pixel; `threshold` is
/// G-MoN_b's.
PixelEstimate run(const std::string& name, const Pixel& px,
                  EstimatorMode mode = EstimatorMode::PerChannel, double threshold = 0.25) {
    std::map<std::string, std::string> kv;
    if (name == "gmonb") kv["threshold"] = std::to_string(threshold);
    return runKernel(name, px, mode, kv);
}
}  // namespace

// ---- Gini coefficient, eq. 4 -----------------------------------------------------------------

TEST(Gini, HandComputedValues) {
    // {1,2,3,4}: 2*(1+4+9+16) / (4*10) - 5/4 = 1.5 - 1.25
    const double a[] = {1, 2, 3, 4};
    EXPECT_DOUBLE_EQ(giniSorted(a, 4), 0.25);
    // one non-zero of four: the maximum (M-1)/M
    const double b[] = {0, 0, 0, 1};
    EXPECT_DOUBLE_EQ(giniSorted(b, 4), 0.75);
    // {1,2,3,4,100}: sum (2j-6) x_j = 400, over 5*110
    const double c[] = {1, 2, 3, 4, 100};
    EXPECT_NEAR(giniSorted(c, 5), 400.0 / 550.0, 1e-15);
}

TEST(Gini, EqualZeroAndTinySets) {
    const double eq[] = {7, 7, 7, 7, 7};
    EXPECT_EQ(giniSorted(eq, 5), 0.0);
    const double zero[] = {0, 0, 0};
    EXPECT_EQ(giniSorted(zero, 3), 0.0);  // 0/0 in eq. 4: defined as perfect equality
    const double one[] = {42};
    EXPECT_EQ(giniSorted(one, 1), 0.0);
    EXPECT_EQ(giniSorted(nullptr, 0), 0.0);
}

TEST(Gini, NegativeValuesAreShiftedToZero) {
    // {-1,0,1} -> {0,1,2}: 2*(2+6)/(3*3) - 4/3 = 4/9
    const double v[] = {-1, 0, 1};
    EXPECT_NEAR(giniSorted(v, 3), 4.0 / 9.0, 1e-15);
    const double neg[] = {-3, -3, -3};
    EXPECT_EQ(giniSorted(neg, 3), 0.0);
}

TEST(Gini, ExtremeMagnitudes) {
    const double huge[] = {3e38, 3e38, 3.4e38};
    const double g = giniSorted(huge, 3);
    EXPECT_TRUE(std::isfinite(g));
    EXPECT_NEAR(g, (2.0 * 3.4e38 - 0 * 3e38 - 2 * 3e38) / (3.0 * 9.4e38), 1e-12);
    const double denorm[] = {0, 0, 1e-45};
    EXPECT_NEAR(giniSorted(denorm, 3), 2.0 / 3.0, 1e-12);
}

// ---- c of G-MoN, section 4.3 -------------------------------------------------------------------

TEST(GMoNTrim, FollowsFloorKMinusOneMinusGk) {
    EXPECT_EQ(gmonTrim(0.0, 21), 0);
    EXPECT_EQ(gmonTrim(0.25, 21), 2);  // floor(10 - 7.5)
    EXPECT_EQ(gmonTrim(0.5, 21), 5);
    EXPECT_EQ(gmonTrim(0.99, 21), 9);
    EXPECT_EQ(gmonTrim(1.0, 21), 10);  // only the median left
    EXPECT_EQ(gmonTrim(0.72727, 5), 1);
    EXPECT_EQ(gmonTrim(1.0, 1), 0);
}

TEST(GMoNTrim, EvenMKeepsTheTwoMiddleMeans) {
    EXPECT_EQ(gmonTrim(1.0, 4), 1);  // paper's c = k = 2 would divide by M - 2c = 0
    EXPECT_EQ(gmonTrim(1.0, 2), 0);
    EXPECT_EQ(gmonTrim(0.5, 4), 1);
}

// ---- estimators, per channel -----------------------------------------------------------------

TEST(Estimators, HandComputedPerChannel) {
    // R = {1,2,3,4,100}, G = 1 everywhere, B = 0 everywhere, equal counts.
    Pixel px({{1, 1, 0}, {2, 1, 0}, {3, 1, 0}, {4, 1, 0}, {100, 1, 0}}, {2, 2, 2, 2, 2});
    PixelEstimate mean = run("mean", px);
    EXPECT_FLOAT_EQ(mean.rgb[0], 22.f);
    EXPECT_FLOAT_EQ(mean.rgb[1], 1.f);
    EXPECT_FLOAT_EQ(mean.rgb[2], 0.f);

    PixelEstimate mon = run("mon", px);
    EXPECT_FLOAT_EQ(mon.rgb[0], 3.f);
    EXPECT_FLOAT_EQ(mon.rgb[1], 1.f);
    EXPECT_FLOAT_EQ(mon.rgb[2], 0.f);  // all-zero channel: 0, never NaN
    EXPECT_EQ(mon.kept[0], 1);

    // G_R = 400/550; c = floor(2 - (1 - G) 2) = 1: mean of ranks 2..4 = (2+3+4)/3
    PixelEstimate g = run("gmon", px);
    EXPECT_FLOAT_EQ(g.rgb[0], 3.f);
    EXPECT_NEAR(g.gini[0], 400.0 / 550.0, 1e-6);
    EXPECT_EQ(g.kept[0], 3);
    EXPECT_FLOAT_EQ(g.rgb[1], 1.f);  // all equal: G = 0, c = 0, the mean
    EXPECT_EQ(g.kept[1], 5);
    EXPECT_FLOAT_EQ(g.gini[1], 0.f);
    EXPECT_FLOAT_EQ(g.rgb[2], 0.f);

    PixelEstimate gb = run("gmonb", px);
    EXPECT_FLOAT_EQ(gb.rgb[0], 3.f);  // G > 0.25: MoN
    EXPECT_FLOAT_EQ(gb.rgb[1], 1.f);  // G = 0: mean
    PixelEstimate gbHigh = run("gmonb", px, EstimatorMode::PerChannel, 0.8);
    EXPECT_FLOAT_EQ(gbHigh.rgb[0], 22.f);  // G <= 0.8: mean
}

TEST(Estimators, GMoNMatchesEquation6Literally) {
    // Eq. 6 with the paper's c, computed here independently on a 9-buffer pixel.
    std::vector<float> v = {0.5f, 0.1f, 0.9f, 0.3f, 7.f, 0.2f, 0.4f, 0.6f, 0.35f};
    std::vector<double> sorted(v.begin(), v.end());
    std::sort(sorted.begin(), sorted.end());
    double sum = 0, sj = 0;
    for (size_t j = 0; j < sorted.size(); ++j) {
        sum += sorted[j];
        sj += double(j + 1) * sorted[j];
    }
    const double M = 9, G = 2 * sj / (M * sum) - (M + 1) / M;  // eq. 4 as printed
    const int k = 4, c = int(std::floor(k - (1 - G) * k));
    double expected = 0;
    for (int j = c; j < 9 - c; ++j) expected += sorted[j];
    expected /= (9 - 2 * c);
    PixelEstimate e = run("gmon", grey(v));
    EXPECT_NEAR(e.gini[0], G, 1e-6);
    EXPECT_EQ(e.kept[0], 9 - 2 * c);
    EXPECT_NEAR(e.rgb[0], expected, 1e-6);
}

TEST(Estimators, MoNEvenMAveragesTheTwoMiddleMeans) {
    PixelEstimate e = run("mon", grey({0, 10, 20, 1000}));
    EXPECT_FLOAT_EQ(e.rgb[0], 15.f);
    EXPECT_EQ(e.kept[0], 2);
}

TEST(Estimators, CountsAreWeights) {
    // counts {1,1,1,3}: the mean of all 6 samples, and the count-weighted middle pair
    Pixel px = grey({0, 10, 20, 1000}, {1, 1, 1, 3});
    EXPECT_FLOAT_EQ(run("mean", px).rgb[0], 3030.f / 6.f);
    EXPECT_FLOAT_EQ(run("mon", px).rgb[0], 15.f);
    Pixel two = grey({0, 4}, {1, 3});
    EXPECT_FLOAT_EQ(run("mon", two).rgb[0], 3.f);  // (1*0 + 3*4) / 4
}

TEST(Estimators, GMoNWithNoTrimIsExactlyTheMean) {
    Pixel px = grey({1.f, 1.0001f, 0.9999f, 1.f, 1.00005f}, {3, 3, 2, 2, 2});
    PixelEstimate g = run("gmon", px);
    PixelEstimate m = run("mean", px);
    EXPECT_EQ(g.kept[0], 5);
    EXPECT_EQ(g.rgb[0], m.rgb[0]);
}

// ---- edges --------------------------------------------------------------------------------------

TEST(Estimators, AllEqualAndAllZeroReturnTheMean) {
    for (const char* fn : {"mean", "mon", "gmon", "gmonb"}) {
        for (auto mode : {EstimatorMode::PerChannel, EstimatorMode::Luminance}) {
            PixelEstimate e = run(fn, grey({0.7f, 0.7f, 0.7f, 0.7f}), mode);
            EXPECT_FLOAT_EQ(e.rgb[1], 0.7f);
            PixelEstimate z = run(fn, grey({0, 0, 0}), mode);
            EXPECT_EQ(z.rgb[0], 0.f);
            EXPECT_FALSE(std::isnan(z.rgb[0]));
        }
    }
}

TEST(Estimators, EmptyBuffersAreLeftOut) {
    // spp = 2 < M = 4: two buffers hold a sample, two are empty (mean 0, count 0)
    Pixel px = grey({1, 3, 0, 0}, {1, 1, 0, 0});
    for (const char* fn : {"mean", "mon", "gmon", "gmonb"}) {
        PixelEstimate e = run(fn, px);
        EXPECT_FLOAT_EQ(e.rgb[0], 2.f);
        EXPECT_EQ(e.kept[0], 2);
        EXPECT_EQ(e.excluded, 0);
    }
    // no sample at all: black, nothing kept
    PixelEstimate none = run("gmon", grey({0, 0, 0}, {0, 0, 0}));
    EXPECT_EQ(none.rgb[0], 0.f);
    EXPECT_EQ(none.kept[0], 0);
}

TEST(Estimators, NonFiniteBuffersAreExcludedAndCounted) {
    Pixel px({{1, 1, 1}, {kNaN, 1, 1}, {3, 3, 3}, {2, kInf, 2}, {-kInf, 0, 0}}, {1, 1, 1, 1, 1});
    for (const char* fn : {"mean", "mon", "gmon", "gmonb"}) {
        for (auto mode : {EstimatorMode::PerChannel, EstimatorMode::Luminance}) {
            PixelEstimate e = run(fn, px, mode);
            EXPECT_EQ(e.excluded, 3);
            EXPECT_TRUE(std::isfinite(e.rgb[0]) && std::isfinite(e.rgb[1]));
            EXPECT_FLOAT_EQ(e.rgb[0], 2.f);  // from {1, 3} only
        }
    }
    Pixel bad = grey({kNaN, kInf}, {1, 1});
    PixelEstimate e = run("gmon", bad);
    EXPECT_EQ(e.excluded, 2);
    EXPECT_EQ(e.rgb[0], 0.f);
    // a corrupt count is excluded too
    Pixel badCount = grey({1, 5}, {kNaN, 1});
    EXPECT_FLOAT_EQ(run("mean", badCount).rgb[0], 5.f);
    EXPECT_EQ(run("mean", badCount).excluded, 1);
}

TEST(Estimators, MEqualsOneGivesTheMean) {
    Pixel px({{0.25f, 5.f, 1e30f}}, {7});
    for (const char* fn : {"mon", "gmon", "gmonb"}) {
        PixelEstimate e = run(fn, px);
        EXPECT_EQ(e.rgb[0], 0.25f);
        EXPECT_EQ(e.rgb[2], 1e30f);
        EXPECT_EQ(e.gini[0], 0.f);
    }
}

TEST(Estimators, NegativeMeansFollowTheDocumentedRule) {
    // ranks use signed values; by default G is computed on the magnitudes {0,1,1,2,10}:
    // sum (2j-6)x / (5*14) = (-2 + 0 + 4 + 40) / 70 = 42/70
    Pixel px = grey({-2, -1, 0, 1, 10});
    PixelEstimate g = run("gmon", px);
    EXPECT_NEAR(g.gini[0], 42.0 / 70.0, 1e-6);
    // c = floor(2 - (1 - 0.6) 2) = 1: mean of {-1, 0, 1}
    EXPECT_FLOAT_EQ(g.rgb[0], 0.f);
    // gini=shift: G on the shifted set {0,1,2,3,12}: sum (2j-6)x / (5*18) = 52/90, c = 1 too
    g = runKernel("gmon", px, EstimatorMode::PerChannel, {{"gini", "shift"}});
    EXPECT_NEAR(g.gini[0], 52.0 / 90.0, 1e-6);
    EXPECT_FLOAT_EQ(g.rgb[0], 0.f);
    EXPECT_FLOAT_EQ(run("mon", px).rgb[0], 0.f);
    EXPECT_FLOAT_EQ(run("mean", px).rgb[0], 1.6f);
}

TEST(Estimators, ExtremeValuesStayFinite) {
    Pixel huge = grey({3e38f, 3.4e38f, 3.4e38f});
    EXPECT_FLOAT_EQ(run("mean", huge).rgb[0], float((3e38 + 6.8e38) / 3));
    EXPECT_TRUE(std::isfinite(run("gmon", huge).rgb[0]));
    Pixel denorm = grey({1e-40f, 1e-40f, 1e-40f});
    EXPECT_EQ(run("gmon", denorm).rgb[0], 1e-40f);
    Pixel mixed = grey({0, 0, 1e-45f});
    EXPECT_TRUE(std::isfinite(run("gmon", mixed).rgb[0]));
    // a million samples in one buffer against singles: counts weight without overflow
    Pixel many = grey({1.f, 2.f}, {1e6f, 1.f});
    EXPECT_NEAR(run("mean", many).rgb[0], (1e6 + 2) / (1e6 + 1), 1e-7);
}

// ---- luminance mode --------------------------------------------------------------------------

TEST(Estimators, LuminanceModeReturnsAChosenBuffersColor) {
    // luminances .2126 (red), .7152 (green), .0722 (blue): the median is the red buffer
    Pixel px({{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {1, 1, 1});
    PixelEstimate lum = run("mon", px, EstimatorMode::Luminance);
    EXPECT_EQ(lum.rgb[0], 1.f);
    EXPECT_EQ(lum.rgb[1], 0.f);
    EXPECT_EQ(lum.rgb[2], 0.f);
    EXPECT_EQ(lum.kept[0], 1);
    // per channel, each channel's median is 0: a colour no buffer had
    PixelEstimate ch = run("mon", px, EstimatorMode::PerChannel);
    EXPECT_EQ(ch.rgb[0], 0.f);
    EXPECT_EQ(ch.rgb[1], 0.f);
}

TEST(Estimators, LuminanceGiniIsOnLuminance) {
    // a bright white firefly among dim greys; G on luminances {1,1,1,1,1,1,100}
    std::vector<float> v = {1, 1, 1, 1, 100, 1, 1};
    PixelEstimate e = run("gmon", grey(v), EstimatorMode::Luminance);
    const double lumSum = 106.0 * (kLuma[0] + kLuma[1] + kLuma[2]);
    const double weighted = 6.0 * 99.0 * (kLuma[0] + kLuma[1] + kLuma[2]);  // (2*7-8) * (100 - 1)
    EXPECT_NEAR(e.gini[0], weighted / (7 * lumSum), 1e-6);
    EXPECT_EQ(e.gini[0], e.gini[2]);
    // G = 594/742: c = floor(3 - (1 - G) 3) = 2, the firefly is trimmed
    EXPECT_EQ(e.kept[0], 3);
    EXPECT_FLOAT_EQ(e.rgb[0], 1.f);
}

TEST(Estimators, TiesAreBrokenByBufferIndex) {
    // equal luminance, different colours: the lower buffer index ranks first, deterministically
    const double w = kLuma[0] / kLuma[1];
    Pixel px({{1, 0, 0}, {0, float(w), 0}, {1, 0, 0}}, {1, 1, 1});
    PixelEstimate a = run("mon", px, EstimatorMode::Luminance);
    PixelEstimate b = run("mon", px, EstimatorMode::Luminance);
    EXPECT_EQ(a.rgb, b.rgb);
}
