// Cascade reweighting (Zirr, Hanika and Dachsbacher 2018; filters/samples/cascade_reweighting.cpp)
// on cases worked by hand: the split of a sample between two cascades, the extremes, a 3x3 image
// whose reweighted centre is computed below line by line, a partial weight, and the convergence to
// the mean as the counts grow.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "mcstat/core/params.h"
#include "mcstat/filters/registry.h"
#include "mcstat/filters/samples/cascade_reweighting.h"
#include "mcstat/filters/samples/cascade_reweighting_operation.h"

namespace mcstat {
namespace {

/// Luminance weights that make a grey sample's luminance its value.
ReweightParams grey(int count = 6, double kappa = 32.0) {
    ReweightParams p;
    p.count = count;
    p.kappa = kappa;
    p.luma = {0.25, 0.5, 0.25};
    return p;
}

TEST(ReweightSplit, BoundariesAndBetween) {
    const ReweightParams p = grey();  // scales 1, 8, 64, 512, 4096, 32768
    // Exactly at a boundary: the sample is the upper cascade's whole (8 is cascade 1's scale).
    CascadeSplit s = splitSample(8.0, p);
    EXPECT_EQ(s.lower, 1);
    EXPECT_EQ(s.wLower, 1.0);
    EXPECT_EQ(s.wUpper, 0.0);
    s = splitSample(1.0, p);
    EXPECT_EQ(s.lower, 0);
    EXPECT_EQ(s.wLower, 1.0);
    // Between 1 and 8: wLower = (1/y - 1/8) / (1 - 1/8). y = 2: (0.5 - 0.125) / 0.875 = 3/7, and
    // the sample counts 3/7 * 2/1 + 4/7 * 2/8 = 6/7 + 1/7 = 1.
    s = splitSample(2.0, p);
    EXPECT_EQ(s.lower, 0);
    EXPECT_NEAR(s.wLower, 3.0 / 7.0, 1e-15);
    EXPECT_NEAR(s.wUpper, 4.0 / 7.0, 1e-15);
    // y = 4: (0.25 - 0.125) / 0.875 = 1/7.
    s = splitSample(4.0, p);
    EXPECT_NEAR(s.wLower, 1.0 / 7.0, 1e-15);
    EXPECT_NEAR(s.wUpper, 6.0 / 7.0, 1e-15);
    // y = 100 between 64 and 512: cascades 2 and 3, count exactly 1.
    s = splitSample(100.0, p);
    EXPECT_EQ(s.lower, 2);
    EXPECT_NEAR(s.wLower * 100.0 / 64.0 + s.wUpper * 100.0 / 512.0, 1.0, 1e-15);
    // Zero and negative luminance: cascade 0 whole.
    for (double y : {0.0, -3.0, 0.5}) {
        s = splitSample(y, p);
        EXPECT_EQ(s.lower, 0) << y;
        EXPECT_EQ(s.wLower, 1.0) << y;
        EXPECT_EQ(s.wUpper, 0.0) << y;
    }
    // Above the top scale 32768: the top cascade, clamped to its luminance.
    s = splitSample(65536.0, p);
    EXPECT_EQ(s.lower, 4);
    EXPECT_EQ(s.wLower, 0.0);
    EXPECT_EQ(s.wUpper, 0.5);
}

TEST(ReweightSplat, NonFiniteIsSkippedAndCountedHugeIsClamped) {
    const ReweightParams p = grey();
    CascadePixel px;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float inf = std::numeric_limits<float>::infinity();
    const float bad[][3] = {{nan, 1.f, 1.f}, {1.f, inf, 1.f}, {-inf, 0.f, 0.f}};
    for (const auto& b : bad) splatSample(px, b, p);
    EXPECT_EQ(px.skipped, 3u);
    EXPECT_EQ(px.n, 0u);
    // 1e38 grey: luminance 1e38, clamped to the top scale 32768 in every channel.
    const float huge[3] = {1e38f, 1e38f, 1e38f};
    splatSample(px, huge, p);
    EXPECT_EQ(px.n, 1u);
    EXPECT_NEAR(px.sum[5 * 3 + 0], 32768.0, 32768.0 * 1e-7);
    // A zero and a negative sample: cascade 0, as they are.
    const float zero[3] = {0.f, 0.f, 0.f}, neg[3] = {-2.f, -2.f, -2.f};
    splatSample(px, zero, p);
    splatSample(px, neg, p);
    EXPECT_EQ(px.n, 3u);
    EXPECT_EQ(px.sum[0], -2.0);
}

/// A width x height image of `count` cascades from every pixel's grey samples.
CascadeImage imageOf(int w, int h, const ReweightParams& p,
                     const std::vector<std::vector<float>>& samples) {
    CascadeImage img;
    img.width = w;
    img.height = h;
    img.count = p.count;
    for (const std::vector<float>& px : samples) {
        CascadePixel c;
        c.sum.assign(size_t(p.count) * 3, 0.0);
        for (float v : px) {
            const float rgb[3] = {v, v, v};
            splatSample(c, rgb, p);
        }
        img.sum.insert(img.sum.end(), c.sum.begin(), c.sum.end());
        img.n.push_back(c.n);
    }
    return img;
}

TEST(Reweight, ALoneFireflyInA3x3ImageIsRemovedByHand) {
    // 3 cascades (scales 1, 8, 64), kappa 1 (1/kappa = 1, the colour factor mix(.., 1, 1) = 1).
    // Every pixel has four samples of 1 (S_0 = 4); the centre has three and one firefly of 64,
    // which is cascade 2's whole (64 is its scale): S_0 = 3, S_2 = 64, N = 4, mean 16.75.
    const ReweightParams p = grey(3, 1.0);
    std::vector<std::vector<float>> s(9, std::vector<float>{1, 1, 1, 1});
    s[4] = {1, 1, 64, 1};
    const CascadeImage img = imageOf(3, 3, p, s);
    EXPECT_EQ(img.sum[(4 * 3 + 2) * 3], 64.0);
    std::vector<float> out;
    std::vector<double> w;
    reweightImage(img, p, out, &w);
    // Centre, cascade 0: counts c_0 = S_0 + S_1/8 = 3 here, 4 around; block mean 35/9 - 1 >= 0,
    // so r = local - 1 = 2, w_0 = clamp((2 + colour) / 2) = 1; E = 3/4.
    // Cascade 1: c_1 = S_0 + S_1/8 + S_2/64 = 4, w_1 = 1, S_1 = 0: E stays 3/4.
    // Cascade 2: c_2 = S_1/8 + S_2/64 = 1 here, 0 around: global = 1/9 - 1 < 0, so r = -8/9;
    // colour = max(0.75, 0.05) * N / (kappa * 64) = 0.046875; w_2 = clamp((-8/9 + 0.046875)/2) = 0.
    EXPECT_EQ(w[4 * 3 + 0], 1.0);
    EXPECT_EQ(w[4 * 3 + 1], 1.0);
    EXPECT_EQ(w[4 * 3 + 2], 0.0);
    EXPECT_FLOAT_EQ(out[4 * 3 + 0], 0.75f);
    // Every other pixel keeps its mean 1 (a corner's clamped block holds the centre once).
    for (int q : {0, 1, 2, 3, 5, 6, 7, 8}) EXPECT_FLOAT_EQ(out[size_t(q) * 3 + 1], 1.f) << q;
}

TEST(Reweight, SpreadKeepsTheImagesEnergy) {
    // The 3x3 image with the centre's firefly (above), kappa 1, spread 1: the centre's removed
    // 64/4 = 16 is scattered evenly over its 3x3 window (16/9 each); the image's total is the
    // mean's. Spread 2 on a 3x3 image: every pixel's window is the whole image.
    ReweightParams p = grey(3, 1.0);
    std::vector<std::vector<float>> s(9, std::vector<float>{1, 1, 1, 1});
    s[4] = {1, 1, 64, 1};
    const double meanTotal = 8 * 1.0 + 16.75;
    for (int r : {1, 2}) {
        p.spread = r;
        std::vector<float> out;
        reweightImage(imageOf(3, 3, p, s), p, out);
        double total = 0;
        for (size_t q = 0; q < 9; ++q) total += out[q * 3];
        EXPECT_NEAR(total, meanTotal, 1e-5) << r;
        EXPECT_NEAR(out[4 * 3], 0.75 + 16.0 / 9.0, 1e-5) << r;
        EXPECT_NEAR(out[0], 1.0 + 16.0 / 9.0, 1e-5) << r;
    }
}

TEST(Reweight, APartialWeightByHand) {
    // 3 cascades, kappa 4: colour factor = (1 + 0.6 * 7) * (1 - 1/4) + 1/4 = 4.15. Every pixel of
    // a 3x3 image has seven samples of 1 and one of 64 (N = 8; block = local everywhere).
    // Cascade 0: c_0 = 7, r = 7/4 - 1/4 = 1.5; colour = 0.05 * 8 / (4 * 1) * 4.15 = 0.415;
    //   w_0 = (1.5 + 0.415) / 2 = 0.9575 (even the base is cut at N = 2 kappa); E = 0.8378125.
    // Cascade 1: c_1 = 7 + 64/64 = 8, r = 1.75: w_1 = 1 (S_1 = 0 anyway).
    // Cascade 2: c_2 = 64/64 = 1, global = local = 1/4: r = 1/4 - 1/4 = 0; colour =
    //   0.8378125 * 8 / (4 * 64) * 4.15 = 0.10865380859375; w_2 = 0.054326904296875;
    //   E = 0.8378125 + w_2 * 64 / 8 = 1.272427734375 (the mean is 8.875).
    const ReweightParams p = grey(3, 4.0);
    const std::vector<std::vector<float>> s(9, std::vector<float>{1, 1, 1, 64, 1, 1, 1, 1});
    std::vector<float> out;
    std::vector<double> w;
    reweightImage(imageOf(3, 3, p, s), p, out, &w);
    for (size_t q = 0; q < 9; ++q) {
        EXPECT_NEAR(w[q * 3 + 0], 0.9575, 1e-7) << q;
        EXPECT_EQ(w[q * 3 + 1], 1.0) << q;
        EXPECT_NEAR(w[q * 3 + 2], 0.054326904296875, 1e-7) << q;
        EXPECT_NEAR(out[q * 3], 1.272427734375, 1e-6) << q;
    }
}

TEST(Reweight, HighCountsGiveTheMean) {
    // One sample of 100 in every 64 (the rest 1), defaults (kappa 32): with N = 64 the bright
    // sample's cascades hold one count and are down-weighted; with N = 64 * 64 they hold 64 >
    // kappa + 1 and every weight is 1, so the estimate is the mean.
    const ReweightParams p = grey();
    auto estimate = [&](int copies) {
        std::vector<float> px;
        for (int k = 0; k < copies; ++k) {
            px.push_back(100.f);
            for (int i = 0; i < 63; ++i) px.push_back(1.f);
        }
        std::vector<float> out;
        reweightImage(imageOf(3, 3, p, std::vector<std::vector<float>>(9, px)), p, out);
        return double(out[4 * 3]);
    };
    const double mean = (100.0 + 63.0) / 64.0;
    const double few = estimate(1), many = estimate(64);
    EXPECT_LT(few, 0.5 * mean);  // at 64 samples even cascade 0 (count 63 < 2 kappa) is cut
    EXPECT_NEAR(many, mean, 1e-6 * mean);
    // In between the estimate rises towards the mean.
    double last = few;
    for (int copies : {2, 4, 8, 16, 32}) {
        const double e = estimate(copies);
        EXPECT_GE(e, last - 1e-9) << copies;
        last = e;
    }
}

TEST(Reweight, NoSamplesIsZeroAndOneSampleRestsOnTheColorTerm) {
    std::vector<std::vector<float>> s(4, std::vector<float>{3.f});  // 2x2, one sample each
    s[0].clear();                                                   // pixel 0: none
    // spp = 1: a pixel's one sample counts exactly 1 in its cascades' counts, so where the block
    // is as dense as the pixel, r = 1/kappa - 1/kappa = 0 and only the colour term (at most
    // 0.05 N / (kappa s_i) times the factor, halved) weights it: the estimate is in [0, 3].
    ReweightParams p = grey(6, 0.5);
    std::vector<float> out;
    reweightImage(imageOf(2, 2, p, s), p, out);
    EXPECT_EQ(out[0], 0.f);
    for (size_t q = 1; q < 4; ++q) {
        EXPECT_GE(out[q * 3], 0.f) << q;
        EXPECT_LT(out[q * 3], 3.f) << q;
    }
    // kappa <= 1e-6 is the reference implementation's "off" switch: every weight 1, the mean.
    p.kappa = 1e-7;
    reweightImage(imageOf(2, 2, p, s), p, out);
    EXPECT_EQ(out[0], 0.f);
    for (size_t q = 1; q < 4; ++q) EXPECT_FLOAT_EQ(out[q * 3], 3.f) << q;
}

/// A 37 x 23 image of noisy samples with fireflies (luminances over five orders of magnitude):
/// cascade sums that are not exact, so any change in the order of a sum shows in the bits.
CascadeImage fireflyImage(const ReweightParams& p) {
    std::mt19937 gen(52);
    std::uniform_real_distribution<float> u(0, 1);
    std::vector<std::vector<float>> s(37 * 23);
    for (size_t q = 0; q < s.size(); ++q) {
        const int n = q % 29 == 3 ? 0 : 3 + int(q % 6);  // some pixels without samples
        for (int i = 0; i < n; ++i)
            s[q].push_back(u(gen) < 0.08f ? 10.f + 3000.f * u(gen) : 0.05f + 1.7f * u(gen));
    }
    return imageOf(37, 23, p, s);
}

TEST(Reweight, OneThreadAndFourGiveTheSameBytes) {
    // The image-wide steps run on threads (rows of pixels handed out as threads free up); the
    // estimate and the weights must be the bytes of one thread, with and without the spread.
    for (int spread : {0, 3}) {
        ReweightParams p = grey(6, 4.0);
        p.spread = spread;
        const CascadeImage img = fireflyImage(p);
        std::vector<float> rgb1;
        std::vector<double> w1;
        reweightImage(img, p, rgb1, &w1, 1);
        for (int threads : {3, 4}) {
            std::vector<float> rgb;
            std::vector<double> w;
            reweightImage(img, p, rgb, &w, threads);
            ASSERT_EQ(rgb.size(), rgb1.size());
            EXPECT_EQ(std::memcmp(rgb.data(), rgb1.data(), rgb.size() * sizeof(float)), 0)
                << spread << " " << threads;
            ASSERT_EQ(w.size(), w1.size());
            EXPECT_EQ(std::memcmp(w.data(), w1.data(), w.size() * sizeof(double)), 0)
                << spread << " " << threads;
        }
    }
}

TEST(Reweight, TheSpreadGathersInTheScatterOrder) {
    // scatterRemoved gathers each pixel's shares (so threads never add into one pixel); the sums
    // must equal, bit for bit, the scatter over the pixels in scanline order (written out here),
    // on 1, 3 and 4 threads. And the order matters on these values: the same scatter over the
    // pixels backwards gives other bits, so a sum whose order followed the threads would fail.
    const int W = 37, H = 23, r = 3;
    const size_t nch = 2;
    std::mt19937 gen(7);
    std::uniform_real_distribution<double> u(0, 1);
    std::vector<double> removed(size_t(W * H) * nch);
    for (double& v : removed) v = u(gen) < 0.1 ? 500 * u(gen) : u(gen) - 0.3;
    auto scatter = [&](bool backwards) {
        std::vector<double> add(removed.size(), 0.0);
        for (int k = 0; k < W * H; ++k) {
            const int pix = backwards ? W * H - 1 - k : k, x = pix % W, y = pix / W;
            const int x0 = std::max(0, x - r), x1 = std::min(W - 1, x + r);
            const int y0 = std::max(0, y - r), y1 = std::min(H - 1, y + r);
            const double share = 1.0 / double((x1 - x0 + 1) * (y1 - y0 + 1));
            for (int qy = y0; qy <= y1; ++qy)
                for (int qx = x0; qx <= x1; ++qx)
                    for (size_t c = 0; c < nch; ++c)
                        add[size_t(qy * W + qx) * nch + c] +=
                            share * removed[size_t(pix) * nch + c];
        }
        return add;
    };
    const std::vector<double> want = scatter(false), other = scatter(true);
    for (int threads : {1, 3, 4}) {
        std::vector<double> add;
        scatterRemoved(W, H, r, nch, removed, add, threads);
        ASSERT_EQ(add.size(), want.size());
        EXPECT_EQ(std::memcmp(add.data(), want.data(), add.size() * sizeof(double)), 0) << threads;
    }
    EXPECT_NE(std::memcmp(other.data(), want.data(), want.size() * sizeof(double)), 0);
}

TEST(ReweightParamsCheck, BadParametersAreOneLineNamingThem) {
    const Operation* op = findOperation("reweight");
    ASSERT_NE(op, nullptr);
    ParamValues v;
    std::string err;
    EXPECT_FALSE(parseOperationParams(*op, {{"base", "1"}}, v, err));
    EXPECT_NE(err.find("base must be"), std::string::npos) << err;
    EXPECT_EQ(err.find('\n'), std::string::npos);
    EXPECT_FALSE(parseOperationParams(*op, {{"kappa", "-1"}}, v, err));
    EXPECT_NE(err.find("kappa must be"), std::string::npos) << err;
    EXPECT_FALSE(parseOperationParams(*op, {{"count", "40"}}, v, err));
    EXPECT_NE(err.find("count must be"), std::string::npos) << err;
    EXPECT_FALSE(parseOperationParams(*op, {{"kapa", "3"}}, v, err));
    EXPECT_NE(err.find("kapa"), std::string::npos) << err;
    ASSERT_TRUE(parseOperationParams(*op, {{"luma", "1,2"}}, v, err)) << err;
    ReweightParams p;
    EXPECT_FALSE(reweightParamsFrom(v, {0.2, 0.7, 0.1}, p, err));
    EXPECT_NE(err.find("luma must be three weights"), std::string::npos) << err;
    // Defaults of the reference implementation.
    ASSERT_TRUE(parseOperationParams(*op, {}, v, err)) << err;
    ASSERT_TRUE(reweightParamsFrom(v, {0.2126, 0.7152, 0.0722}, p, err)) << err;
    EXPECT_EQ(p.count, 6);
    EXPECT_EQ(p.base, 8.0);
    EXPECT_EQ(p.start, 1.0);
    EXPECT_EQ(p.kappa, 32.0);
}

TEST(ReweightState, EncodeDecodeRoundTripsBitForBit) {
    ReweightParams p = grey(4, 2.0);
    p.base = 5.5;
    const CascadeImage img = imageOf(2, 1, p, {{1.f, 7.f, 1e6f, 0.3f}, {}});
    PixelStateParts parts;
    std::string err;
    ASSERT_TRUE(encodeCascadeState(img, {2, 0}, p, parts, err)) << err;
    EXPECT_EQ(parts.owner.operation, "reweight");
    EXPECT_EQ(parts.owner.params, "base=5.5:count=4:luma=0.25,0.5,0.25:start=1");
    CascadeImage back;
    std::vector<uint64_t> skipped;
    ReweightParams q;
    ASSERT_TRUE(decodeCascadeState(parts, 2, back, skipped, q, err)) << err;
    EXPECT_EQ(back.sum, img.sum);
    EXPECT_EQ(back.n, img.n);
    EXPECT_EQ(skipped, (std::vector<uint64_t>{2, 0}));
    EXPECT_EQ(q.count, 4);
    EXPECT_EQ(q.base, 5.5);
    EXPECT_EQ(q.luma[1], 0.5);
}

}  // namespace
}  // namespace mcstat
