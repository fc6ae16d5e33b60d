// Jung's estimators (thesis eq. 4.6-4.8, 5.1, 5.2): TMPE, MPE (= MoN), myriad and meridian, against
// hand-computed values and brute-force minimisation of the cost functions.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "mcstat/filters/pixel/mean.h"
#include "mcstat/filters/pixel/median.h"
#include "mcstat/filters/pixel/meridian.h"
#include "mcstat/filters/pixel/myriad.h"
#include "mcstat/filters/pixel/tmpe.h"
#include "mcstat/filters/registry.h"
#include "pixel_support.h"

using namespace mcstat;

namespace {

using namespace mcstat::testing;

struct Opts {
    EstimatorMode mode = EstimatorMode::PerChannel;
    double alpha = 0.25, gamma = 0.05, delta = 0.05;
    /// The thesis' form (0.05 x range, section 4.2): these tests reproduce the thesis; the default
    /// (Hampel's fence) has its own tests (test_extremes.cpp).
    ScaleRule scale = ScaleRule::Range;
    std::array<double, 3> luma = kLuma;
};

/// The estimators under test, called directly with their own parameter structs (the registry's
/// binding is tested in tests/filters/test_registry.cpp): values such as gamma = 1e-300 are
/// within the kernels' domain even where no command line would write them.
enum class Est { Mean, MoN, TMPE, Myriad, Meridian };

PixelEstimate run(Est fn, const Pixel& px, const Opts& o = {}) {
    const PixelParams base{o.mode, o.luma};
    EstimatorScratch s;
    PixelEstimate e;
    switch (fn) {
        case Est::Mean:
            estimateMean(px.view(), base, e, s);
            break;
        case Est::MoN:
            estimateMoN(px.view(), base, e, s);
            break;
        case Est::TMPE: {
            TmpeParams p;
            static_cast<PixelParams&>(p) = base;
            p.alpha = o.alpha;
            estimateTMPE(px.view(), p, e, s);
            break;
        }
        case Est::Myriad: {
            MyriadParams p;
            static_cast<PixelParams&>(p) = base;
            p.gamma = o.gamma;
            p.scale = o.scale;
            estimateMyriad(px.view(), p, e, s);
            break;
        }
        case Est::Meridian: {
            MeridianParams p;
            static_cast<PixelParams&>(p) = base;
            p.delta = o.delta;
            p.scale = o.scale;
            estimateMeridian(px.view(), p, e, s);
            break;
        }
    }
    return e;
}

Opts absScale(double scale, EstimatorMode mode = EstimatorMode::PerChannel) {
    Opts o;
    o.gamma = o.delta = scale;
    o.scale = ScaleRule::Absolute;
    o.mode = mode;
    return o;
}

/// Brute force for eq. 4.7: the cost on a dense grid over [x_0, x_K-1], then golden section around
/// the best grid point. Returns the minimiser; `cost` receives its cost.
double bruteMyriad(const std::vector<double>& x, const std::vector<double>& w, double gamma,
                   double& cost, int grid = 200000) {
    const int K = int(x.size());
    const double lo = x.front(), hi = x.back(), h = (hi - lo) / grid;
    double best = lo, bestCost = myriadCost(x.data(), w.data(), K, gamma, lo);
    for (int i = 1; i <= grid; ++i) {
        const double b = lo + h * i;
        const double c = myriadCost(x.data(), w.data(), K, gamma, b);
        if (c < bestCost) bestCost = c, best = b;
    }
    double a = std::max(lo, best - h), bb = std::min(hi, best + h);
    const double g = (std::sqrt(5.0) - 1) / 2;
    for (int it = 0; it < 200; ++it) {
        const double c1 = bb - g * (bb - a), c2 = a + g * (bb - a);
        if (myriadCost(x.data(), w.data(), K, gamma, c1) <
            myriadCost(x.data(), w.data(), K, gamma, c2))
            bb = c2;
        else
            a = c1;
    }
    const double refined = 0.5 * (a + bb);
    const double rc = myriadCost(x.data(), w.data(), K, gamma, refined);
    if (rc < bestCost) bestCost = rc, best = refined;
    cost = bestCost;
    return best;
}

}  // namespace

