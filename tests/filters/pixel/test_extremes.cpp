// Issue 38: robust at both ends and at every scale. Every per-pixel estimator of the registry
// against one or two outlying buffers of magnitude 1e1 .. 1e38, of either sign, among inliers at
// 0, 1e-3, 1 and 1e3 (all equal, or spread), at M = 3, 7 and 21: the output's distance from the
// inliers' median, in units of the inliers' spread, must be what the estimator promises
// (docs/estimators.md, "What each estimator promises at the extremes"). Then the issue's "done
// when" pixels, and the papers' forms one modifier away (scale=rel, gini=shift).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "mcstat/filters/pixel/gmon.h"
#include "mcstat/filters/pixel/ranking.h"
#include "mcstat/filters/pixel/tmpe.h"
#include "mcstat/filters/registry.h"
#include "pixel_support.h"

using namespace mcstat;
using namespace mcstat::testing;

namespace {

/// One case of the matrix: M buffers, `outliers` of them (1 or 2) at x and x / 2, the others
/// inliers around `level`.
struct Case {
    int M = 7;
    int outliers = 1;
    double level = 1.0;
    bool spread = true;  ///< inliers spread evenly over level +- 1 % (else all equal to level)
    double x = 1e30;     ///< the outlier (signed)

    std::vector<float> inliers() const {
        const int n = M - outliers;
        // Half-width 1 % of the level's magnitude (1e-5 at level 0): evenly spaced, a few ulps
        // at least apart in float at every level here.
        const double h = spread ? 0.01 * std::max(std::fabs(level), 1e-3) : 0.0;
        std::vector<float> v;
        for (int i = 0; i < n; ++i)
            v.push_back(float(level + h * (n == 1 ? 0.0 : -1.0 + 2.0 * i / (n - 1))));
        return v;
    }
    std::vector<float> buffers() const {
        std::vector<float> v = inliers();
        // The outliers in the middle of the buffer order (estimators must not depend on it).
        v.insert(v.begin() + long(v.size() / 2), float(x));
        if (outliers == 2) v.insert(v.begin() + 1, float(x / 2));
        return v;
    }
    std::string name() const {
        char b[160];
        std::snprintf(b, sizeof b, "M=%d outliers=%d level=%g %s x=%g", M, outliers, level,
                      spread ? "spread" : "equal", x);
        return b;
    }
};

double median(std::vector<float> v) {
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return n % 2 ? double(v[n / 2]) : 0.5 * (double(v[n / 2 - 1]) + double(v[n / 2]));
}

/// What an estimator promises for one case, given the output `out`: a bound on
/// |out - median(inliers)| / unit, or (mean) the value itself.
struct Verdict {
    bool ok = true;
    std::string why;
};

/// The inliers' spread unit: half their range, or (all equal) 1e-6 of their magnitude (1e-30 at
/// zero), far below any distance an outlier could cause and far above float rounding of an
/// average of equal values (which is exact).
double unitOf(const Case& c) {
    const std::vector<float> in = c.inliers();
    const auto [lo, hi] = std::minmax_element(in.begin(), in.end());
    const double half = 0.5 * (double(*hi) - double(*lo));
    return half > 0.0 ? half : std::max(1e-6 * std::fabs(c.level), 1e-30);
}

double meanOf(const std::vector<float>& v) {
    double s = 0.0;
    for (float x : v) s += double(x);
    return s / double(v.size());
}

/// Whether the outliers lie beyond 9 x the inliers' range from their median, and so beyond
/// Hampel's fence 3 x 1.4826 x MAD whatever the MAD (k < M/2 outliers on one side leave the MAD
/// within the inliers' range), or all equal inliers with a MAD of 0.
bool beyondFence(const Case& c) {
    const std::vector<float> in = c.inliers();
    const auto [lo, hi] = std::minmax_element(in.begin(), in.end());
    const double range = double(*hi) - double(*lo);
    const double med = median(in);
    const double nearest = std::min(std::fabs(c.x - med), std::fabs(c.x / 2 - med));
    return nearest > 9.0 * range;
}

/// Whether the outliers' magnitudes are at least 100 x the inliers' largest (and not 0): G-MoN's
/// Gini of magnitudes is then about (M - k) / M, far above 1 / floor(M/2).
bool largeMagnitude(const Case& c) {
    const std::vector<float> in = c.inliers();
    const auto [lo, hi] = std::minmax_element(in.begin(), in.end());
    const double largest = std::max(std::fabs(double(*lo)), std::fabs(double(*hi)));
    const double smallest = c.outliers == 2 ? std::fabs(c.x / 2) : std::fabs(c.x);
    return smallest >= 100.0 * largest && smallest > 0.0;
}

bool far(const Case& c) { return beyondFence(c) && largeMagnitude(c); }

/// The promise of registry estimator `name` (default parameters) on case `c` (docs/estimators.md).
Verdict promise(const std::string& name, const Case& c, double out) {
    const std::vector<float> all = c.buffers(), in = c.inliers();
    const double med = median(in), unit = unitOf(c);
    const double d = std::fabs(out - med) / unit;
    const double meanD = std::fabs(meanOf(all) - med) / unit;
    const int M = c.M, k = c.outliers;
    // Within the inliers' range: |out - med| <= their range = 2 units (plus float rounding of the
    // output: 1e-6 relative to the value, in units).
    const double slack = 1e-6 * std::max(std::fabs(med), unit) / unit;
    const bool within = d <= 2.0 + slack;
    // No farther than the mean (trimmed means: trimming c per side keeps (k - c) / (M - 2c) <=
    // k / M outliers in the average), up to the inliers' own spread.
    const bool noWorseThanMean = d <= meanD * (1.0 + 1e-6) + 2.0 + slack;
    Verdict v;
    auto need = [&v, d](bool cond, const char* what) {
        if (!cond) {
            v.ok = false;
            v.why = std::string(what) + " (distance " + std::to_string(d) + " units)";
        }
    };
    // Every estimator here averages or selects buffers: never outside [min, max] of them.
    const auto [lo, hi] = std::minmax_element(all.begin(), all.end());
    need(out >= double(*lo) - 1e-6 * std::fabs(double(*lo)) &&
             out <= double(*hi) + 1e-6 * std::fabs(double(*hi)),
         "outside the buffers' hull");
    if (!v.ok) return v;
    if (name == "mean") {
        // Breakdown point 0: the mean itself, dragged by any outlier.
        need(std::fabs(out - meanOf(all)) <= 1e-6 * std::max(std::fabs(meanOf(all)), 1e-30),
             "not the mean");
    } else if (name == "mon" || name == "median") {
        // Breakdown floor((M - 1) / 2) / M: fewer than half of the buffers never move it out of
        // the inliers' range, at any magnitude.
        need(within, "median left the inliers' range");
    } else if (name == "tmpe") {
        // floor(0.25 M) trimmed per side: breakdown floor(0.25 M) / M (0 at M = 3: the mean).
        const int trim = tmpeTrim(0.25, M);
        if (k <= trim)
            need(within, "TMPE kept an outlier it trims");
        else
            need(noWorseThanMean, "TMPE farther than the mean");
    } else if (name == "gmon") {
        // G-MoN (Gini of magnitudes): from M = 4, outliers far above the inliers' magnitude (either
        // sign) give G ~ (M - k) / M and c = floor(G floor(M/2)) >= k: trimmed. Otherwise (M = 3,
        // or outliers not far) a trimmed mean: no farther than the mean.
        if (M >= 4 && far(c))
            need(within, "G-MoN kept a far outlier");
        else
            need(noWorseThanMean, "G-MoN farther than the mean");
    } else if (name == "gmonb") {
        // G-MoN_b: far outliers give G > 0.25 at every M >= 3: the median of means.
        if (far(c))
            need(within, "G-MoN_b kept a far outlier");
        else
            need(noWorseThanMean, "G-MoN_b farther than the mean");
    } else if (name == "myriad" || name == "meridian") {
        // Scale from the range within Hampel's fence: fewer than half of the buffers, beyond the
        // fence, neither set the scale nor move the estimate out of the inliers' range.
        if (2 * k < M && beyondFence(c))
            need(within, "M-estimator dragged by an outlier beyond the fence");
    } else {
        v.ok = false;
        v.why = "no promise stated for this estimator (docs/estimators.md, then here)";
    }
    return v;
}

}  // namespace

