// The removed light given back (filters/keep_light.h): energy conserved to float summation, a zero
// residual gives the robust image bit for bit, a lone firefly spread wide, a supported caustic
// kept close, AOVs by the beauty's kernels, the same bits at any thread count, the extremes.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "mcstat/filters/keep_light.h"
#include "mcstat/filters/keep_light_stream.h"

namespace mcstat {
namespace {

struct Field {
    int w, h;
    std::vector<float> robust, d, se;
    std::vector<float> robustY;  ///< the robust luminance, or empty (no edge test)
    std::vector<double> residual;
    std::vector<uint8_t> active;
    Field(int w_, int h_, int nch = 3)
        : w(w_),
          h(h_),
          robust(size_t(w_ * h_ * nch), 0.f),
          d(size_t(w_ * h_), 0.f),
          se(size_t(w_ * h_), 0.f),
          residual(size_t(w_ * h_ * nch), 0.0),
          active(size_t(w_ * h_), 0) {}
    size_t at(int x, int y) const { return size_t(y) * size_t(w) + size_t(x); }
    const float* robustYOrNull() const { return robustY.empty() ? nullptr : robustY.data(); }
};

/// Scales then return with rule 6's rest (a supported cluster's luck by the light guide), the
/// tent alone otherwise: the output per channel.
std::vector<float> giveBack(const Field& f, int nch, const KeepLightParams& p, int nthreads,
                            std::vector<uint8_t>* scaleOut = nullptr) {
    std::vector<uint8_t> scale(f.d.size()), restScale(f.d.size());
    std::vector<float> restShare(f.d.size());
    keepLightScales(f.d.data(), f.se.data(), f.robustYOrNull(), f.active.data(), f.w, f.h, p,
                    scale.data(), nthreads, restScale.data(), restShare.data());
    const std::vector<float> light =
        keepLightLightGuide(f.robustYOrNull(), f.d.data(), f.w, f.h, nthreads);
    std::vector<float> out(f.robust.size());
    returnResidual(f.robust.data(), f.residual.data(), scale.data(), keepLightRadii(p.maxRadius),
                   f.w, f.h, nch, out.data(), nthreads, nullptr, nullptr, restScale.data(),
                   restShare.data(), light.data());
    if (scaleOut) *scaleOut = scale;
    return out;
}

/// A size x size image of one channel, robust 0.1 everywhere (its luminance too), and a 3 x 3
/// block of d = se = 1 (residual 1) whose top left pixel is (at, at).
Field blockOnAFloor(int size, int at) {
    Field f(size, size, 1);
    std::fill(f.robust.begin(), f.robust.end(), 0.1f);
    f.robustY.assign(f.d.size(), 0.1f);
    for (int y = at; y < at + 3; ++y)
        for (int x = at; x < at + 3; ++x) {
            const size_t q = f.at(x, y);
            f.residual[q] = 1.0;
            f.d[q] = f.se[q] = 1.f;
            f.active[q] = 1;
        }
    return f;
}

/// A random image: robust values in [0, 1), residuals mostly 0, some small of both signs, a few
/// fireflies up to 1e4; d their average, se their size.
Field randomField(int w, int h, unsigned seed) {
    Field f(w, h);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const size_t p = f.at(x, y);
            for (int c = 0; c < 3; ++c) f.robust[p * 3 + size_t(c)] = float(u(rng));
            const double kind = u(rng);
            const double size = kind < 0.6 ? 0.0 : kind < 0.95 ? u(rng) - 0.3 : 1e4 * u(rng);
            if (size == 0.0) continue;
            for (int c = 0; c < 3; ++c) f.residual[p * 3 + size_t(c)] = size * (0.5 + u(rng));
            f.d[p] = float(size);
            f.se[p] = float(std::fabs(size));
            f.active[p] = 1;
        }
    // The robust luminance, so that the edge test takes part wherever the mean is nearer the
    // neighbours' median.
    f.robustY.resize(f.d.size());
    for (size_t p = 0; p < f.d.size(); ++p)
        f.robustY[p] = 0.2126f * f.robust[p * 3] + 0.7152f * f.robust[p * 3 + 1] +
                       0.0722f * f.robust[p * 3 + 2];
    return f;
}

TEST(KeepLight, RadiiDoubleUpToTheLargest) {
    EXPECT_EQ(keepLightRadii(32), (std::vector<int>{0, 1, 2, 4, 8, 16, 32}));
    EXPECT_EQ(keepLightRadii(20), (std::vector<int>{0, 1, 2, 4, 8, 16, 20}));
    EXPECT_EQ(keepLightRadii(1), (std::vector<int>{0, 1}));
    EXPECT_EQ(keepLightRadii(0), (std::vector<int>{0}));
}

// Every channel's sum over the image is the robust sum plus every residual, to float summation:
// the kernels sum to 1 inside the image, at its edges too.
TEST(KeepLight, EnergyConservedToFloatSummationOnRandomImages) {
    for (unsigned seed : {1u, 2u, 3u}) {
        for (auto [w, h] : {std::pair{97, 61}, std::pair{5, 3}, std::pair{1, 40}}) {
            const Field f = randomField(w, h, seed);
            const std::vector<float> out = giveBack(f, 3, {}, 2);
            for (int c = 0; c < 3; ++c) {
                double before = 0.0, after = 0.0, res = 0.0, scale = 0.0;
                for (size_t p = 0; p < f.d.size(); ++p) {
                    before += f.robust[p * 3 + size_t(c)];
                    after += out[p * 3 + size_t(c)];
                    res += f.residual[p * 3 + size_t(c)];
                    scale += std::fabs(out[p * 3 + size_t(c)]);
                }
                // Each output is one float rounding of its exact value: at most 2^-24 of it.
                EXPECT_NEAR(after, before + res, 1e-6 * scale + 1e-12)
                    << "seed " << seed << " " << w << "x" << h << " channel " << c;
            }
        }
    }
}

// Only removed light moves (rule 9 keeps every gain in place), so no pixel ends below the
// smaller of its robust value and its plain mean: what it receives from others is their losses,
// never their gains. randomField's residuals share their pixel's sign in every channel, a third
// of them gains (d in [-0.3, 0)), so the bound holds per channel here (on renders it holds for the
// luminance, the decision's d). Without the rule a gain's negative light reaches its neighbours.
TEST(KeepLight, NoPixelEndsBelowItsRobustValueAndItsMean) {
    for (unsigned seed : {1u, 2u, 3u}) {
        const Field f = randomField(97, 61, seed);
        const std::vector<float> out = giveBack(f, 3, {}, 2);
        size_t gains = 0;
        for (size_t p = 0; p < f.d.size(); ++p) {
            gains += f.d[p] < 0.f;
            for (size_t c = 0; c < 3; ++c) {
                const double robust = f.robust[p * 3 + c];
                const double floor = std::min(robust, robust + f.residual[p * 3 + c]);
                ASSERT_GE(double(out[p * 3 + c]), floor - 1e-6 * std::fabs(floor))
                    << "seed " << seed << " pixel " << p << " channel " << c;
            }
        }
        EXPECT_GT(gains, 500u);  // the bound is tested where it could fail
    }
    // By hand: the bottom row of a light (rows 0 to 16: 17) over a dark floor of 0.05, and in it
    // a pixel that a mode-seeking estimator filled (robust 17, mean 12.95, 16 of 21 buffers on
    // the light: d = -4.05, se 1.62, z = -2.5; its neighbours' median is the light's, so the edge
    // test does not keep it). Its gain stays: it is its mean, and every other pixel keeps its
    // value bit for bit (spread, its -4.05 would darken the pixels around it).
    Field f(33, 33, 1);
    for (int y = 0; y < 33; ++y)
        for (int x = 0; x < 33; ++x) f.robust[f.at(x, y)] = y <= 16 ? 17.f : 0.05f;
    f.robustY = f.robust;
    const size_t p = f.at(16, 16);
    f.residual[p] = -4.05;
    f.d[p] = -4.05f;
    f.se[p] = 1.62f;
    f.active[p] = 1;
    const std::vector<float> out = giveBack(f, 1, {}, 1);
    EXPECT_EQ(out[p], float(double(17.f) - 4.05));
    for (size_t q = 0; q < out.size(); ++q) {
        if (q != p) {
            ASSERT_EQ(out[q], f.robust[q]) << q;
        }
    }
}

TEST(KeepLight, ZeroResidualGivesTheRobustImageBitForBit) {
    Field f = randomField(40, 30, 7);
    std::fill(f.residual.begin(), f.residual.end(), 0.0);
    f.robust[0] = -0.f;
    f.robust[1] = std::numeric_limits<float>::quiet_NaN();
    f.robust[2] = std::numeric_limits<float>::denorm_min();
    const std::vector<float> out = giveBack(f, 3, {}, 2);
    EXPECT_EQ(std::memcmp(out.data(), f.robust.data(), out.size() * sizeof(float)), 0);
}

// Pixels no residual reaches keep their robust value bit for bit, even next to a firefly of 1e38.
TEST(KeepLight, PixelsBeyondEveryWindowAreUntouched) {
    Field f(200, 3, 1);
    for (size_t i = 0; i < f.robust.size(); ++i) f.robust[i] = 0.1f * float(i % 7);
    const size_t p = f.at(5, 1);
    f.residual[p] = 1e38;
    f.d[p] = f.se[p] = 1e38f;
    f.active[p] = 1;
    std::vector<uint8_t> scale;
    const std::vector<float> out = giveBack(f, 1, {}, 1, &scale);
    const int R = KeepLightParams().maxRadius;
    EXPECT_EQ(keepLightRadii(R)[scale[p]], R);  // a lone firefly: the widest window
    for (int y = 0; y < 3; ++y)
        for (int x = 0; x < 200; ++x) {
            const size_t q = f.at(x, y);
            if (x <= 5 + R) {
                EXPECT_GT(out[q], f.robust[q]) << x << "," << y;
                EXPECT_TRUE(std::isfinite(out[q]));
            } else {
                EXPECT_EQ(out[q], f.robust[q]) << x << "," << y;  // exactly
            }
        }
}

// A firefly of 1e38 far above and left of a supported caustic leaves the caustic's scales as they
// are without it: the scale choice sums each window directly (a summed-area table would carry
// the firefly's rounding into every window below and right of it, and fails this test).
TEST(KeepLight, AFarFireflyOf1e38ChangesNoOtherScale) {
    Field f(96, 96, 1);
    for (int y = 60; y < 69; ++y)
        for (int x = 60; x < 69; ++x) {
            const size_t p = f.at(x, y);
            f.residual[p] = 1e-3;
            f.d[p] = 1e-3f;
            f.se[p] = 3e-4f;
            f.active[p] = 1;
        }
    std::vector<uint8_t> alone, with;
    giveBack(f, 1, {}, 2, &alone);
    const size_t far = f.at(2, 2);
    f.residual[far] = 1e38;
    f.d[far] = f.se[far] = 1e38f;
    f.active[far] = 1;
    giveBack(f, 1, {}, 2, &with);
    for (int y = 60; y < 69; ++y)
        for (int x = 60; x < 69; ++x)
            EXPECT_EQ(alone[f.at(x, y)], with[f.at(x, y)]) << x << "," << y;
}

// A firefly alone (d = se, its neighbours exact zeros): its window grows to the largest, and its
// light is spread thin: no pixel gets more than a hundredth of it.
TEST(KeepLight, ALoneFireflyIsSpreadWide) {
    const int R = KeepLightParams().maxRadius;
    Field f(2 * R + 40, 2 * R + 30, 1);  // its window inside the image
    const size_t p = f.at(R + 20, R + 10);
    f.residual[p] = 900.0;
    f.d[p] = f.se[p] = 900.f;
    f.active[p] = 1;
    std::vector<uint8_t> scale;
    const std::vector<float> out = giveBack(f, 1, {}, 2, &scale);
    EXPECT_EQ(keepLightRadii(R)[scale[p]], R);
    double total = 0.0, peak = 0.0;
    for (float v : out) {
        total += v;
        peak = std::max(peak, double(v));
    }
    EXPECT_NEAR(total, 900.0, 1e-6);
    EXPECT_LT(peak, 9.0);
    // The tent's centre: (r + 1)^2 of (r + 1)^4.
    EXPECT_NEAR(peak, 900.0 / (double(R + 1) * double(R + 1)), 1e-3);
    EXPECT_GT(out[f.at(R + 20 + R / 2, R + 10 - R / 2)], 0.f);
}

// A caustic: a 9 x 9 region whose every pixel lost light its buffers support (d = 10, se = 3:
// z = 3.3 each), in an image that lost nothing: its windows stop at the region's size, and
// nearly all its light stays within it and a few pixels of its edge.
TEST(KeepLight, ASupportedCausticIsKeptClose) {
    Field f(96, 96, 1);
    for (int y = 40; y < 49; ++y)
        for (int x = 40; x < 49; ++x) {
            const size_t p = f.at(x, y);
            f.residual[p] = 10.0;
            f.d[p] = 10.f;
            f.se[p] = 3.f;
            f.active[p] = 1;
        }
    std::vector<uint8_t> scale;
    const std::vector<float> out = giveBack(f, 1, {}, 2, &scale);
    const std::vector<int> radii = keepLightRadii(KeepLightParams().maxRadius);
    double inside = 0.0, total = 0.0;
    for (int y = 0; y < 96; ++y)
        for (int x = 0; x < 96; ++x) {
            const size_t q = f.at(x, y);
            total += out[q];
            if (x >= 36 && x < 53 && y >= 36 && y < 53) inside += out[q];
            // Its pixels stop at its size: the centre's at 4, a corner's (whose own small
            // windows are mostly dark) at 8.
            if (f.active[q]) {
                EXPECT_LE(radii[scale[q]], x > 41 && x < 47 && y > 41 && y < 47 ? 4 : 8)
                    << x << "," << y;
            }
        }
    // Each output is one float rounding of its exact value (rule 6 spreads some of it wide).
    EXPECT_NEAR(total, 810.0, 1e-7 * 810.0);
    EXPECT_GT(inside, 0.9 * total);
    // The same region, but each pixel's light a lone firefly's (se = d): spread far wider.
    for (size_t p = 0; p < f.se.size(); ++p)
        if (f.active[p]) f.se[p] = 1000.f;
    const std::vector<float> wide = giveBack(f, 1, {}, 2, &scale);
    double wideInside = 0.0;
    for (int y = 36; y < 53; ++y)
        for (int x = 36; x < 53; ++x) wideInside += wide[f.at(x, y)];
    EXPECT_LT(wideInside, 0.5 * total);
}

// A caustic of six pixels, each of which alone looks like a firefly (z = d / se = 1.1), the
// buffers of its 3 x 3 neighbourhoods significant together (2.2 to 2.7 >= supportZ): kept within
// a pixel, where ICI alone (supportZ out of reach) spreads each to the largest window.
TEST(KeepLight, ASmallCausticOfFireflyLikePixelsIsKeptClose) {
    Field f(64, 64, 1);
    for (int y = 30; y < 32; ++y)
        for (int x = 30; x < 33; ++x) {
            const size_t p = f.at(x, y);
            f.residual[p] = 5.0;
            f.d[p] = 5.f;
            f.se[p] = 4.5f;
            f.active[p] = 1;
        }
    const int R = KeepLightParams().maxRadius;
    const std::vector<int> radii = keepLightRadii(R);
    std::vector<uint8_t> scale;
    giveBack(f, 1, {}, 1, &scale);
    for (size_t p = 0; p < scale.size(); ++p)
        if (f.active[p]) {
            EXPECT_LE(radii[scale[p]], 1) << p;
        }
    KeepLightParams iciAlone;
    iciAlone.supportZ = 1e9;
    giveBack(f, 1, iciAlone, 1, &scale);
    for (size_t p = 0; p < scale.size(); ++p)
        if (f.active[p]) {
            EXPECT_EQ(radii[scale[p]], R) << p;
        }
}

// A thin caustic, a line of one-pixel-wide events whose 3 x 3 neighbourhoods are significant
// together (z = 15 / sqrt(3 * 16) = 2.17): each pixel keeps radius 1, and by the cluster guide
// its light stays on its line. By hand, at the line's middle (robust 0, so the plain mean is d):
// the tent's mean of d is (2 + 4 + 2) 5 / 16 = 2.5 on the line and (1 + 2 + 1) 5 / 16 = 1.25
// beside it, the light guide 5 on the line (a neighbour along it holds 5 too) and 0 beside it, so
// the guide c sqrt(m + c) is 2.5 sqrt(7.5) on the line and 1.25 sqrt(1.25) beside it. A sender's
// tent puts 2, 4, 2 on its row and 1, 2, 1 on each row beside it, so its window's guided sum is
// 8 (2.5 sqrt(7.5) + 1.25 sqrt(1.25)); a pixel on the line gets from its three senders 5 x 2.5
// sqrt(7.5) / (2.5 sqrt(7.5) + 1.25 sqrt(1.25)) = 5 x 2 sqrt(6) / (2 sqrt(6) + 1), one beside it
// 2.5 / (2 sqrt(6) + 1): 83 % of the light stays on the line, where the tent alone keeps half
// (5 x 8 / 16 = 2.5 on the line, 5 x 4 / 16 = 1.25 beside it) and c alone two thirds.
TEST(KeepLight, AThinCausticStaysOnItsLine) {
    Field f(64, 64, 1);
    for (int x = 10; x < 54; ++x) {
        const size_t p = f.at(x, 30);
        f.residual[p] = 5.0;
        f.d[p] = 5.f;
        f.se[p] = 4.f;
        f.active[p] = 1;
    }
    const std::vector<int> radii = keepLightRadii(KeepLightParams().maxRadius);
    std::vector<uint8_t> scale(f.d.size());
    keepLightScales(f.d.data(), f.se.data(), f.robustYOrNull(), f.active.data(), f.w, f.h, {},
                    scale.data(), 2);
    for (int x = 11; x < 53; ++x) ASSERT_EQ(radii[scale[f.at(x, 30)]], 1) << x;
    // The two ends, whose 3 x 3 neighbourhoods hold two events (z = 1.77), go wide; kept at radius
    // 1 here, so that nothing but the line's own light reaches the pixels checked by hand.
    scale[f.at(10, 30)] = scale[f.at(53, 30)] = scale[f.at(30, 30)];
    const std::vector<float> cluster =
        keepLightClusterGuide(f.robustYOrNull(), f.d.data(), f.w, f.h, 2);
    EXPECT_FLOAT_EQ(cluster[f.at(30, 30)], float(2.5 * std::sqrt(7.5)));
    EXPECT_FLOAT_EQ(cluster[f.at(30, 29)], float(1.25 * std::sqrt(1.25)));
    EXPECT_FLOAT_EQ(cluster[f.at(30, 28)], 0.f);
    std::vector<float> guided(f.robust.size()), tent(f.robust.size());
    returnResidual(f.robust.data(), f.residual.data(), scale.data(), radii, f.w, f.h, 1,
                   guided.data(), 2, nullptr, cluster.data());
    returnResidual(f.robust.data(), f.residual.data(), scale.data(), radii, f.w, f.h, 1,
                   tent.data(), 2);
    const double k = 2.0 * std::sqrt(6.0);
    EXPECT_NEAR(guided[f.at(30, 30)], 5.0 * k / (k + 1.0), 1e-6);
    EXPECT_NEAR(guided[f.at(30, 29)], 2.5 / (k + 1.0), 1e-6);
    EXPECT_NEAR(guided[f.at(30, 31)], 2.5 / (k + 1.0), 1e-6);
    EXPECT_EQ(guided[f.at(30, 28)], 0.f);
    EXPECT_NEAR(tent[f.at(30, 30)], 2.5, 1e-6);
    EXPECT_NEAR(tent[f.at(30, 29)], 1.25, 1e-6);
    double total = 0.0;
    for (float v : guided) total += v;
    EXPECT_NEAR(total, 44 * 5.0, 1e-9 * 220.0 + 1e-5);
}

/// The edge of a bright surface, as a defocused emitter's in the fixture's dof scene: rows 0 to 3
/// the surface (robust 17), row 4 the pixels it covers in part, rows 5 on the dark floor (0.1).
/// Row 4's robust values hold some of its light (1.0, where three of nine buffers saw it); the
/// pixel at (4, 4) saw it in one buffer, so the robust estimate dropped it: robust 0.05, mean
/// 0.55 (d = se = 0.5). Returns the field and that pixel.
std::pair<Field, size_t> partlyCoveredEdge() {
    Field f(9, 9, 1);
    f.robustY.assign(f.d.size(), 0.1f);
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 9; ++x) f.robustY[f.at(x, y)] = 17.f;
    for (int x = 0; x < 9; ++x) f.robustY[f.at(x, 4)] = 1.f;
    const size_t p = f.at(4, 4);
    f.robustY[p] = 0.05f;
    for (size_t q = 0; q < f.d.size(); ++q) f.robust[q] = f.robustY[q];
    f.residual[p] = 0.5;
    f.d[p] = f.se[p] = 0.5f;
    f.active[p] = 1;
    return {f, p};
}