// ---- TMPE (eq. 5.1) and MPE (eq. 5.2) -----------------------------------------------------------

TEST(TMPE, AlphaMapsToATrimCount) {
    EXPECT_EQ(tmpeTrim(0.0, 9), 0);
    EXPECT_EQ(tmpeTrim(0.1, 9), 0);    // floor(0.9)
    EXPECT_EQ(tmpeTrim(0.12, 17), 2);  // the thesis' 12% breakdown point: floor(2.04)
    EXPECT_EQ(tmpeTrim(0.25, 17), 4);
    EXPECT_EQ(tmpeTrim(0.2, 5), 1);
    EXPECT_EQ(tmpeTrim(3.0 / 7.0, 7), 3);  // alpha = i/m exactly as eq. 5.1 intends
    EXPECT_EQ(tmpeTrim(2.0 / 7.0, 7), 2);
    EXPECT_EQ(tmpeTrim(0.1 * 3, 10), 3);  // 0.30000000000000004 * 10
    EXPECT_EQ(tmpeTrim(0.7 / 7.0 * 3, 10), 3);
    EXPECT_EQ(tmpeTrim(0.5, 5), 2);  // the largest alpha: the median
    EXPECT_EQ(tmpeTrim(0.5, 4), 1);  // even M: the two middle means stay (eq. 5.2)
    EXPECT_EQ(tmpeTrim(0.5, 2), 0);
    EXPECT_EQ(tmpeTrim(0.5, 1), 0);
    EXPECT_EQ(tmpeTrim(-1.0, 5), 0);
}

TEST(TMPE, HandComputedAndEndpoints) {
    Pixel px = grey({100, 2, 4, 1, 3});
    Opts o;
    o.alpha = 0.2;  // c = 1: mean of {2, 3, 4}
    PixelEstimate t = run(Est::TMPE, px, o);
    EXPECT_FLOAT_EQ(t.rgb[0], 3.f);
    EXPECT_EQ(t.kept[0], 3);
    o.alpha = 0.0;
    EXPECT_FLOAT_EQ(run(Est::TMPE, px, o).rgb[0], 22.f);
    // counts as weights, even M: alpha 0.5 -> the count-weighted middle pair, exactly MoN / MPE
    Pixel w = grey({0, 10, 20, 1000}, {1, 3, 1, 1});
    o.alpha = 0.5;
    EXPECT_FLOAT_EQ(run(Est::TMPE, w, o).rgb[0], 12.5f);  // (3*10 + 20) / 4
    for (auto mode : {EstimatorMode::PerChannel, EstimatorMode::Luminance}) {
        o.mode = mode;
        o.alpha = 0.5;
        Pixel c({{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {5, 5, 5}, {0.2f, 0.3f, 0.1f}}, {1, 2, 1, 3, 1});
        EXPECT_EQ(run(Est::TMPE, c, o).rgb, run(Est::MoN, c, o).rgb);
        o.alpha = 0.0;
        const auto a = run(Est::TMPE, c, o).rgb, b = run(Est::Mean, c, o).rgb;
        for (int ch = 0; ch < 3; ++ch) EXPECT_FLOAT_EQ(a[ch], b[ch]);
    }
}

TEST(MPE, MedianIsRegisteredAsMoN) {
    const Operation* e = findEstimator("median");
    ASSERT_NE(e, nullptr);
    EXPECT_NE(e->title.find("MPE"), std::string::npos);
    // The same kernel as MoN: equal results on an even and an odd set, in both modes.
    for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel})
        for (const Pixel& px : {grey({4, 1, 9, 2}), grey({7, 1, 3}, {2, 1, 5})}) {
            EXPECT_EQ(runKernel("median", px, mode).rgb, runKernel("mon", px, mode).rgb);
            EXPECT_EQ(runKernel("median", px, mode).rgb, run(Est::MoN, px, {mode}).rgb);
        }
}