// The matrix: 8 estimators x 2 modes x (3 + 1) outlier layouts x 4 levels x 2 inlier kinds x 14
// outliers. Every registry estimator is in it: a new one fails until its promise is written.
TEST(Extremes, EveryEstimatorKeepsItsPromise) {
    const std::vector<double> magnitudes = {1e1, 1e2, 1e4, 1e8, 1e16, 1e30, 1e38};
    int checked = 0, within = 0;
    for (const Operation& est : estimatorRegistry()) {
        for (EstimatorMode mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
            const PixelKernel kernel = kernelOf(est.name, mode);
            EstimatorScratch s;
            for (const auto& [M, k] :
                 std::vector<std::pair<int, int>>{{3, 1}, {7, 1}, {21, 1}, {21, 2}})
                for (double level : {0.0, 1e-3, 1.0, 1e3})
                    for (bool spread : {false, true})
                        for (double mag : magnitudes)
                            for (double sign : {1.0, -1.0}) {
                                Case c;
                                c.M = M;
                                c.outliers = k;
                                c.level = level;
                                c.spread = spread;
                                c.x = sign * mag;
                                const Pixel px = grey(c.buffers());
                                PixelEstimate e;
                                kernel.estimate(px.view(), e, s);
                                for (int ch = 0; ch < 3; ++ch) {
                                    const Verdict v = promise(est.name, c, double(e.rgb[ch]));
                                    ASSERT_TRUE(v.ok)
                                        << est.name
                                        << (mode == EstimatorMode::Luminance ? " lum " : " ch ")
                                        << c.name() << ": " << v.why << ", output " << e.rgb[ch];
                                }
                                ++checked;
                                within += est.name != "mean" &&
                                          std::fabs(double(e.rgb[0]) - median(c.inliers())) <=
                                              2.0 * unitOf(c);
                            }
        }
    }
    EXPECT_EQ(checked, int(estimatorRegistry().size()) * 2 * 4 * 4 * 2 * 14);
    // The promises are not vacuous: most robust outputs stay within the inliers' range.
    EXPECT_GT(within, checked / 2);
}