// The pixel's neighbours put the median of their robust values at 1.0, nearer its mean (0.55)
// than its robust value (0.05): it keeps its light, and is its plain mean. Without the robust
// luminance the same pixel looks like a lone firefly (d = se) and goes wide.
TEST(KeepLight, AnEdgesPartlyCoveredPixelKeepsItsLight) {
    auto [f, p] = partlyCoveredEdge();
    std::vector<uint8_t> scale;
    const std::vector<float> out = giveBack(f, 1, {}, 2, &scale);
    EXPECT_EQ(scale[p], 0);
    EXPECT_FLOAT_EQ(out[p], 0.55f);
    for (size_t q = 0; q < out.size(); ++q) {
        if (q == p) continue;
        EXPECT_EQ(out[q], f.robust[q]) << q;  // nothing moved elsewhere
    }
    // Non-finite neighbours take no part: two of the floor's three below it, NaN and infinite,
    // leave 1.0 the median of the seven others.
    f.robustY[f.at(3, 5)] = std::numeric_limits<float>::quiet_NaN();
    f.robustY[f.at(5, 5)] = std::numeric_limits<float>::infinity();
    giveBack(f, 1, {}, 2, &scale);
    EXPECT_EQ(scale[p], 0);
    // Its own robust luminance not finite: no test, the choice without it.
    f.robustY[p] = std::numeric_limits<float>::quiet_NaN();
    giveBack(f, 1, {}, 2, &scale);
    EXPECT_GT(scale[p], 1);
    f.robustY.clear();
    giveBack(f, 1, {}, 2, &scale);
    EXPECT_GT(scale[p], 1);
}

