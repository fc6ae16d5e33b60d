// Pajot et al. 2011: the per-pixel estimator against hand-worked distributions and eq. 3-5
// computed here the slow, obvious way, and every numerical edge of
// include/mcstat/filters/samples/sample_delaying_kde.h.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "mcstat/filters/samples/sample_delaying_kde.h"

namespace mcstat {
namespace {

const float kNegInf = -std::numeric_limits<float>::infinity();

/// Grey sample whose luminance is exactly y with luma (1, 0, 0) weights: l = float(log(y)).
PajotParams params(PajotMethod m, int n = 7) {
    PajotParams p;
    p.method = m;
    p.learning = n;
    p.luma = {1.0, 0.0, 0.0};  // Y = R: the hand computations use R alone
    return p;
}

void addY(PajotPixel& px, double y, const PajotParams& p) {
    const float rgb[3] = {float(y), 0.5f, 0.25f};
    ASSERT_TRUE(px.add(rgb, p));
}

float logOf(double y) {
    const float rgb[3] = {float(y), 0.f, 0.f};
    return pajotLogLuminance(rgb, {1.0, 0.0, 0.0});
}

// ---- eq. 3 and eq. 4, the slow way, over explicit values ----------------------------------------

double kernel(double u) { return std::fabs(u) < 1 ? 0.75 * (1 - u * u) : 0.0; }

double density(const std::vector<double>& v, double x, double h) {
    double s = 0;
    for (double xi : v) s += kernel((x - xi) / h) / h;
    return s / double(v.size());
}

double meanNearest(const std::vector<double>& v) {  // v sorted
    double s = 0;
    for (size_t i = 0; i < v.size(); ++i) {
        double d = HUGE_VAL;
        if (i > 0) d = std::min(d, v[i] - v[i - 1]);
        if (i + 1 < v.size()) d = std::min(d, v[i + 1] - v[i]);
        s += d;
    }
    return s / double(v.size());
}

/// The values a mode list stands for (section 4.2: n regularly spaced values in [lo, hi]).
std::vector<double> expand(const std::vector<PajotMode>& modes) {
    std::vector<double> v;
    for (const PajotMode& m : modes)
        for (uint32_t i = 0; i < m.n; ++i)
            v.push_back(m.n == 1 ? m.lo : m.lo + (double(m.hi) - m.lo) * i / double(m.n - 1));
    return v;
}

TEST(PajotKernel, NearestNeighbourOfTheApproximateDistribution) {
    // 0 | 1, 2, 3 | 10: distances 1, 1, 1, 1, 7 -> 11 / 5.
    const std::vector<PajotMode> modes{{0, 0, 1}, {1, 3, 3}, {10, 10, 1}};
    EXPECT_DOUBLE_EQ(adrNearestNeighbour(modes), 11.0 / 5.0);
    EXPECT_DOUBLE_EQ(adrNearestNeighbour({{2, 2, 1}}), 0.0);  // one value: no neighbour
    EXPECT_DOUBLE_EQ(adrNearestNeighbour({{2, 2, 4}}), 0.0);  // four equal values
}

TEST(PajotKernel, ClosedFormDensityEqualsTheSumOverExpandedValues) {
    const std::vector<PajotMode> modes{{-1.5f, -1.5f, 1}, {0, 1, 41}, {1.25f, 4, 1000}, {9, 9, 3}};
    const std::vector<double> v = expand(modes);
    for (double h : {0.01, 0.3, 1.0, 7.0})
        for (double x : {-2.0, -1.5, 0.0, 0.013, 0.5, 1.1, 1.25, 2.0, 3.99, 9.0, 12.0})
            EXPECT_NEAR(adrDensity(modes, x, h), density(v, x, h), 1e-12 * (1 + density(v, x, h)))
                << "x=" << x << " h=" << h;
}

TEST(PajotKernel, AdaptiveBandwidthsAreEquation4) {
    const std::vector<float> l{0.f, 1.f, 2.f, 10.f};
    const std::vector<double> v(l.begin(), l.end());
    const double nn = meanNearest(v);  // (1 + 1 + 1 + 8) / 4
    ASSERT_DOUBLE_EQ(nn, 2.75);
    double logSum = 0;
    for (double x : v) logSum += std::log(density(v, x, nn));
    const double g = std::exp(logSum / 4);
    const std::vector<double> h = adaptiveBandwidths(l);
    for (size_t i = 0; i < v.size(); ++i)
        EXPECT_NEAR(h[i], nn * std::sqrt(g / density(v, v[i], nn)), 1e-12);
    // The isolated value gets the widest kernel.
    EXPECT_GT(h[3], h[1]);
}

TEST(PajotKernel, RuleOfThumbIsEquation5) {
    EXPECT_DOUBLE_EQ(rotBandwidth(7, 2.0), std::pow(175.0, -0.2) * 2.0);
    EXPECT_DOUBLE_EQ(rotBandwidth(0, 2.0), 0.0);
}

TEST(PajotKernel, AggregationJoinsOverlappingAndEqualNeighbours) {
    const std::vector<float> l{0, 0.5f, 3, 3, 7};
    const std::vector<PajotMode> modes = aggregateModes(l, {0.3, 0.3, 0.0, 0.0, 1.0});
    ASSERT_EQ(modes.size(), 3u);  // {0, 0.5} overlap (0.5 < 0.6), {3, 3} equal, {7} alone
    EXPECT_EQ(modes[0].n, 2u);
    EXPECT_EQ(modes[1].n, 2u);
    EXPECT_EQ(modes[1].lo, 3.f);
    EXPECT_EQ(modes[2].n, 1u);
    EXPECT_EQ(lastExtendedUpperBound(modes), 3.f);
    EXPECT_EQ(lastExtendedUpperBound({{1, 1, 1}}), kNegInf);
}

// ---- two clusters and an outlier, worked by hand
// ------------------------------------------------- l = 0, 0.1, 0.2 | 2, 2.1, 2.2 | 10.  ADR: nn =
// (6 * 0.1 + 7.8) / 7 = 1.2; the clusters' pilot densities are ~0.26, the outlier's 0.75 / 8.4 =
// 0.089, G ~ 0.225, so h ~ 1.11 in the clusters and 1.90 at the outlier: the clusters (gap 1.8
// < 2.22) form one extended mode [0, 2.2], the outlier (gap 7.8) stays single and is delayed. ROT:
// sigma = 3.51, h = 175^-0.2 sigma = 1.25: the same.

class TwoClustersAndAnOutlier : public ::testing::TestWithParam<PajotMethod> {};

TEST_P(TwoClustersAndAnOutlier, TheOutlierIsDelayedAndTheRestSplatted) {
    const PajotParams p = params(GetParam());
    PajotPixel px;
    for (double y : {1.0, 1.1051709, 1.2214028, 7.3890561, 8.1661699, 9.0250135}) addY(px, y, p);
    EXPECT_EQ(px.state().phase, PajotPhase::Learning);
    // During learning the estimate is the plain mean of the samples so far.
    EXPECT_NEAR(px.estimate()[0],
                (1.0 + 1.1051709 + 1.2214028 + 7.3890561 + 8.1661699 + 9.0250135) / 6, 1e-5);
    addY(px, 22026.466, p);  // the 7th sample ends the learning
    ASSERT_NE(px.state().phase, PajotPhase::Learning);
    EXPECT_FLOAT_EQ(px.acceptance(), logOf(9.0250135));
    ASSERT_EQ(px.state().delayed.size(), 1u);
    EXPECT_FLOAT_EQ(px.state().delayed[0].rgb[0], float(22026.466));
    EXPECT_EQ(px.state().splatted, 6);
    const double mean6 = (1.0 + 1.1051709 + 1.2214028 + 7.3890561 + 8.1661699 + 9.0250135) / 6;
    EXPECT_NEAR(px.estimate()[0], mean6, 1e-5);
    EXPECT_FLOAT_EQ(px.estimate()[1], 0.5f);
    if (GetParam() != PajotMethod::ROT) {
        ASSERT_EQ(px.state().modes.size(), 2u);
        EXPECT_EQ(px.state().modes[0].n, 6u);
        EXPECT_EQ(px.state().modes[1].n, 1u);
    }
    if (GetParam() != PajotMethod::ADR) {
        ASSERT_EQ(px.state().rotSingles.size(), 1u);
        EXPECT_FLOAT_EQ(px.state().rotSingles[0], logOf(22026.466));
    }
    const PajotCounts c = px.counts();
    EXPECT_EQ(c.delayed, 1);
}

TEST_P(TwoClustersAndAnOutlier, AClusterGrowingIntoTheOutlierReleasesIt) {
    const PajotParams p = params(GetParam());
    PajotPixel px;
    for (double y : {1.0, 1.1051709, 1.2214028, 7.3890561, 8.1661699, 9.0250135, 22026.466})
        addY(px, y, p);
    ASSERT_EQ(px.state().delayed.size(), 1u);
    // Samples walk from the upper cluster (l = 2.2) towards the outlier (l = 10) in steps of
    // 0.4 (ROT's 2h stays above 0.4 as sigma grows); once the chain reaches it, m jumps to 10 and
    // the delayed sample is splatted.
    int added = 0;
    for (double l = 2.6; l < 9.9; l += 0.4) {
        addY(px, std::exp(l), p);
        ++added;
        if (l < 7.0) {  // the gap to 10 exceeds every bandwidth here (ROT: 2h < 2.5)
            EXPECT_EQ(px.state().delayed.size(), 1u) << "l=" << l;
        }
    }
    EXPECT_TRUE(px.state().delayed.empty());
    EXPECT_FLOAT_EQ(px.acceptance(), logOf(22026.466));
    EXPECT_EQ(px.state().splatted, 7 + added);
    if (GetParam() == PajotMethod::ADR) {
        ASSERT_EQ(px.state().modes.size(), 1u);  // one extended mode from 0 to 10
        EXPECT_EQ(px.state().modes[0].n, uint32_t(7 + added));
    }
}

INSTANTIATE_TEST_SUITE_P(Methods, TwoClustersAndAnOutlier,
                         ::testing::Values(PajotMethod::ADR, PajotMethod::ROT, PajotMethod::Hybrid),
                         [](const ::testing::TestParamInfo<PajotMethod>& param) {
                             return std::string(pajotMethodName(param.param));
                         });

TEST(PajotAdr, ANewSampleBetweenTwoModesMergesThemWhenItsKernelReachesBoth) {
    // Two extended modes of 5 values each, [0, 1] and [2, 3], and a new value at 1.5. The test
    // decides with eq. 3-4 over the expanded values whether the kernels overlap on each side, and
    // checks the merge against that.
    PajotState s;
    s.phase = PajotPhase::ADR;
    s.modes = {{0, 1, 5}, {2, 3, 5}};
    s.mAdr = 3;
    std::vector<PajotMode> with = s.modes;
    with.insert(with.begin() + 1, PajotMode{1.5f, 1.5f, 1});
    const std::vector<double> v = expand(with);
    const double nn = meanNearest(v);
    double logSum = 0;
    for (double x : v) logSum += std::log(density(v, x, nn));
    const double g = std::exp(logSum / double(v.size()));
    auto h = [&](double x) { return nn * std::sqrt(g / density(v, x, nn)); };
    const bool below = 0.5 < h(1.0) + h(1.5), above = 0.5 < h(1.5) + h(2.0);
    ASSERT_TRUE(below && above) << "the hand case must merge on both sides";

    PajotPixel px(s);
    const PajotParams p = params(PajotMethod::ADR);
    addY(px, std::exp(1.5), p);
    ASSERT_EQ(px.state().modes.size(), 1u);
    EXPECT_EQ(px.state().modes[0].lo, 0.f);
    EXPECT_EQ(px.state().modes[0].hi, 3.f);
    EXPECT_EQ(px.state().modes[0].n, 11u);

    // Far from both (l = 6.5): a new single mode, nothing merges, and it is delayed.
    addY(px, std::exp(6.5), p);
    ASSERT_EQ(px.state().modes.size(), 2u);
    EXPECT_EQ(px.state().modes[1].n, 1u);
    EXPECT_EQ(px.state().delayed.size(), 1u);
    // A value inside [lo, hi] only counts.
    addY(px, std::exp(0.7), p);
    EXPECT_EQ(px.state().modes[0].n, 12u);
}

TEST(PajotHybrid, SwitchesToRotAfterTSuccessiveEqualMaxima) {
    PajotParams p = params(PajotMethod::Hybrid);
    p.T = 2;
    p.delta = 0;
    PajotPixel px;
    for (double y : {1.0, 1.1051709, 1.2214028, 7.3890561, 8.1661699, 9.0250135, 22026.466})
        addY(px, y, p);
    EXPECT_EQ(px.state().phase, PajotPhase::ADR);  // one equal distance so far (the learning)
    EXPECT_EQ(px.state().run, 1);
    addY(px, std::exp(2.6), p);  // both m rise to 2.6: a second equal distance
    EXPECT_EQ(px.state().phase, PajotPhase::ROT);
    EXPECT_TRUE(px.state().modes.empty());  // ADR's data released
    EXPECT_FLOAT_EQ(px.acceptance(), logOf(std::exp(2.6)));

    PajotParams never = p;
    never.T = 1000;
    PajotPixel q;
    for (double y : {1.0, 1.1051709, 1.2214028, 7.3890561, 8.1661699, 9.0250135, 22026.466, 13.46})
        addY(q, y, never);
    EXPECT_EQ(q.state().phase, PajotPhase::ADR);
}

// ---- numerical edges ---------------------------------------------------------------------------

TEST(PajotEdges, NonFiniteSamplesAreRefusedAndChangeNothing) {
    const PajotParams p = params(PajotMethod::Hybrid, 3);
    PajotPixel px;
    const float nan = std::numeric_limits<float>::quiet_NaN(),
                inf = std::numeric_limits<float>::infinity();
    const float bad[][3] = {{nan, 1, 1}, {1, inf, 1}, {1, 1, -inf}};
    for (const auto& s : bad) EXPECT_FALSE(px.add(s, p));
    EXPECT_EQ(px.state().taken, 0);
    EXPECT_EQ(px.estimate()[0], 0.f);
}

TEST(PajotEdges, BlackAndNegativeSamplesAreAlwaysSplatted) {
    PajotParams p = params(PajotMethod::ADR, 4);
    p.luma = {0.2126, 0.7152, 0.0722};
    PajotPixel px;
    const float samples[][3] = {{0, 0, 0}, {-1, -1, -1}, {-5, 1, 1}, {0, 0, 0}, {0, 0, 0}};
    for (const auto& s : samples) ASSERT_TRUE(px.add(s, p));
    EXPECT_EQ(px.state().splatted, 5);
    EXPECT_TRUE(px.state().modes.empty());  // no log-luminance, no distribution
    EXPECT_FLOAT_EQ(px.estimate()[0], -6.f / 5.f);
    // A negative component with a positive luminance has a log-luminance like any other sample.
    const float mixed[3] = {-0.1f, 1.f, 1.f};
    EXPECT_NEAR(pajotLogLuminance(mixed, p.luma), std::log(-0.02126 + 0.7152 + 0.0722), 1e-6);
}

TEST(PajotEdges, AllEqualLuminancesFormOneExtendedMode) {
    for (PajotMethod m : {PajotMethod::ADR, PajotMethod::ROT, PajotMethod::Hybrid}) {
        const PajotParams p = params(m, 50);
        PajotPixel px;
        for (int i = 0; i < 200; ++i) addY(px, 3.0, p);  // sigma = 0, nn = 0
        EXPECT_EQ(px.state().splatted, 200) << pajotMethodName(m);
        EXPECT_FLOAT_EQ(px.estimate()[0], 3.f);
        EXPECT_FLOAT_EQ(px.acceptance(), logOf(3.0));
        addY(px, 4.0, p);  // zero bandwidths: a different value cannot join: delayed
        EXPECT_EQ(px.state().delayed.size(), 1u) << pajotMethodName(m);
    }
}

TEST(PajotEdges, ASingleSample) {
    // Learning of 50 never ends: the estimate is the sample (nothing classified).
    PajotPixel a;
    addY(a, 5.0, params(PajotMethod::Hybrid, 50));
    EXPECT_FLOAT_EQ(a.estimate()[0], 5.f);
    // Learning of 1: one value is one single mode, no extended mode, m = -inf: delayed; the
    // estimate is black until a second sample joins it.
    const PajotParams p1 = params(PajotMethod::ADR, 1);
    PajotPixel b;
    addY(b, 5.0, p1);
    EXPECT_EQ(b.acceptance(), kNegInf);
    EXPECT_EQ(b.state().delayed.size(), 1u);
    EXPECT_EQ(b.estimate()[0], 0.f);
    addY(b, 5.0, p1);  // an equal value: one extended mode, both splatted
    EXPECT_TRUE(b.state().delayed.empty());
    EXPECT_FLOAT_EQ(b.estimate()[0], 5.f);
}

TEST(PajotEdges, ExtremeMagnitudesStayFinite) {
    const PajotParams p = params(PajotMethod::Hybrid, 4);
    PajotPixel px;
    for (double y : {1e38, 2e38, 1e-40 /* denormal in float */, 3e-45, 1.0}) addY(px, y, p);
    for (float v : px.estimate()) EXPECT_TRUE(std::isfinite(v));
    EXPECT_TRUE(std::isfinite(logOf(1e-40)));
    EXPECT_NEAR(logOf(1e38), std::log(1e38), 1e-4);
}

TEST(PajotEdges, AFullDubiousListDiscardsTheBrightest) {
    // ROT over 1000 equal body samples: sigma stays below 1, 2h < 0.3, so outliers at l = 10, 20,
    // 15 and 12 never join anything and all want the dubious list, which holds 2.
    PajotParams p = params(PajotMethod::ROT, 4);
    p.maxDelayed = 2;
    PajotPixel px;
    for (int i = 0; i < 1000; ++i) addY(px, 1.0, p);
    for (double l : {10.0, 20.0, 15.0, 12.0}) addY(px, std::exp(l), p);
    ASSERT_EQ(px.state().delayed.size(), 2u);
    EXPECT_EQ(px.state().discarded, 2);  // 20 when 15 came, 15 when 12 came
    std::vector<float> kept{px.state().delayed[0].l, px.state().delayed[1].l};
    std::sort(kept.begin(), kept.end());
    EXPECT_EQ(kept, (std::vector<float>{logOf(std::exp(10.0)), logOf(std::exp(12.0))}));
    EXPECT_EQ(px.state().splatted, 1000);
    // A bound of 0 discards every delayed sample.
    p.maxDelayed = 0;
    PajotPixel q;
    for (int i = 0; i < 4; ++i) addY(q, 1.0, p);
    addY(q, 1e6, p);
    EXPECT_EQ(q.state().discarded, 1);
    EXPECT_TRUE(q.state().delayed.empty());
}

/// Feeds `samples` log-normal body samples (sigma 0.3 in log space); sample i is a firefly, 10^5
/// times brighter, when isFirefly(i). Returns the mean of the body samples and of all samples.
template <class IsFirefly>
std::pair<double, double> feedBody(PajotPixel& px, const PajotParams& p, int samples,
                                   IsFirefly isFirefly) {
    std::mt19937_64 rng(7);
    std::normal_distribution<double> body(0.0, 0.3);
    double sumBody = 0, sumAll = 0;
    int64_t nBody = 0;
    for (int i = 0; i < samples; ++i) {
        const bool firefly = isFirefly(i);
        const double y = (firefly ? 1e5 : 1.0) * std::exp(body(rng));
        addY(px, y, p);
        sumAll += double(float(y));
        if (!firefly) {
            sumBody += double(float(y));
            ++nBody;
        }
    }
    return {sumBody / double(nBody), sumAll / double(samples)};
}

TEST(PajotEdges, AMillionSamplesAndOneFirefly) {
    // ROT and the hybrid take a million samples; ADR 10^5: its nearest-neighbour bandwidth shrinks
    // like 1/n, so every tail sample becomes a single mode (section 4.3, Table 1) and an update
    // costs a pass over the modes: 0.65 s for 10^5 samples, 80 s for 10^6 (docs/pajot.md).
    for (PajotMethod m : {PajotMethod::ROT, PajotMethod::Hybrid, PajotMethod::ADR}) {
        const int samples = m == PajotMethod::ADR ? 100000 : 1000000;
        const PajotParams p = params(m, 50);
        PajotPixel px;
        const auto [bodyMean, allMean] =
            feedBody(px, p, samples, [samples](int i) { return i == samples / 2; });
        EXPECT_EQ(px.state().taken, samples);
        EXPECT_EQ(px.state().splatted + px.counts().delayed + px.state().discarded, samples);
        // The firefly never reached the image; the body's brightest tail may be delayed too (ADR:
        // its 64-sample list overflows and the brightest are discarded, well under 1 % of bias).
        EXPECT_GT(allMean, bodyMean * 1.05);
        EXPECT_LT(px.estimate()[0], bodyMean * 1.001) << pajotMethodName(m);
        EXPECT_GT(px.estimate()[0], bodyMean * 0.99) << pajotMethodName(m);
        EXPECT_LE(px.counts().delayed, p.maxDelayed);
    }
}

TEST(PajotEdges, BrightSamplesThatRecurAreLightNotFireflies) {
    // Bright samples every 1000 samples (a thousand in a million): they form a mode of their own
    // and m moves above them, so the estimate converges to the true mean, as for a caustic
    // (section 4.3's progressiveness). Ten in a million, spread like the body, are not enough for
    // ROT's bandwidth at n = 10^6 (h = 0.01): only close pairs join, and part stays delayed.
    for (PajotMethod m : {PajotMethod::ROT, PajotMethod::Hybrid}) {
        const PajotParams p = params(m, 50);
        PajotPixel px;
        const auto [bodyMean, allMean] =
            feedBody(px, p, 1000000, [](int i) { return i % 1000 == 999; });
        EXPECT_GT(allMean, bodyMean * 10);
        EXPECT_NEAR(px.estimate()[0], allMean, 0.01 * allMean) << pajotMethodName(m);
    }
}

TEST(PajotEdges, AStateCopiedMidwayContinuesBitForBit) {
    const PajotParams p = params(PajotMethod::Hybrid, 50);
    std::mt19937_64 rng(3);
    std::lognormal_distribution<double> d(0.0, 1.5);
    std::vector<double> ys(5000);
    for (double& y : ys) y = d(rng);
    PajotPixel straight, first;
    for (double y : ys) addY(straight, y, p);
    for (size_t i = 0; i < 2500; ++i) addY(first, ys[i], p);
    PajotPixel resumed(first.state());
    for (size_t i = 2500; i < ys.size(); ++i) addY(resumed, ys[i], p);
    EXPECT_EQ(resumed.estimate(), straight.estimate());
    EXPECT_EQ(resumed.state().splatted, straight.state().splatted);
    EXPECT_EQ(resumed.state().delayed.size(), straight.state().delayed.size());
}

TEST(PajotParamsCheck, RangesAreChecked) {
    std::string err;
    PajotParams p;
    EXPECT_TRUE(validatePajotParams(p, err));
    p.learning = 0;
    EXPECT_FALSE(validatePajotParams(p, err));
    EXPECT_NE(err.find("n (learning samples)"), std::string::npos);
    p = PajotParams();
    p.delta = -1;
    EXPECT_FALSE(validatePajotParams(p, err));
    PajotMethod m;
    EXPECT_TRUE(parsePajotMethod("rot", m));
    EXPECT_EQ(m, PajotMethod::ROT);
    EXPECT_FALSE(parsePajotMethod("ROT ", m));
}

}  // namespace
}  // namespace mcstat