// The mean is dragged by every one of those outliers, which is why the matrix means something:
// at M = 7, one buffer of 1e8 among inliers at 1 moves it by about 1.4e7.
TEST(Extremes, TheMeanIsDragged) {
    const Pixel px = grey({1, 1, 1, 1e8f, 1, 1, 1});
    EXPECT_NEAR(runKernel("mean", px).rgb[0], (6.0 + 1e8) / 7.0, 1.0);
}

// ---- the "done when" ----------------------------------------------------------------

namespace {

const std::vector<float> kAbout025 = {0.25f, 0.26f, 0.24f, 0.255f, 0.245f, 0.25f, 0.252f};

std::vector<float> with(float x) {
    std::vector<float> v = kAbout025;
    v.insert(v.begin() + 3, x);
    return v;
}

}  // namespace

TEST(Extremes, OneHugeBufferMovesNoEstimatorButTheMean) {
    for (float x : {1e30f, 3e38f})
        for (const Operation& est : estimatorRegistry())
            for (EstimatorMode mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
                const PixelEstimate e = runKernel(est.name, grey(with(x)), mode);
                for (int ch = 0; ch < 3; ++ch) {
                    if (est.name == "mean") {
                        EXPECT_GT(e.rgb[ch], x / 10) << x;  // the mean: x / 8
                        continue;
                    }
                    EXPECT_NEAR(e.rgb[ch], 0.25, 0.025) << est.name << " x=" << x;
                }
            }
}