// A firefly beside an emitter (the fixture's default scene: one buffer's event of 37.6 at a pixel
// whose reference is 0.25, the light at 200 above it): three of its nine neighbours are the
// emitter, the median is the floor's, nearer its robust value than its mean (4.9). Spread wide.
TEST(KeepLight, AFireflyBesideAnEmitterIsStillSpread) {
    Field f(9, 9, 1);
    f.robustY.assign(f.d.size(), 0.25f);
    for (int x = 0; x < 9; ++x) f.robustY[f.at(x, 3)] = 200.f;
    const size_t p = f.at(4, 4);
    for (size_t q = 0; q < f.d.size(); ++q) f.robust[q] = f.robustY[q];
    f.residual[p] = 4.65;
    f.d[p] = f.se[p] = 4.65f;
    f.active[p] = 1;
    std::vector<uint8_t> scale;
    const std::vector<float> out = giveBack(f, 1, {}, 2, &scale);
    EXPECT_GT(scale[p], 1);
    EXPECT_LT(out[p], 0.25f + 0.5f);
}

// AOVs go back by the beauty's kernels: where two light groups summed to the beauty's residual,
// the returned groups sum to the returned beauty (to float rounding).
TEST(KeepLight, AovsThatSummedToTheBeautyStillSum) {
    Field f = randomField(64, 48, 11);
    const size_t n = f.d.size();
    // Channels: beauty R, G, B, group a R, G, B, group b R, G, B (b = beauty - a).
    std::vector<float> robust(n * 9);
    std::vector<double> residual(n * 9);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (size_t p = 0; p < n; ++p)
        for (int c = 0; c < 3; ++c) {
            const double share = u(rng);
            const float beauty = f.robust[p * 3 + size_t(c)];
            robust[p * 9 + size_t(c)] = beauty;
            robust[p * 9 + 3 + size_t(c)] = float(share * beauty);
            robust[p * 9 + 6 + size_t(c)] = beauty - float(share * beauty);
            const double r = f.residual[p * 3 + size_t(c)];
            residual[p * 9 + size_t(c)] = r;
            residual[p * 9 + 3 + size_t(c)] = share * r;
            residual[p * 9 + 6 + size_t(c)] = r - share * r;
        }
    std::vector<uint8_t> scale(n);
    const KeepLightParams params;
    keepLightScales(f.d.data(), f.se.data(), f.robustYOrNull(), f.active.data(), f.w, f.h, params,
                    scale.data(), 2);
    std::vector<float> out(n * 9);
    returnResidual(robust.data(), residual.data(), scale.data(), keepLightRadii(params.maxRadius),
                   f.w, f.h, 9, out.data(), 2);
    for (size_t p = 0; p < n; ++p)
        for (int c = 0; c < 3; ++c) {
            const double beauty = out[p * 9 + size_t(c)];
            const double sum = double(out[p * 9 + 3 + size_t(c)]) + out[p * 9 + 6 + size_t(c)];
            EXPECT_NEAR(sum, beauty, 4e-7 * (std::fabs(beauty) + 1.0)) << p << " " << c;
        }
}