// ---- myriad (eq. 4.7) ---------------------------------------------------------------------------

TEST(Myriad, TwoClustersGlobalMinimumMatchesBruteForce) {
    // three samples near 0 against two near 10: two local minima, the global one at the larger
    // cluster
    std::vector<double> x = {0.0, 0.1, 0.2, 10.0, 10.1}, w = {1, 1, 1, 1, 1};
    const double gamma = 0.5;
    double bruteCost = 0;
    const double brute = bruteMyriad(x, w, gamma, bruteCost);
    const double b = myriadSorted(x.data(), w.data(), 5, gamma);
    EXPECT_LT(b, 1.0);
    EXPECT_NEAR(b, brute, 1e-6);
    EXPECT_LE(myriadCost(x.data(), w.data(), 5, gamma, b), bruteCost + 1e-12);
    // the other local minimum exists and is worse: descending from 10 must not be the answer
    EXPECT_GT(myriadCost(x.data(), w.data(), 5, gamma, 10.05), bruteCost + 1.0);
    // weight the far cluster by counts (3 samples per buffer): the global minimum moves there
    std::vector<double> w2 = {1, 1, 1, 3, 3};
    const double b2 = myriadSorted(x.data(), w2.data(), 5, gamma);
    const double brute2 = bruteMyriad(x, w2, gamma, bruteCost);
    EXPECT_GT(b2, 9.0);
    EXPECT_NEAR(b2, brute2, 1e-6);
}

TEST(Myriad, RandomSetsMatchBruteForce) {
    std::mt19937 rng(12345);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    int worse = 0;
    for (int trial = 0; trial < 300; ++trial) {
        const int K = 2 + int(u(rng) * 8);
        std::vector<double> x(static_cast<size_t>(K)), w(static_cast<size_t>(K));
        for (int j = 0; j < K; ++j) {
            // clusters, spread values and heavy tails
            x[size_t(j)] = trial % 3 == 0 ? std::floor(u(rng) * 4) + 0.05 * u(rng)
                                          : std::pow(10.0, 3.0 * u(rng)) * u(rng);
            w[size_t(j)] = 1.0 + std::floor(u(rng) * 4);
        }
        std::sort(x.begin(), x.end());
        x.erase(std::unique(x.begin(), x.end()), x.end());
        w.resize(x.size());
        const int Kd = int(x.size());
        if (Kd < 2) continue;
        const double gamma = (x.back() - x.front()) * std::pow(10.0, -3.0 + 4.0 * u(rng));
        double bruteCost = 0;
        bruteMyriad(x, w, gamma, bruteCost, 40000);
        const double b = myriadSorted(x.data(), w.data(), Kd, gamma);
        const double c = myriadCost(x.data(), w.data(), Kd, gamma, b);
        EXPECT_GE(b, x.front());
        EXPECT_LE(b, x.back());
        if (c > bruteCost + 1e-9 * std::max(1.0, std::fabs(bruteCost))) {
            ++worse;
            ADD_FAILURE() << "trial " << trial << " K " << Kd << " gamma " << gamma << ": cost "
                          << c << " > brute " << bruteCost;
        }
    }
    EXPECT_EQ(worse, 0);
}

TEST(Myriad, ScaleLimits) {
    // gamma very large: the count-weighted mean (eq. 4.7 -> eq. 4.5)
    Pixel px = grey({1, 2, 3, 50}, {1, 2, 1, 1});
    EXPECT_NEAR(run(Est::Myriad, px, absScale(1e8)).rgb[0], (1 + 4 + 3 + 50) / 5.0, 1e-5);
    Opts rel;
    rel.gamma = 1e6;  // relative: 1e6 x range
    EXPECT_NEAR(run(Est::Myriad, px, rel).rgb[0], 58.0 / 5.0, 1e-5);
    // gamma -> 0: the mode (most-weighted value), counts deciding
    EXPECT_EQ(run(Est::Myriad, grey({3, 1, 2, 1}), absScale(1e-30)).rgb[0], 1.f);
    EXPECT_EQ(run(Est::Myriad, grey({1, 2, 3}, {1, 5, 1}), absScale(1e-30)).rgb[0], 2.f);
    EXPECT_EQ(run(Est::Myriad, grey({1, 2, 3}, {1, 1, 5}), absScale(1e-300)).rgb[0], 3.f);
    Opts tiny;
    tiny.gamma = 1e-12;
    EXPECT_EQ(run(Est::Myriad, grey({7, 9, 9, 100}), tiny).rgb[0], 9.f);
}