TEST(Extremes, OneNegativeBufferMovesNeitherMoNNorGMoN) {
    for (const char* name : {"mon", "gmon", "gmonb"})
        for (EstimatorMode mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
            const PixelEstimate e = runKernel(name, grey(with(-5.f)), mode);
            EXPECT_NEAR(e.rgb[0], 0.25, 0.025) << name;
        }
    // G of the magnitudes {0.24, 0.245, 0.25, 0.25, 0.252, 0.255, 0.26, 5} (eq. 4): sum (2j - 9)
    // x_j / (8 sum x_j) = 33.412 / 54.016 = 0.61856, so G-MoN trims floor(0.619 x 4) = 2 per side
    // (4 kept) and G-MoN_b (0.618 > 0.25) is the median of means.
    const PixelEstimate g = runKernel("gmon", grey(with(-5.f)));
    EXPECT_EQ(g.kept[0], 4);
    EXPECT_NEAR(g.gini[0], 0.61856, 1e-4);
    // The mean is dragged: (sum of the seven + -5) / 8.
    EXPECT_NEAR(runKernel("mean", grey(with(-5.f))).rgb[0], (1.752 - 5.0) / 8.0, 1e-6);
}

// ---- the papers' forms, one modifier away -----------------------------------------------------

// Jung 2016 section 4.2's gamma = 0.05 x range is what the issue saw: one buffer X sets gamma and
// the myriad lands about 4e-4 X away at M = 8 (3e38 among 0.25s gave 1.25e35).
TEST(Extremes, TheThesisScaleIsOneModifierAway) {
    const PixelEstimate rel =
        runKernel("myriad", grey(with(3e38f)), EstimatorMode::Luminance, {{"scale", "rel"}});
    EXPECT_GT(rel.rgb[0], 1e-4 * 3e38);
    EXPECT_LT(rel.rgb[0], 1e-3 * 3e38);
    const PixelEstimate hampel =
        runKernel("myriad", grey(with(3e38f)), EstimatorMode::Luminance, {{"scale", "hampel"}});
    EXPECT_NEAR(hampel.rgb[0], 0.25, 0.01);
    // The meridian's delta = 0.05 x range is huge there too, but a large delta makes it the
    // median: it was never dragged, and its default changes it only where the range scale did.
    EXPECT_NEAR(
        runKernel("meridian", grey(with(3e38f)), EstimatorMode::Luminance, {{"scale", "rel"}})
            .rgb[0],
        0.25, 0.025);
}