/// The return written the plain way: every q sums, over every p, residual(p) times p's weight at
/// q, t(q - p) g(q) / sum over q' inside the image of t(q' - p) g(q'). g is the cluster guide for
/// a window of radius 1, else the guide, else 1 (without one, or where p's window has none).
/// With a rest (rule 6), p sends restShare[p] of its residual so and the rest at
/// radii[restScale[p]] by the light guide, else 1.
std::vector<double> directReturn(const Field& f, int nch, const std::vector<uint8_t>& scale,
                                 const std::vector<int>& radii, const float* guide,
                                 const float* clusterGuide = nullptr,
                                 const uint8_t* restScale = nullptr,
                                 const float* restShare = nullptr, const float* light = nullptr) {
    std::vector<double> out(f.robust.begin(), f.robust.end());
    for (int py = 0; py < f.h; ++py)
        for (int px = 0; px < f.w; ++px) {
            const size_t p = f.at(px, py);
            const double share = restShare ? double(restShare[p]) : 1.0;
            for (const bool rest : {false, true}) {
                if (rest && !(share < 1.0)) continue;
                const int r = radii[rest ? restScale[p] : scale[p]];
                auto t = [&](int x, int y) {
                    return double(r + 1 - std::abs(x - px)) * double(r + 1 - std::abs(y - py));
                };
                auto normOf = [&](const float* g) {
                    double norm = 0.0;
                    for (int y = std::max(0, py - r); y <= std::min(f.h - 1, py + r); ++y)
                        for (int x = std::max(0, px - r); x <= std::min(f.w - 1, px + r); ++x)
                            norm += t(x, y) * (g ? double(g[f.at(x, y)]) : 1.0);
                    return norm;
                };
                const float* g = nullptr;
                if (rest) {
                    if (light && normOf(light) > 0.0) g = light;
                } else if (clusterGuide && r == 1 && normOf(clusterGuide) > 0.0) {
                    g = clusterGuide;
                } else if (guide && normOf(guide) > 0.0) {
                    g = guide;
                }
                const double norm = normOf(g), part = rest ? 1.0 - share : share;
                for (int y = std::max(0, py - r); y <= std::min(f.h - 1, py + r); ++y)
                    for (int x = std::max(0, px - r); x <= std::min(f.w - 1, px + r); ++x)
                        for (int c = 0; c < nch; ++c) {
                            const double v = f.residual[p * size_t(nch) + size_t(c)];
                            if (v == 0.0 || !std::isfinite(v)) continue;
                            out[f.at(x, y) * size_t(nch) + size_t(c)] +=
                                v * part * t(x, y) * (g ? double(g[f.at(x, y)]) : 1.0) / norm;
                        }
            }
        }
    return out;
}

// The block sums (van Herk's, rows and columns) and the direct sums over sparse rows give the
// plain sums' values: dense and sparse residuals, radii up to beyond the image, with a guide that
// is 0 in places and without one.
TEST(KeepLight, TheGatherEqualsThePlainSums) {
    for (unsigned seed : {4u, 5u}) {
        for (int r : {0, 1, 3, 8, 40}) {
            Field f = randomField(53, 37, seed);
            if (seed == 5u)  // sparse: every 50th pixel keeps its residual
                for (size_t p = 0; p < f.d.size(); ++p)
                    if (p % 50 != 7)
                        for (int c = 0; c < 3; ++c) f.residual[p * 3 + size_t(c)] = 0.0;
            std::mt19937 rng(seed);
            std::uniform_real_distribution<float> u(0.f, 1.f);
            std::vector<float> guide(f.d.size());
            for (size_t p = 0; p < guide.size(); ++p)
                guide[p] = (p / 53) % 9 == 0 ? 0.f : u(rng);  // black rows: no surface
            std::vector<uint8_t> scale(f.d.size());
            for (size_t p = 0; p < scale.size(); ++p) scale[p] = uint8_t(p % 3);
            const std::vector<int> radii = {0, std::min(r, 2), r};
            // A cluster guide that is 0 over whole windows in places (d <= 0 there).
            const std::vector<float> cluster =
                keepLightClusterGuide(f.robustYOrNull(), f.d.data(), f.w, f.h, 2);
            // A rest (rule 6) from a third of the pixels, of shares 0 to 1, at another radius;
            // the light guide 0 over whole windows in places (the black rows).
            std::vector<uint8_t> restScale(f.d.size());
            std::vector<float> restShare(f.d.size(), 1.f);
            for (size_t p = 0; p < scale.size(); ++p)
                if (p % 3 == 1) {
                    restScale[p] = uint8_t((p / 3) % 3);
                    restShare[p] = float((p / 7) % 5) / 4.f;
                }
            const std::vector<float> light =
                keepLightLightGuide(guide.data(), f.d.data(), f.w, f.h, 2);
            using Guides = std::array<const float*, 3>;
            const float* const g0 = guide.data();
            const float* const c0 = cluster.data();
            const float* const l0 = light.data();
            for (const auto& [g, cg, lg] :
                 {Guides{nullptr, nullptr, nullptr}, Guides{g0, nullptr, nullptr},
                  Guides{nullptr, c0, nullptr}, Guides{g0, c0, nullptr}, Guides{g0, c0, l0},
                  Guides{nullptr, nullptr, l0}}) {
                const bool rest = lg != nullptr;
                std::vector<float> out(f.robust.size());
                returnResidual(f.robust.data(), f.residual.data(), scale.data(), radii, f.w, f.h, 3,
                               out.data(), 2, g, cg, rest ? restScale.data() : nullptr,
                               rest ? restShare.data() : nullptr, lg);
                const std::vector<double> want =
                    directReturn(f, 3, scale, radii, g, cg, rest ? restScale.data() : nullptr,
                                 rest ? restShare.data() : nullptr, lg);
                for (size_t i = 0; i < out.size(); ++i)
                    ASSERT_NEAR(out[i], want[i], 1e-6 * std::fabs(want[i]) + 1e-4)
                        << "seed " << seed << " r " << r << " guide " << (g != nullptr)
                        << " cluster guide " << (cg != nullptr) << " rest " << rest << " at " << i;
            }
        }
    }
}

TEST(KeepLight, SameBitsForAnyThreadCount) {
    const Field f = randomField(131, 77, 3);
    const std::vector<float> one = giveBack(f, 3, {}, 1);
    for (int t : {2, 3, 8}) {
        const std::vector<float> many = giveBack(f, 3, {}, t);
        EXPECT_EQ(std::memcmp(one.data(), many.data(), one.size() * sizeof(float)), 0) << t;
    }
}

// NaN and Inf residuals are not returned (the pixel keeps its robust value there); NaN or Inf d
// and se count as 0 in the scale choice.
TEST(KeepLight, NonFiniteResidualsStayOut) {
    Field f(20, 20, 1);
    const size_t a = f.at(3, 3), b = f.at(10, 10), c = f.at(15, 4);
    f.residual[a] = std::numeric_limits<double>::quiet_NaN();
    f.residual[b] = std::numeric_limits<double>::infinity();
    f.residual[c] = 4.0;
    f.d[a] = std::numeric_limits<float>::quiet_NaN();
    f.se[b] = std::numeric_limits<float>::infinity();
    f.d[c] = f.se[c] = 4.f;
    f.active[a] = f.active[b] = f.active[c] = 1;
    const std::vector<float> out = giveBack(f, 1, {}, 2);
    double total = 0.0;
    for (float v : out) {
        EXPECT_TRUE(std::isfinite(v));
        total += v;
    }
    EXPECT_NEAR(total, 4.0, 1e-6);  // float outputs
}