TEST(Myriad, HugeRangesStayFiniteAndOptimal) {
    std::vector<double> x = {1e-6, 1e-3, 1.0, 1e3, 1e6}, w = {1, 1, 1, 1, 1};
    for (double gamma : {1e-6, 1e-3, 1.0, 5e4, 1e5, 1e9}) {
        const double b = myriadSorted(x.data(), w.data(), 5, gamma);
        ASSERT_TRUE(std::isfinite(b)) << gamma;
        double bruteCost = 0;
        bruteMyriad(x, w, gamma, bruteCost, 400000);
        // the grid cannot resolve the 1e-6 cluster: allow the brute force to be *worse*, never
        // better
        EXPECT_LE(myriadCost(x.data(), w.data(), 5, gamma, b),
                  bruteCost + 1e-9 * std::max(1.0, std::fabs(bruteCost)))
            << gamma;
    }
    // the thesis' relative scale on that spread: gamma = 0.05 * 1e6; the three small values win
    PixelEstimate e = run(Est::Myriad, grey({1e-6f, 1e-3f, 1.f, 1e3f, 1e6f}));
    EXPECT_TRUE(std::isfinite(e.rgb[0]));
    EXPECT_LT(e.rgb[0], 2000.f);
    PixelEstimate big = run(Est::Myriad, grey({3e38f, 3.4e38f, 1.f}));
    EXPECT_TRUE(std::isfinite(big.rgb[0]));
}

TEST(Myriad, TiesGoToTheSmallerValue) {
    // two identical clusters: two global minima, mirror images; the smaller wins, deterministically
    std::vector<double> x = {0.0, 10.0}, w = {2, 2};
    const double b = myriadSorted(x.data(), w.data(), 2, 0.1);
    EXPECT_LT(b, 1.0);
    EXPECT_GE(b, 0.0);
    PixelEstimate e = run(Est::Myriad, grey({10, 0, 0, 10}), absScale(0.1));
    EXPECT_LT(e.rgb[0], 1.f);
}

TEST(Myriad, LuminanceModeReproducesBetaOnLuminance) {
    // coloured buffers and a white firefly: RGB = weighted average with k_j; its luminance is beta
    Pixel px({{0.2f, 0.3f, 0.1f},
              {0.25f, 0.3f, 0.12f},
              {0.18f, 0.28f, 0.2f},
              {40, 40, 40},
              {0.21f, 0.31f, 0.1f}},
             {4, 4, 4, 4, 3});
    Opts o;
    o.mode = EstimatorMode::Luminance;
    PixelEstimate e = run(Est::Myriad, px, o);
    std::vector<double> Y;
    for (size_t j = 0; j < 5; ++j)
        Y.push_back(kLuma[0] * px.mean[3 * j] + kLuma[1] * px.mean[3 * j + 1] +
                    kLuma[2] * px.mean[3 * j + 2]);
    std::vector<double> ys = Y, ws = {4, 4, 4, 3, 4};  // sorted by Y: firefly last
    std::vector<int> idx = {0, 1, 2, 3, 4};
    std::sort(idx.begin(), idx.end(), [&](int a, int b) { return Y[size_t(a)] < Y[size_t(b)]; });
    for (size_t r = 0; r < 5; ++r) ys[r] = Y[size_t(idx[r])], ws[r] = px.count[size_t(idx[r])];
    const double gamma = 0.05 * (ys.back() - ys.front());
    const double beta = myriadSorted(ys.data(), ws.data(), 5, gamma);
    const double lum = kLuma[0] * e.rgb[0] + kLuma[1] * e.rgb[1] + kLuma[2] * e.rgb[2];
    EXPECT_NEAR(lum, beta, 1e-6 * std::max(1.0, beta));
    EXPECT_LT(e.rgb[0], 0.3f);  // the firefly has weight gamma^2 / (gamma^2 + ~40^2): gone
    EXPECT_EQ(e.kept[0], 4);
    EXPECT_EQ(e.kept[0], e.kept[2]);
    // equal luminance (exactly, with luma 0.5/0.25/0.25), different colours: K = 1, the
    // count-weighted mean of the colours
    o.luma = {0.5, 0.25, 0.25};
    Pixel same({{1, 0, 0}, {0, 1, 1}}, {1, 3});
    PixelEstimate s = run(Est::Myriad, same, o);
    EXPECT_FLOAT_EQ(s.rgb[0], 0.25f);
    EXPECT_FLOAT_EQ(s.rgb[1], 0.75f);
    EXPECT_EQ(s.kept[0], 2);
}