// The default scale, hand-computed: {1, 2, 3, 4, 100} has median 3, absolute deviations
// {2, 1, 0, 1, 97}, MAD 1, fence 3 x 1.4826 = 4.4478: 100 is outside, so gamma = 0.05 x (4 - 1)
// = 0.15 (the thesis' would be 0.05 x 99 = 4.95).
TEST(Extremes, HampelScaleIsTheRangeWithinTheFence) {
    const Pixel px = grey({1, 2, 3, 4, 100});
    for (const char* name : {"myriad", "meridian"}) {
        const char* key = std::string(name) == "myriad" ? "gamma" : "delta";
        const float byDefault = runKernel(name, px).rgb[0];
        EXPECT_NEAR(
            byDefault,
            runKernel(name, px, EstimatorMode::PerChannel, {{key, "0.15"}, {"scale", "abs"}})
                .rgb[0],
            1e-5)
            << name;
        EXPECT_NEAR(
            runKernel(name, px, EstimatorMode::PerChannel, {{"scale", "rel"}}).rgb[0],
            runKernel(name, px, EstimatorMode::PerChannel, {{key, "4.95"}, {"scale", "abs"}})
                .rgb[0],
            1e-5)
            << name;
    }
    // MAD 0 (more than half of the buffers equal): the scale is 0, the selection limit: the value
    // those buffers share, exactly.
    EXPECT_EQ(runKernel("myriad", grey({0.5f, 0.5f, 0.5f, 0.7f, 9.f})).rgb[0], 0.5f);
    EXPECT_EQ(runKernel("meridian", grey({0.5f, 0.5f, 0.5f, 0.7f, 9.f})).rgb[0], 0.5f);
    // No outlier: the fence holds every buffer and the default is the thesis' scale, bit for bit.
    const Pixel clean = grey({0.21f, 0.25f, 0.24f, 0.3f, 0.27f, 0.26f, 0.22f});
    for (const char* name : {"myriad", "meridian"})
        for (EstimatorMode mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel})
            EXPECT_EQ(runKernel(name, clean, mode).rgb,
                      runKernel(name, clean, mode, {{"scale", "rel"}}).rgb)
                << name;
}

// Buisine et al. 2021 eq. 4 is defined for non-negative values: there both Gini inputs are it, bit
// for bit; below zero, gini=shift is the form before issue 38, blind to a negative outlier.
TEST(Extremes, GiniOfMagnitudes) {
    // {-5, 0.25 x 7}: magnitudes {0.25 x 7, 5}: sum (2j - 9) x_j = 0.25 (-7 - 5 - 3 - 1 + 1 + 3 +
    // 5)
    // + 7 x 5 = -1.75 + 35, over 8 x (1.75 + 5): 33.25 / 54.
    const std::vector<double> v = {-5, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25};
    EXPECT_NEAR(giniMagnitudes(v.data(), v.size()), 33.25 / 54.0, 1e-15);
    // Shifted by 5: {0, 5.25 x 7}: 7 x 5.25 x 1 / (8 x 36.75) = 1/8.
    EXPECT_NEAR(giniSorted(v.data(), v.size()), 0.125, 1e-15);
    // Mixed signs merge by magnitude: {-3, -1, 2} -> {1, 2, 3}: (-2 + 0 + 6) / (3 x 6) = 2/9.
    const std::vector<double> m = {-3, -1, 2};
    EXPECT_NEAR(giniMagnitudes(m.data(), m.size()), 2.0 / 9.0, 1e-15);
    // Non-negative values: the same bits as giniSorted.
    const std::vector<double> p = {0.0, 0.1, 0.3, 0.3, 7.0};
    EXPECT_EQ(giniMagnitudes(p.data(), p.size()), giniSorted(p.data(), p.size()));
    // The estimators: gini=shift keeps the mean on the negative outlier, gini=abs trims it.
    const Pixel px = grey(with(-5.f));
    EXPECT_NEAR(runKernel("gmon", px, EstimatorMode::Luminance, {{"gini", "shift"}}).rgb[0],
                (1.752 - 5.0) / 8.0, 1e-6);
    EXPECT_NEAR(runKernel("gmonb", px, EstimatorMode::Luminance, {{"gini", "shift"}}).rgb[0],
                (1.752 - 5.0) / 8.0, 1e-6);
    // An all-negative smooth pixel is the mirror of a positive one: the mean (G small), where the
    // shifted form sees the spread over its minimum as dispersion.
    const Pixel neg = grey({-10.f, -10.1f, -10.2f, -9.9f, -10.05f, -9.95f, -10.f, -10.f});
    const PixelEstimate a = runKernel("gmon", neg, EstimatorMode::Luminance);
    EXPECT_EQ(a.kept[0], 8);
    const PixelEstimate sh = runKernel("gmon", neg, EstimatorMode::Luminance, {{"gini", "shift"}});
    EXPECT_LT(sh.kept[0], 8);
}