// The light guide (rule 6) by hand: the plain mean's luminance m = robustY + d, at most the
// brightest of the 8 neighbours' (inside the image); 0 where m is negative or not finite.
TEST(KeepLight, TheLightGuideByHand) {
    // 4 x 3: a floor of 0.1 with a lone firefly (m = 50.1) at (0, 0), a pair of bright pixels
    // (m = 2.1 and 3.1) at (2, 1) and (3, 1), a negative mean at (1, 2), a NaN residual at (3, 2).
    const int w = 4, h = 3;
    std::vector<float> robustY(w * h, 0.1f), d(w * h, 0.f);
    auto at = [&](int x, int y) { return size_t(y * w + x); };
    d[at(0, 0)] = 50.f;
    d[at(2, 1)] = 2.f;
    d[at(3, 1)] = 3.f;
    d[at(1, 2)] = -0.5f;
    d[at(3, 2)] = std::numeric_limits<float>::quiet_NaN();
    const std::vector<float> g = keepLightLightGuide(robustY.data(), d.data(), w, h, 2);
    auto m = [](double v) { return float(v); };
    EXPECT_EQ(g[at(0, 0)], m(0.1f));                // the firefly: its neighbours' 0.1
    EXPECT_EQ(g[at(1, 0)], m(0.1f));                // beside it: its own
    EXPECT_EQ(g[at(2, 1)], m(double(0.1f) + 2.0));  // the pair: each its own (2.1 <= 3.1)
    EXPECT_EQ(g[at(3, 1)], m(double(0.1f) + 2.0));  // 3.1, but at most its brightest, 2.1
    EXPECT_EQ(g[at(1, 2)], 0.f);                    // a negative mean
    EXPECT_EQ(g[at(3, 2)], 0.f);                    // not finite
    EXPECT_EQ(g[at(2, 2)], m(0.1f));                // its own 0.1, under the pair's
    // Without robustY, m is d alone; a lone pixel has no neighbour: 0.
    const std::vector<float> alone = keepLightLightGuide(nullptr, d.data(), 1, 1, 1);
    EXPECT_EQ(alone[0], 0.f);
    const std::vector<float> noRobust = keepLightLightGuide(nullptr, d.data(), w, h, 1);
    EXPECT_EQ(noRobust[at(0, 0)], 0.f);  // its neighbours' d are 0
    EXPECT_EQ(noRobust[at(3, 1)], 2.f);
}

// Rule 6 by hand: a 3 x 3 block of d = se = 1 on a floor of 0.1 (20 x 20, one channel). Every
// window's interval holds 0 (n d / area against 4 sqrt(n) / area), so ICI's own radius is the
// largest; the 3 x 3 test's Z is 9 / 3 = 3 at the centre, 6 / sqrt(6) at an edge's middle and
// 4 / 2 = 2 at a corner: the shares kept within a pixel are 1 - (2 / Z)^2 = 5 / 9, 1 / 3 and 0,
// and the rest, 4 / 9 + 4 x 2 / 3 + 4 x 1 = 64 / 9 of the 9, goes to the largest radius by the
// light guide: 1.1 on the block, 0.1 on the floor, so the block (2 % of the pixels) takes about a
// fifth of it back. Without the rest (rule 6 off) nothing reaches beyond two pixels of the block.
TEST(KeepLight, ASupportedClustersLuckGoesWhereTheLightIs) {
    Field f = blockOnAFloor(20, 9);
    const KeepLightParams params;
    const std::vector<int> radii = keepLightRadii(params.maxRadius);
    const size_t n = f.d.size(), largest = radii.size() - 1;
    std::vector<uint8_t> scale(n), restScale(n);
    std::vector<float> restShare(n);
    keepLightScales(f.d.data(), f.se.data(), f.robustY.data(), f.active.data(), f.w, f.h, params,
                    scale.data(), 2, restScale.data(), restShare.data());
    for (int y = 9; y < 12; ++y)
        for (int x = 9; x < 12; ++x) {
            const size_t p = f.at(x, y);
            const int edges = (x == 10) + (y == 10);  // 2: the centre, 1: an edge's middle
            EXPECT_EQ(radii[scale[p]], 1) << x << "," << y;
            EXPECT_EQ(restScale[p], largest) << x << "," << y;
            EXPECT_FLOAT_EQ(restShare[p], edges == 2   ? 5.f / 9.f
                                          : edges == 1 ? 1.f / 3.f
                                                       : 0.f)
                << x << "," << y;
        }
    EXPECT_EQ(restShare[f.at(5, 5)], 1.f);  // the floor sends nothing
    // The light guide against a tent alone for the rest: the tent of radius 64 over 20 x 20 is
    // flat to 17 % (55 to 65 per axis), so the block's share of the rest is about 9 x 1.1 /
    // (9 x 1.1 + 391 x 0.1) = 0.20 by the guide (at least 0.17), 9 / 400 by the tent (at most
    // 0.027).
    const std::vector<float> light = keepLightLightGuide(f.robustY.data(), f.d.data(), f.w, f.h, 2);
    std::vector<float> guided(n), tent(n), local(n);
    returnResidual(f.robust.data(), f.residual.data(), scale.data(), radii, f.w, f.h, 1,
                   guided.data(), 2, nullptr, nullptr, restScale.data(), restShare.data(),
                   light.data());
    returnResidual(f.robust.data(), f.residual.data(), scale.data(), radii, f.w, f.h, 1,
                   tent.data(), 2, nullptr, nullptr, restScale.data(), restShare.data(), nullptr);
    // Rule 6 off: the same scales, all of the light within a pixel of the block.
    returnResidual(f.robust.data(), f.residual.data(), scale.data(), radii, f.w, f.h, 1,
                   local.data(), 2);
    const double rest = 64.0 / 9.0;
    double total = 0.0, block = 0.0, blockByTent = 0.0, near = 0.0, far = 0.0;
    for (int y = 0; y < 20; ++y)
        for (int x = 0; x < 20; ++x) {
            const size_t q = f.at(x, y);
            const double added = double(guided[q]) - double(0.1f);
            total += added;
            const bool inBlock = x >= 9 && x < 12 && y >= 9 && y < 12;
            if (inBlock) {
                block += added;
                blockByTent += double(tent[q]) - double(0.1f);
            }
            if (x >= 7 && x < 14 && y >= 7 && y < 14) {
                near += added;
            } else {
                far += added;
            }
            if (x < 8 || x > 12 || y < 8 || y > 12) {
                EXPECT_EQ(local[q], 0.1f) << x << "," << y;
            }
        }
    EXPECT_NEAR(total, 9.0, 1e-6);  // 400 float roundings of about 0.1
    EXPECT_GT(near, 9.0 - rest);    // the kept shares stay within a pixel
    EXPECT_GT(block - blockByTent, (0.17 - 0.027) * rest);
    EXPECT_GT(far, 0.5 * rest);  // and most of the rest on the floor
    EXPECT_EQ(std::memcmp(giveBack(f, 1, params, 2).data(), guided.data(), n * sizeof(float)), 0);
}