// ---- meridian (eq. 4.8) -------------------------------------------------------------------------

TEST(Meridian, HandComputedCostsAndSelection) {
    // delta = 1: cost(0) = log 2 + log 3 + log 11 = 4.19; cost(1) = 2 log 2 + log 10 = 3.69;
    // cost(2) = log 3 + log 2 + log 9 = 3.99; cost(10) = log 11 + log 10 + log 9 = 6.9
    std::vector<double> x = {0, 1, 2, 10}, w = {1, 1, 1, 1};
    EXPECT_NEAR(meridianCost(x.data(), w.data(), 4, 1.0, 1.0), 2 * std::log(2.0) + std::log(10.0),
                1e-12);
    EXPECT_EQ(meridianSorted(x.data(), w.data(), 4, 1.0), 1);
    EXPECT_EQ(run(Est::Meridian, grey({10, 2, 0, 1}), absScale(1.0)).rgb[0], 1.f);
    // the minimum over the real line is at a sample (eq. 4.8's beta in {x_i}): dense scan
    const double best = meridianCost(x.data(), w.data(), 4, 1.0, 1.0);
    for (int i = 0; i <= 100000; ++i)
        ASSERT_GE(meridianCost(x.data(), w.data(), 4, 1.0, 10.0 * i / 100000), best - 1e-12);
}

TEST(Meridian, LimitsTiesAndWeights) {
    // delta large: the median (odd count); delta tiny: the mode
    EXPECT_EQ(run(Est::Meridian, grey({0, 1, 2, 3, 100}), absScale(1e9)).rgb[0], 2.f);
    EXPECT_EQ(run(Est::Meridian, grey({3, 1, 2, 1}), absScale(1e-30)).rgb[0], 1.f);
    // ties by rank: {0, 1} are symmetric -> the smaller
    EXPECT_EQ(run(Est::Meridian, grey({1, 0})).rgb[0], 0.f);
    // counts are sample weights: three samples behind 1 beat one behind 0
    EXPECT_EQ(run(Est::Meridian, grey({0, 1}, {1, 3})).rgb[0], 1.f);
    PixelEstimate k = run(Est::Meridian, grey({5, 5, 1, 9}));
    EXPECT_EQ(k.rgb[0], 5.f);
    EXPECT_EQ(k.kept[0], 2);
}

TEST(Meridian, LuminanceReturnsOneBuffersColor) {
    Opts o;
    o.mode = EstimatorMode::Luminance;
    Pixel px({{0.2f, 0.3f, 0.1f}, {0.22f, 0.31f, 0.1f}, {30, 30, 30}, {0.21f, 0.29f, 0.12f}},
             {1, 1, 1, 1});
    PixelEstimate e = run(Est::Meridian, px, o);
    bool isBuffer = false;
    for (size_t j = 0; j < 4; ++j)
        isBuffer |= e.rgb[0] == px.mean[3 * j] && e.rgb[1] == px.mean[3 * j + 1] &&
                    e.rgb[2] == px.mean[3 * j + 2];
    EXPECT_TRUE(isBuffer);
    EXPECT_LT(e.rgb[0], 1.f);
    EXPECT_EQ(e.kept[0], 1);
    // equal luminance (exactly, with luma 0.5/0.25/0.25): the lowest buffer index
    o.luma = {0.5, 0.25, 0.25};
    Pixel same({{0, 1, 1}, {1, 0, 0}, {3, 3, 3}}, {1, 1, 1});
    EXPECT_EQ(run(Est::Meridian, same, o).rgb, (std::array<float, 3>{0, 1, 1}));
    Pixel swapped({{1, 0, 0}, {0, 1, 1}, {3, 3, 3}}, {1, 1, 1});
    EXPECT_EQ(run(Est::Meridian, swapped, o).rgb, (std::array<float, 3>{1, 0, 0}));
}