// Rule 8 by hand (9 x 9, one channel): a defocused light's edge whose pixels all lost their
// light. Rows 0 to 3 are the light (robust 17), row 4 its edge (robust 0.1, plain means 0.4, d =
// se = 0.3, but 0.5 at (3, 4), 0.6 at (4, 4) and 0.3 at (5, 4)), rows 5 to 8 the floor (0.1).
// No robust value near (4, 4) holds the light (rule 5's median is 0.1) and its 3 x 3 test's Z is
// 1.1 / sqrt(0.45) = 1.64, so its light would go wide. Its 8 neighbours' plain means, sorted:
// 0.1 0.1 0.1 0.3 0.5 17 17 17, median 0.4: it keeps half the gap to its robust value, 0.15 of
// its d = 0.5, in place (restShare 0.7, restScale 0), and sends the rest to radius 64, where the
// tent over 9 x 9 gives its own pixel 65^2 / 565^2. A lone firefly on the floor (4, 7) keeps
// nothing: its neighbours' level is its robust value. A pixel that gained (d < 0) keeps nothing.
TEST(KeepLight, ANeighbourhoodsLightStaysWhereItsMeansSayItIs) {
    Field f(9, 9, 1);
    f.robustY.assign(f.d.size(), 0.1f);
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 9; ++x) f.robustY[f.at(x, y)] = 17.f;
    auto lose = [&](int x, int y, float d) {
        const size_t q = f.at(x, y);
        f.residual[q] = d;
        f.d[q] = d;
        f.se[q] = std::fabs(d);
        f.active[q] = 1;
    };
    for (int x = 0; x < 9; ++x) lose(x, 4, 0.3f);
    lose(3, 4, 0.4f);
    lose(4, 4, 0.5f);
    lose(5, 4, 0.2f);
    lose(4, 7, 0.5f);   // a lone firefly
    lose(1, 7, -0.2f);  // a pixel that gained
    f.robust = f.robustY;
    const size_t p = f.at(4, 4), n = f.d.size();
    const std::vector<int> radii = keepLightRadii(KeepLightParams{}.maxRadius);
    auto scales = [&](double share, std::vector<uint8_t>& scale, std::vector<uint8_t>& restScale,
                      std::vector<float>& restShare) {
        KeepLightParams params;
        params.neighbourShare = share;
        scale.assign(n, 0);
        restScale.assign(n, 0);
        restShare.assign(n, 0.f);
        keepLightScales(f.d.data(), f.se.data(), f.robustY.data(), f.active.data(), f.w, f.h,
                        params, scale.data(), 1, restScale.data(), restShare.data());
    };
    std::vector<uint8_t> scale, restScale;
    std::vector<float> restShare;
    scales(0.5, scale, restScale, restShare);
    EXPECT_EQ(radii[scale[p]], 64);
    EXPECT_EQ(restScale[p], 0);
    EXPECT_NEAR(restShare[p], 0.7, 1e-6);
    // (6, 4): neighbours 0.1 0.1 0.1 0.3 0.4 17 17 17, level 0.35, keeps 0.125 of 0.3.
    EXPECT_NEAR(restShare[f.at(6, 4)], 1.0 - 0.125 / 0.3, 1e-6);
    for (const size_t q : {f.at(4, 7), f.at(1, 7)}) {
        EXPECT_EQ(restShare[q], 1.f) << q;
        EXPECT_EQ(restScale[q], scale[q]) << q;
    }
    // p's own light alone: 0.15 in place, 0.35 x 65^2 / 565^2 of the wide window's back.
    std::vector<double> alone(n, 0.0);
    alone[p] = 0.5;
    const std::vector<float> light = keepLightLightGuide(f.robustY.data(), f.d.data(), f.w, f.h, 1);
    std::vector<float> out(n);
    returnResidual(f.robust.data(), alone.data(), scale.data(), radii, f.w, f.h, 1, out.data(), 1,
                   nullptr, nullptr, restScale.data(), restShare.data(), light.data());
    EXPECT_NEAR(out[p], 0.1 + 0.15 + 0.35 * 4225.0 / 319225.0, 1e-6);
    double total = 0.0;
    for (size_t q = 0; q < n; ++q) total += double(out[q]) - double(f.robust[q]);
    EXPECT_NEAR(total, 0.5, 4e-5);  // 36 float roundings at 17 (half an ulp: 9.5e-7)
    // The share: all of the gap (0.3 of 0.5), more than d (all of it), none (rules 1 to 7 alone).
    scales(1.0, scale, restScale, restShare);
    EXPECT_NEAR(restShare[p], 0.4, 1e-6);
    scales(4.0, scale, restScale, restShare);
    EXPECT_EQ(restShare[p], 0.f);
    scales(0.0, scale, restScale, restShare);
    EXPECT_EQ(restShare[p], 1.f);
    EXPECT_EQ(restScale[p], scale[p]);
    // A neighbour that is not finite takes no part: 0.1 0.1 0.1 0.3 0.5 17 17, level 0.3.
    f.robustY[f.at(3, 3)] = std::numeric_limits<float>::quiet_NaN();
    scales(0.5, scale, restScale, restShare);
    EXPECT_NEAR(restShare[p], 0.8, 1e-6);
    // Its own robust value not finite: no rule 8.
    f.robustY[p] = std::numeric_limits<float>::infinity();
    scales(0.5, scale, restScale, restShare);
    EXPECT_EQ(restShare[p], 1.f);
}

// Rule 9 by hand (9 x 9, one channel, robust 0.1): a 3 x 3 block of d = se = 1 (z = 1 each,
// supported together: Z = 12.5 / 3) around p = (4, 4), whose own d = 4.5 with se = 1 lies beyond
// ownZ = 2.5 of its own standard errors (a filter across pixels leaves such a residual, and a
// median of many buffers where many hold a light): the light is p's own, radius 0, all of it in
// place. Its neighbours (z = 1) keep the support test's radius 1. At z = 2.6 p still keeps it;
// at 2.4 (under ownZ) p is a supported cluster's pixel again, and so at 3.9 with ownZ 4; a gain
// (d = -4.5) and se = 0 (d not 0: the buffers agree) stay in place too.
TEST(KeepLight, LightBeyondAPixelsOwnNoiseStaysInIt) {
    Field f = blockOnAFloor(9, 3);
    const size_t p = f.at(4, 4), n = f.d.size();
    KeepLightParams params;
    const std::vector<int> radii = keepLightRadii(params.maxRadius);
    std::vector<uint8_t> scale(n), restScale(n);
    std::vector<float> restShare(n);
    auto scales = [&](float d, float se) {
        f.residual[p] = d;
        f.d[p] = d;
        f.se[p] = se;
        keepLightScales(f.d.data(), f.se.data(), f.robustY.data(), f.active.data(), f.w, f.h,
                        params, scale.data(), 1, restScale.data(), restShare.data());
    };
    scales(4.5f, 1.f);
    EXPECT_EQ(scale[p], 0);
    EXPECT_EQ(restShare[p], 1.f);
    EXPECT_EQ(radii[scale[f.at(3, 4)]], 1);
    // p's light alone comes back whole in p, bit for bit its mean's 0.1 + 4.5 in float.
    std::vector<double> alone(n, 0.0);
    alone[p] = 4.5;
    std::vector<float> out(n);
    returnResidual(f.robust.data(), alone.data(), scale.data(), radii, f.w, f.h, 1, out.data(), 1,
                   nullptr, nullptr, restScale.data(), restShare.data());
    EXPECT_EQ(out[p], float(double(0.1f) + 4.5));
    for (size_t q = 0; q < n; ++q) {
        if (q != p) {
            EXPECT_EQ(out[q], 0.1f) << q;
        }
    }
    // ownZ 2.5: z = 2.6 stays, z = 2.4 goes with its block (radius 1); ownZ 4 lets 3.9 go too.
    scales(2.6f, 1.f);
    EXPECT_EQ(scale[p], 0);
    scales(2.4f, 1.f);
    EXPECT_EQ(radii[scale[p]], 1);
    params.ownZ = 4.0;
    scales(3.9f, 1.f);
    EXPECT_EQ(radii[scale[p]], 1);
    params.ownZ = KeepLightParams().ownZ;
    scales(-4.5f, 1.f);
    EXPECT_EQ(scale[p], 0);
    scales(4.5f, 0.f);
    EXPECT_EQ(scale[p], 0);
}

// Rule 7's inputs by hand (32 x 8, radii 0, 1, 2, 4, gamma 4, se 0.01 everywhere): d = 2 left
// of column 16, 0 right of it. At (4, 4) every window lies on the left: ICI's estimate 2. At
// (14, 4) the windows of radius 0 and 1 say 2 and the one of radius 2 (columns 12 to 16) 8 / 5 =
// 1.6 +- 0.008: empty, so 2; its largest window (columns 10 to 18) 12 / 9. At (16, 4) the
// radius-1 window says 6 / 9 against d = 0 +- 0.04: the estimate is its own 0; its largest
// window 8 / 9. A pixel that lost nothing (6, 4), d = se = 0, amid the 2s: 0 +- 0 against 16 / 9,
// so 0, though it is not active. Negative estimates count as 0.
TEST(KeepLight, TheBiasAndLevelByHand) {
    Field f(32, 8, 1);
    for (int y = 0; y < 8; ++y)
        for (int x = 0; x < 32; ++x) {
            const size_t p = f.at(x, y);
            f.d[p] = x < 16 ? 2.f : 0.f;
            f.se[p] = 0.01f;
            f.active[p] = 1;
        }
    f.d[f.at(6, 4)] = f.se[f.at(6, 4)] = 0.f;
    f.active[f.at(6, 4)] = 0;
    f.d[f.at(30, 1)] = -1.f;  // a negative estimate of its own: bias 0
    KeepLightParams p;
    p.maxRadius = 4;
    const size_t n = f.d.size();
    std::vector<uint8_t> scale(n), restScale(n);
    std::vector<float> restShare(n), bias(n, -7.f), level(n, -7.f);
    keepLightScales(f.d.data(), f.se.data(), nullptr, f.active.data(), f.w, f.h, p, scale.data(), 2,
                    restScale.data(), restShare.data(), bias.data(), level.data());
    EXPECT_FLOAT_EQ(bias[f.at(4, 4)], 2.f);
    EXPECT_FLOAT_EQ(bias[f.at(14, 4)], 2.f);
    EXPECT_FLOAT_EQ(level[f.at(14, 4)], 12.f / 9.f);
    EXPECT_EQ(bias[f.at(16, 4)], 0.f);
    EXPECT_FLOAT_EQ(level[f.at(16, 4)], 8.f / 9.f);
    EXPECT_EQ(bias[f.at(6, 4)], 0.f);
    EXPECT_EQ(scale[f.at(6, 4)], 0);  // not active: no scale of its own
    EXPECT_EQ(bias[f.at(30, 1)], 0.f);
    for (size_t q = 0; q < n; ++q) ASSERT_GE(level[q], 0.f) << q;
    // The guide: bias where a surface was hit, plus floor x albedo x level.
    const float bs[5] = {2.f, 2.f, 2.f, 2.f, 2.f}, lv[5] = {1.f, 1.f, 1.f, 1.f, 0.5f};
    const float al[5] = {0.f, 0.5f, 1.f, std::numeric_limits<float>::quiet_NaN(), 1.f};
    const std::vector<float> g = keepLightBiasGuide(bs, lv, al, 5, 1, 4.0);
    EXPECT_EQ(g[0], 0.f);  // no surface: nothing, whatever the bias
    EXPECT_EQ(g[1], 4.f);  // 2 + 4 x 0.5 x 1
    EXPECT_EQ(g[2], 6.f);
    EXPECT_EQ(g[3], 0.f);  // an albedo that is not finite counts as 0
    EXPECT_EQ(g[4], 4.f);  // 2 + 4 x 1 x 0.5
}

// Rule 7's return by hand (9 x 9, one channel): the centre sends 1 at radius 2 over an albedo of
// 1. With a bias guide of 1 on columns 4 and beyond and 0 left of them, the tent's weights
// (3 - |dx|)(3 - |dy|) on the right sum to 9 x 6 = 54: the centre gets 9 / 54, its right
// neighbour 6 / 54, its left one nothing at all. Without rule 7 (biasRadius 0), a bias guide of
// 0 everywhere (its window's sum 0: the albedo takes over) or a window wider than biasRadius,
// the albedo's tent: 6 / 81 on the left.
TEST(KeepLight, AWindowsLightFollowsTheBias) {
    const int w = 9, h = 9, c = 4 * w + 4;
    const std::vector<int> radii = keepLightRadii(4);  // 0, 1, 2, 4
    std::vector<float> robust(w * h, 0.f), albedo(w * h, 1.f), biasGuide(w * h, 0.f),
        none(w * h, 0.f);
    std::vector<double> residual(w * h, 0.0);
    std::vector<uint8_t> scale(w * h, 0);
    residual[c] = 1.0;
    scale[c] = 2;  // radius 2
    for (int y = 0; y < h; ++y)
        for (int x = 4; x < w; ++x) biasGuide[size_t(y * w + x)] = 1.f;
    auto run = [&](const std::vector<float>* bias, int biasRadius, uint8_t k) {
        scale[c] = k;
        std::vector<float> out(w * h);
        returnResidual(robust.data(), residual.data(), scale.data(), radii, w, h, 1, out.data(), 1,
                       albedo.data(), nullptr, nullptr, nullptr, nullptr,
                       bias ? bias->data() : nullptr, biasRadius);
        return out;
    };
    const std::vector<float> byBias = run(&biasGuide, 2, 2);
    EXPECT_FLOAT_EQ(byBias[c], 9.f / 54.f);
    EXPECT_FLOAT_EQ(byBias[c + 1], 6.f / 54.f);
    EXPECT_FLOAT_EQ(byBias[c + 2 - 2 * w], 1.f / 54.f);
    EXPECT_EQ(byBias[c - 1], 0.f);
    double sum = 0.0;
    for (float v : byBias) sum += v;
    EXPECT_NEAR(sum, 1.0, 1e-6);
    const std::vector<float> plain = run(nullptr, 0, 2);
    EXPECT_FLOAT_EQ(plain[c - 1], 6.f / 81.f);
    EXPECT_EQ(run(&biasGuide, 0, 2), plain);
    EXPECT_EQ(run(&none, 2, 2), plain);
    // Radius 4 is beyond biasRadius 2: the albedo's tent (5 - |dx|)(5 - |dy|), whose window is
    // the whole 9 x 9 image: the left neighbour gets 20 / 625.
    const std::vector<float> wide = run(&biasGuide, 2, 3);
    EXPECT_FLOAT_EQ(wide[c - 1], 20.f / 625.f);
}

// The stream's random images send rests (rule 6), so that the stream's tests below cover it.
TEST(KeepLight, RandomImagesHoldSupportedClusters) {
    const Field f = randomField(61, 47, 11);
    std::vector<uint8_t> scale(f.d.size()), restScale(f.d.size());
    std::vector<float> restShare(f.d.size());
    keepLightScales(f.d.data(), f.se.data(), f.robustY.data(), f.active.data(), f.w, f.h, {},
                    scale.data(), 2, restScale.data(), restShare.data());
    EXPECT_GT(std::count_if(restShare.begin(), restShare.end(), [](float v) { return v < 1.f; }),
              5);
}

// The stream (keep_light_stream.h): the whole-image steps over a band at a time.

/// A guide in [0, 1) with black rows (no surface), as the albedo gives it.
std::vector<float> randomGuide(const Field& f, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::vector<float> g(f.d.size());
    for (size_t p = 0; p < g.size(); ++p) g[p] = (p / size_t(f.w)) % 7 == 3 ? 0.f : u(rng);
    return g;
}

/// The whole-image functions as the stream runs them: scales with rule 6's rest, the cluster and
/// light guides, with a guide rule 7's bias guide, the return with every guide.
std::vector<float> wholeImage(const Field& f, const std::vector<float>* guide,
                              const KeepLightParams& p, int nthreads) {
    std::vector<uint8_t> scale(f.d.size()), restScale(f.d.size());
    std::vector<float> restShare(f.d.size()), bias(f.d.size()), level(f.d.size());
    keepLightScales(f.d.data(), f.se.data(), f.robustYOrNull(), f.active.data(), f.w, f.h, p,
                    scale.data(), nthreads, restScale.data(), restShare.data(), bias.data(),
                    level.data());
    const std::vector<float> cluster =
        keepLightClusterGuide(f.robustYOrNull(), f.d.data(), f.w, f.h, nthreads);
    const std::vector<float> light =
        keepLightLightGuide(f.robustYOrNull(), f.d.data(), f.w, f.h, nthreads);
    const std::vector<float> byBias =
        guide ? keepLightBiasGuide(bias.data(), level.data(), guide->data(), f.w, f.h, p.biasFloor)
              : std::vector<float>();
    std::vector<float> out(f.robust.size());
    returnResidual(f.robust.data(), f.residual.data(), scale.data(), keepLightRadii(p.maxRadius),
                   f.w, f.h, 3, out.data(), nthreads, guide ? guide->data() : nullptr,
                   cluster.data(), restScale.data(), restShare.data(), light.data(),
                   guide ? byBias.data() : nullptr, p.biasRadius);
    return out;
}

/// What the stream gives, and the most rows fill ran ahead of take.
struct Streamed {
    std::vector<float> out;
    int mostAhead = 0;
};

Streamed streamed(const Field& f, const std::vector<float>* guide, const KeepLightParams& p,
                  int bandRows, int nthreads) {
    const size_t w = size_t(f.w);
    Streamed s;
    s.out.assign(f.robust.size(), std::numeric_limits<float>::quiet_NaN());
    int filled = 0, taken = 0;
    auto fill = [&](int y0, int y1, const KeepLightBandIn& in) {
        EXPECT_EQ(y0, filled);  // in order, each row once
        for (size_t i = 0; i < size_t(y1 - y0) * w; ++i) {
            const size_t q = size_t(y0) * w + i;
            std::copy_n(f.residual.data() + q * 3, 3, in.residual + i * 3);
            in.d[i] = f.d[q];
            in.se[i] = f.se[q];
            in.robustY[i] = f.robustY.empty() ? 0.f : f.robustY[q];  // 0: no pixel passes
            in.active[i] = f.active[q];
            if (in.guide) in.guide[i] = (*guide)[q];
        }
        filled = y1;
        s.mostAhead = std::max(s.mostAhead, filled - taken);
        return true;
    };
    auto take = [&](int y0, int y1, const double* add) {
        EXPECT_EQ(y0, taken);
        for (size_t i = 0; i < size_t(y1 - y0) * w * 3; ++i) {
            const size_t q = size_t(y0) * w * 3 + i;
            s.out[q] = add[i] != 0.0 ? float(double(f.robust[q]) + add[i]) : f.robust[q];
        }
        taken = y1;
        return true;
    };
    EXPECT_TRUE(keepLightStream(f.w, f.h, 3, guide != nullptr, p, fill, take, nthreads, bandRows));
    EXPECT_EQ(taken, f.h);
    return s;
}