// ---- shared edges -------------------------------------------------------------------------------

TEST(JungEstimators, EdgesOfEveryEstimator) {
    for (Est fn : {Est::TMPE, Est::Myriad, Est::Meridian}) {
        for (auto mode : {EstimatorMode::PerChannel, EstimatorMode::Luminance}) {
            Opts o;
            o.mode = mode;
            // M = 1
            PixelEstimate one = run(fn, Pixel({{0.25f, 5.f, 1e30f}}, {7}), o);
            EXPECT_EQ(one.rgb[0], 0.25f);
            EXPECT_EQ(one.rgb[2], 1e30f);
            // all equal, all zero
            EXPECT_FLOAT_EQ(run(fn, grey({0.7f, 0.7f, 0.7f, 0.7f}), o).rgb[1], 0.7f);
            PixelEstimate z = run(fn, grey({0, 0, 0}), o);
            EXPECT_EQ(z.rgb[0], 0.f);
            // NaN / Inf excluded and counted; the rest {1, 3}
            Pixel bad({{1, 1, 1}, {kNaN, 1, 1}, {3, 3, 3}, {2, kInf, 2}, {-kInf, 0, 0}},
                      {1, 1, 1, 1, 1});
            PixelEstimate b = run(fn, bad, o);
            EXPECT_EQ(b.excluded, 3);
            EXPECT_GE(b.rgb[0], 1.f);
            EXPECT_LE(b.rgb[0], 3.f);
            EXPECT_EQ(b.rgb[0], b.rgb[2]);
            // no valid buffer: black; empty buffers left out
            PixelEstimate none = run(fn, grey({kNaN, 0}, {1, 0}), o);
            EXPECT_EQ(none.rgb[0], 0.f);
            EXPECT_EQ(none.kept[0], 0);
            EXPECT_EQ(run(fn, grey({4, 0, 0}, {2, 0, 0}), o).rgb[0], 4.f);
            // negative means are ranked as they are
            PixelEstimate neg = run(fn, grey({-2, -1, -1.5f, 40}), o);
            EXPECT_LT(neg.rgb[0], 0.f);
        }
    }
}

TEST(JungEstimators, FireflyIsRemoved) {
    Pixel px = grey({0.2f, 0.21f, 0.19f, 0.2f, 500.f, 0.22f, 0.18f});
    for (auto mode : {EstimatorMode::PerChannel, EstimatorMode::Luminance}) {
        Opts o;
        o.mode = mode;
        for (Est fn : {Est::TMPE, Est::Meridian}) EXPECT_NEAR(run(fn, px, o).rgb[0], 0.2f, 0.02f);
        // The thesis' relative gamma = 0.05 x range = 25 is wide next to the firefly's distance of
        // 500: its weight gamma^2 / (gamma^2 + 500^2) = 1/401 still pulls the myriad to
        // (1.2 + 500/401) / (6 + 1/401) = 0.408 (the mean is 71.6). A smaller gamma removes it.
        const double k = 1.0 / 401.0;
        EXPECT_NEAR(run(Est::Myriad, px, o).rgb[0], (1.2 + 500 * k) / (6 + k), 2e-3);
        o.gamma = 0.001;
        EXPECT_NEAR(run(Est::Myriad, px, o).rgb[0], 0.2f, 0.02f);
    }
}