KeepLightParams withRadius(int r) {
    KeepLightParams p;
    p.maxRadius = r;
    return p;
}

// One band holding every row is the whole-image functions, bit for bit.
TEST(KeepLightStream, OneBandIsTheWholeImageBitForBit) {
    const Field f = randomField(61, 47, 11);
    const std::vector<float> guide = randomGuide(f, 11);
    for (const std::vector<float>* g : {static_cast<const std::vector<float>*>(nullptr), &guide}) {
        const std::vector<float> want = wholeImage(f, g, {}, 2);
        const Streamed got = streamed(f, g, {}, 47, 2);
        EXPECT_EQ(std::memcmp(want.data(), got.out.data(), want.size() * sizeof(float)), 0)
            << "guide " << (g != nullptr);
    }
}

// Bands of any height, down to one row, give the whole image's values up to the sums' order (the
// scales and weights are the same: a different choice would move light by whole pixels), conserve
// every channel's light, and never read further ahead than a band and 2 R + 1 rows (2 R + rule
// 7's min(biasRadius, R) with a guide).
TEST(KeepLightStream, BandsGiveTheWholeImageUpToRounding) {
    const Field f = randomField(53, 97, 12);
    const std::vector<float> guide = randomGuide(f, 12);
    for (int r : {0, 1, 4, 32})
        for (const std::vector<float>* g :
             {static_cast<const std::vector<float>*>(nullptr), &guide}) {
            const KeepLightParams p = withRadius(r);
            const std::vector<float> want = wholeImage(f, g, p, 2);
            for (int band : {1, 3, 16, 40}) {
                const Streamed got = streamed(f, g, p, band, 2);
                // Rule 7's bias guide (with a guide) holds the norms back min(16, r) rows more.
                const int halo = std::max(1, r), biasHalo = g && r >= 2 ? std::min(16, r) : 0;
                EXPECT_LE(got.mostAhead, band + 2 * halo + std::max(1, biasHalo))
                    << r << " " << band;
                for (size_t i = 0; i < want.size(); ++i)
                    ASSERT_NEAR(got.out[i], want[i], 1e-6 * std::fabs(want[i]) + 1e-9)
                        << "radius " << r << " band " << band << " guide " << (g != nullptr)
                        << " at " << i;
                for (int c = 0; c < 3; ++c) {
                    double after = 0.0, before = 0.0, size = 0.0;
                    for (size_t q = 0; q < f.d.size(); ++q) {
                        after += got.out[q * 3 + size_t(c)];
                        before += f.robust[q * 3 + size_t(c)] + f.residual[q * 3 + size_t(c)];
                        size += std::fabs(got.out[q * 3 + size_t(c)]);
                    }
                    EXPECT_NEAR(after, before, 1e-6 * size) << r << " " << band << " " << c;
                }
            }
        }
}

TEST(KeepLightStream, SameBitsForAnyThreadCount) {
    const Field f = randomField(71, 203, 13);
    const std::vector<float> guide = randomGuide(f, 13);
    const Streamed one = streamed(f, &guide, {}, 24, 1);
    for (int t : {2, 3, 8}) {
        const Streamed many = streamed(f, &guide, {}, 24, t);
        EXPECT_EQ(std::memcmp(one.out.data(), many.out.data(), one.out.size() * sizeof(float)), 0)
            << t;
    }
}

// A tall image holds no more than a short one: fill stays a band and 2 R + 1 rows ahead of take
// (what the stream holds is those rows and R more behind), whatever the height.
TEST(KeepLightStream, HoldsAFewBandsWhateverTheHeight) {
    for (int h : {300, 3000}) {
        const Field f = randomField(8, h, 14);
        const Streamed got = streamed(f, nullptr, withRadius(8), 32, 2);
        EXPECT_LE(got.mostAhead, 32 + 2 * 8 + 1) << h;
        EXPECT_GE(got.mostAhead, 32) << h;  // a band is filled whole
    }
}

// The extremes by bands: images of one row, one column, one pixel, fewer rows than the radius;
// NaN and infinite residuals and a firefly of 1e38 on the bands' boundaries. Every band height
// gives the whole image's values (to float rounding) and only finite ones.
TEST(KeepLightStream, ExtremeShapesAndValues) {
    for (const auto& [w, h, r] :
         {std::array<int, 3>{1, 1, 32}, std::array<int, 3>{1, 50, 4}, std::array<int, 3>{50, 1, 4},
          std::array<int, 3>{7, 5, 1024}, std::array<int, 3>{9, 40, 2}}) {
        Field f = randomField(w, h, 16);
        const double inf = std::numeric_limits<double>::infinity();
        for (int y = 0; y < h; y += 3) {  // every third row: a boundary of bands of 1 and 3 rows
            const size_t p = f.at(w / 2, y);
            f.residual[p * 3] = y % 2 ? std::numeric_limits<double>::quiet_NaN() : 1e38;
            f.residual[p * 3 + 1] = y % 2 ? inf : -1e38;
            f.d[p] = y % 2 ? std::numeric_limits<float>::quiet_NaN() : 1e38f;
            f.se[p] = y % 2 ? std::numeric_limits<float>::infinity() : 1e38f;
            f.active[p] = 1;
            // The robust luminance beside it: NaN, infinite, 1e38 (the edge test's median).
            f.robustY[f.at(w / 3, y)] =
                y % 3 ? std::numeric_limits<float>::quiet_NaN()
                      : (y % 2 ? 1e38f : -std::numeric_limits<float>::infinity());
        }
        const KeepLightParams p = withRadius(r);
        const std::vector<float> want = wholeImage(f, nullptr, p, 2);
        for (int band : {1, 3, h}) {
            const Streamed got = streamed(f, nullptr, p, band, 2);
            for (size_t i = 0; i < want.size(); ++i) {
                ASSERT_TRUE(std::isfinite(got.out[i])) << w << "x" << h << " band " << band;
                ASSERT_NEAR(got.out[i], want[i], 1e-6 * std::fabs(want[i]) + 1e-9)
                    << w << "x" << h << " radius " << r << " band " << band << " at " << i;
            }
        }
    }
}

// A firefly of 1e38 in the middle of a tall image returned by bands of 5 rows: the rows beyond
// its window keep the robust values bit for bit, those within it all got light.
TEST(KeepLightStream, RowsBeyondTheWindowAreUntouched) {
    Field f(3, 200, 3);
    for (size_t i = 0; i < f.robust.size(); ++i) f.robust[i] = 0.1f * float(i % 7);
    const size_t p = f.at(1, 100);
    for (int c = 0; c < 3; ++c) f.residual[p * 3 + size_t(c)] = 1e38;
    f.d[p] = f.se[p] = 1e38f;
    f.active[p] = 1;
    const Streamed got = streamed(f, nullptr, {}, 5, 2);
    const int R = KeepLightParams().maxRadius;
    for (int y = 0; y < 200; ++y)
        for (size_t i = f.at(0, y) * 3; i < f.at(0, y + 1) * 3; ++i) {
            if (std::abs(y - 100) <= R) {
                EXPECT_GT(got.out[i], f.robust[i]) << y;
                EXPECT_TRUE(std::isfinite(got.out[i])) << y;
            } else {
                EXPECT_EQ(got.out[i], f.robust[i]) << y;  // exactly
            }
        }
}

// A false from fill or from take ends the stream with false, and nothing is called after it.
TEST(KeepLightStream, FalseFromTheCallerStopsIt) {
    const Field f = randomField(10, 100, 15);
    for (const bool fillFails : {true, false}) {
        int fills = 0, takes = 0;
        // Bands of 10 rows, radius 2: the first band's rows 0 to 5 are returned once it is filled.
        auto fill = [&](int, int, const KeepLightBandIn&) { return ++fills < 2 || !fillFails; };
        auto take = [&](int, int, const double*) { return ++takes < 1 || fillFails; };
        EXPECT_FALSE(keepLightStream(f.w, f.h, 3, false, withRadius(2), fill, take, 2, 10));
        EXPECT_EQ(fills, fillFails ? 2 : 1);
        EXPECT_EQ(takes, 1);
    }
}

}  // namespace
}  // namespace mcstat
