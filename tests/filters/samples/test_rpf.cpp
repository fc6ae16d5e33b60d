// Random parameter filtering (Sen & Darabi 2011, implementation report): the pieces on cases
// worked by hand — mutual information (eq. 1), the colour and feature weights (eq. 9-16), the
// clustering of section 4.2, the blend of eq. 20 — and the filter's determinism.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>
#include <vector>

#include "mcstat/filters/samples/rpf_filter.h"

namespace mcstat {
namespace {

TEST(RpfMutualInformation, IndependentVariablesShareNothing) {
    // x = i mod 2 and y = (i / 2) mod 2: every joint bin holds 1/4, the product of the marginals.
    std::vector<float> x, y;
    for (int i = 0; i < 400; ++i) {
        x.push_back(float(i % 2));
        y.push_back(float((i / 2) % 2));
    }
    EXPECT_NEAR(mutualInformation(x.data(), y.data(), x.size()), 0.0, 1e-12);
}

TEST(RpfMutualInformation, IdenticalVariablesShareTheirEntropy) {
    // Four equally likely bins: mu(X; X) = H(X) = log 4.
    std::vector<float> x;
    for (int i = 0; i < 400; ++i) x.push_back(float(i % 4));
    EXPECT_NEAR(mutualInformation(x.data(), x.data(), x.size()), std::log(4.0), 1e-12);
}

TEST(RpfMutualInformation, HandWorkedJointTable) {
    // Pairs (0,0), (0,0), (1,1), (1,0): p(x) = 1/2, 1/2; p(y) = 3/4, 1/4.
    // mu = 1/2 log((1/2)/(1/2*3/4)) + 1/4 log((1/4)/(1/2*1/4)) + 1/4 log((1/4)/(1/2*3/4)).
    const std::vector<float> x{0, 0, 1, 1}, y{0, 0, 1, 0};
    const double want =
        0.5 * std::log(4.0 / 3.0) + 0.25 * std::log(2.0) + 0.25 * std::log(2.0 / 3.0);
    EXPECT_NEAR(mutualInformation(x.data(), y.data(), 4), want, 1e-12);
    // Symmetric.
    EXPECT_NEAR(mutualInformation(y.data(), x.data(), 4), want, 1e-12);
}

TEST(RpfMutualInformation, BinsByRoundingAfterTheMinimum) {
    // Section 5.1: subtract the minimum, round. 0.2 and 0.6 share bin 0 (0.4 rounds down); 0.2
    // and 0.8 do not (0.6 rounds up), so y below is fully informative about x only in the second.
    const std::vector<float> x{0, 0, 1, 1};
    const std::vector<float> same{0.2f, 0.6f, 0.2f, 0.6f}, apart{0.2f, 0.2f, 0.8f, 0.8f};
    EXPECT_NEAR(mutualInformation(x.data(), same.data(), 4), 0.0, 1e-12);
    EXPECT_NEAR(mutualInformation(x.data(), apart.data(), 4), std::log(2.0), 1e-12);
}

/// Normalised samples (section 4.3) of a layout with n random parameters and m features.
std::vector<float> normalised(std::vector<float> xs, int dims) {
    const size_t n = xs.size() / size_t(dims);
    for (int d = 0; d < dims; ++d) {
        double m = 0, q = 0;
        for (size_t i = 0; i < n; ++i) m += xs[i * size_t(dims) + size_t(d)];
        m /= double(n);
        for (size_t i = 0; i < n; ++i) q += std::pow(xs[i * size_t(dims) + size_t(d)] - m, 2);
        const double sd = std::sqrt(q / double(n));
        for (size_t i = 0; i < n; ++i) {
            float& v = xs[i * size_t(dims) + size_t(d)];
            v = sd > 0 ? float((v - m) / sd) : 0.f;
        }
    }
    return xs;
}

TEST(RpfWeights, ColorDrivenOnlyByARandomParameterGetsNoColorWeight) {
    // Colour = the random parameter (e.g. the light sample: a penumbra); screen position and the
    // feature are independent of it. Eq. 10 gives W_c,k^r near 1, so eq. 15 clamps alpha to 0:
    // the bilateral filter ignores colour differences here.
    RpfLayout L;
    L.randoms = 1;
    L.features = 1;
    L.isPosition = {false};
    std::mt19937 gen(7);
    std::uniform_real_distribution<float> u(0, 1);
    std::vector<float> xs;
    for (int i = 0; i < 3000; ++i) {
        const float r = u(gen);
        xs.insert(xs.end(), {r, r, r, 8 * u(gen), 8 * u(gen), r, u(gen)});
    }
    const RpfWeights w = rpfFeatureWeights(L, normalised(xs, L.dims()).data(), 3000, 0);
    for (int k = 0; k < 3; ++k) {
        EXPECT_GT(w.colorChannelOnRandom[size_t(k)], 0.95);
        EXPECT_EQ(w.alpha[size_t(k)], 0.0);
    }
    EXPECT_GT(w.colorOnRandom, 0.95);
}

TEST(RpfWeights, ColorDrivenOnlyByTheTextureFeatureWeighsThatFeature) {
    // The report's Fig. 6 case: colour = texture value, the texture a function of screen position
    // only (a checker over x); a second feature is noise drawn from the random parameter. The
    // texture gets a high beta (eq. 16); the noise feature, dependent on r (eq. 9), gets ~0.
    RpfLayout L;
    L.randoms = 1;
    L.features = 2;
    L.isPosition = {false, false};
    std::mt19937 gen(11);
    std::uniform_real_distribution<float> u(0, 1);
    std::vector<float> xs;
    for (int i = 0; i < 3000; ++i) {
        const float px = 16 * u(gen), py = 16 * u(gen), r = u(gen);
        const float tex = (int(std::floor(px / 2)) % 2) ? 0.8f : 0.2f;
        xs.insert(xs.end(), {tex, tex, tex, px, py, r, tex, r});
    }
    const RpfWeights w = rpfFeatureWeights(L, normalised(xs, L.dims()).data(), 3000, 0);
    EXPECT_LT(w.featureOnRandom[0], 0.05);  // the texture does not depend on r
    EXPECT_GT(w.featureOnRandom[1], 0.95);  // the noise feature does
    EXPECT_GT(w.beta[0], 0.3);
    EXPECT_LT(w.beta[1], 0.02);
    EXPECT_GT(w.beta[0], 20 * w.beta[1]);
    // Colour does not depend on r: alpha stays near 1 (eq. 15 at t = 0).
    for (int k = 0; k < 3; ++k) EXPECT_GT(w.alpha[size_t(k)], 0.9);
    // Eq. 16 by hand from the reported fractions.
    EXPECT_NEAR(w.beta[0], w.colorOnFeature[0] * std::max(1.0 - w.featureOnRandom[0], 0.0), 1e-12);
}

TEST(RpfWeights, LaterPassesWeighTheRandomShareMore) {
    // Eq. 15-16: (1 + 0.1 t) grows with the pass; the same neighbourhood gives a smaller alpha.
    RpfLayout L;
    L.randoms = 1;
    L.features = 1;
    L.isPosition = {false};
    std::mt19937 gen(3);
    std::uniform_real_distribution<float> u(0, 1);
    std::vector<float> xs;
    for (int i = 0; i < 3000; ++i) {
        const float px = 8 * u(gen), r = u(gen), c = 0.5f * r + 0.5f * (px / 8);
        xs.insert(xs.end(), {c, c, c, px, 8 * u(gen), r, u(gen)});
    }
    const std::vector<float> nx = normalised(xs, L.dims());
    const RpfWeights w0 = rpfFeatureWeights(L, nx.data(), 3000, 0);
    const RpfWeights w3 = rpfFeatureWeights(L, nx.data(), 3000, 3);
    EXPECT_EQ(w0.colorChannelOnRandom[0], w3.colorChannelOnRandom[0]);
    const double wcr = w0.colorChannelOnRandom[0];
    EXPECT_NEAR(w0.alpha[0], std::max(1 - 2 * wcr, 0.0), 1e-12);
    EXPECT_NEAR(w3.alpha[0], std::max(1 - 2 * 1.3 * wcr, 0.0), 1e-12);
}

/// A window of `width` x `height` pixels, `spp` samples each, one random parameter and features
/// N1.X (a surface id stand-in) and a noise feature.
RpfWindow makeWindow(int width, int height, int spp, uint32_t seed,
                     const std::function<void(int, int, int, float*)>& fill) {
    RpfWindow w;
    w.width = width;
    w.height = height;
    w.y0 = 0;
    w.rows = height;
    w.layout.randoms = 1;
    w.layout.features = 2;
    w.layout.isPosition = {false, false};
    std::mt19937 gen(seed);
    std::uniform_real_distribution<float> u(0, 1);
    w.offset.push_back(0);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            for (int i = 0; i < spp; ++i) {
                float s[8] = {0, 0, 0, x + u(gen), y + u(gen), u(gen), 0, u(gen)};
                fill(x, y, i, s);
                w.x.insert(w.x.end(), s, s + 8);
            }
            w.offset.push_back(w.offset.back() + uint64_t(spp));
        }
    return w;
}

TEST(RpfFilter, ClusteringDropsSamplesFromAnotherSurface) {
    // Colour is noise from the random parameter everywhere. The centre pixel lies on surface A
    // (feature 0 = 1, no spread), the others on surface B (feature 0 = 0). Section 4.2, with the
    // 0.1 floor (sigma_P is 0 here), keeps none of them: N = P, and the result equals a pass
    // whose box holds the pixel alone. When the neighbours are on surface A too, they join N.
    RpfParams p;
    p.boxes = {7};
    RpfParams alone = p;
    alone.boxes = {1};  // M = 1 x 8 x 1/2 < s: no draws
    for (bool sameSurface : {false, true}) {
        const RpfWindow w = makeWindow(9, 9, 8, 5, [&](int x, int y, int, float* s) {
            const bool centre = x == 4 && y == 4;
            s[0] = s[1] = s[2] = s[5];
            s[6] = centre || sameSurface ? 1.f : 0.f;
        });
        std::vector<float> c(w.samples() * 3);
        for (size_t i = 0; i < w.samples(); ++i) std::copy_n(w.sample(i), 3, c.data() + i * 3);
        std::vector<float> out = c, own = c;
        std::vector<RpfPixelReport> report;
        rpfPass(w, p, 0, c, out, 4, 5, 1, &report);
        rpfPass(w, alone, 0, c, own, 4, 5, 1);
        const RpfPixelReport& centre = report[4];
        const size_t first = size_t(w.offset[4 * 9 + 4]);
        if (!sameSurface) {
            EXPECT_EQ(centre.neighbours, 8);
            for (size_t i = first * 3; i < (first + 8) * 3; ++i) EXPECT_EQ(out[i], own[i]);
        } else {
            EXPECT_GT(centre.neighbours, 8 + 100);  // 7 x 7 x 8 / 2 - 8 draws, most kept
            EXPECT_NE(out[first * 3], own[first * 3]);
        }
    }
}

TEST(RpfFilter, KeptStopsTheDrawsOnceNHoldsThatMany) {
    // One surface, so every draw inside the image is kept. Box 15 at 8 spp: M = 15 x 15 x 8 / 2 =
    // 900, 892 draws. Without a bound N holds most of them; with kept = 300 drawing stops at 300
    // (the pixel's 8 included), which changes the filtered colours; a bound no draw reaches
    // (kept = M) changes nothing, bit for bit.
    const RpfWindow w = makeWindow(31, 31, 8, 17, [](int, int, int, float* s) {
        s[0] = s[1] = s[2] = 3 * s[5];
        s[6] = 1.f;
    });
    std::vector<float> c(w.samples() * 3);
    for (size_t i = 0; i < w.samples(); ++i) std::copy_n(w.sample(i), 3, c.data() + i * 3);
    auto pass = [&](int64_t kept, std::vector<RpfPixelReport>& report) {
        RpfParams p;
        p.boxes = {15};
        p.maxKept = kept;
        std::vector<float> out = c;
        rpfPass(w, p, 0, c, out, 15, 16, 1, &report);
        return out;
    };
    std::vector<RpfPixelReport> none, bound, unreached;
    const std::vector<float> all = pass(0, none), some = pass(300, bound),
                             same = pass(900, unreached);
    const size_t centre = 15, first = size_t(w.offset[15 * 31 + 15]);
    EXPECT_GT(none[centre].neighbours, 600);  // 892 draws, a few beyond the image's edge or on P
    EXPECT_EQ(bound[centre].neighbours, 300);
    EXPECT_EQ(unreached[centre].neighbours, none[centre].neighbours);
    EXPECT_EQ(same, all);
    EXPECT_NE(some[first * 3], all[first * 3]);
    for (const RpfPixelReport& r : bound) EXPECT_LE(r.neighbours, 300);
}

TEST(RpfFilter, KeepsTheEnergyOfAConstantImage) {
    // Eq. 20 is a normalised weighted mean: on a constant colour every filtered sample, and so
    // every pixel, keeps that colour whatever the weights.
    const RpfWindow w = makeWindow(24, 20, 4, 9, [](int, int, int, float* s) {
        s[0] = 0.37f;
        s[1] = 1.5f;
        s[2] = 1e-3f;
        s[6] = s[3] > 12 ? 1.f : 0.f;
    });
    RpfParams p;
    std::vector<float> rgb;
    rpfFilterRows(w, p, 0, 20, rgb, 2);
    ASSERT_EQ(rgb.size(), size_t(24 * 20 * 3));
    for (size_t i = 0; i < rgb.size(); i += 3) {
        ASSERT_FLOAT_EQ(rgb[i], 0.37f);
        ASSERT_FLOAT_EQ(rgb[i + 1], 1.5f);
        ASSERT_FLOAT_EQ(rgb[i + 2], 1e-3f);
    }
}

TEST(RpfFilter, BlocksOfRowsAndThreadsGiveTheSameBits) {
    // A noisy image whose colour depends on the random parameter in the left half and on the
    // feature in the right half. Filtering rows [a, b) from a window holding only the halo they
    // need equals filtering the whole image, bit for bit, for 1 and 2 threads.
    const int W = 20, H = 70;
    const RpfWindow all = makeWindow(W, H, 4, 21, [](int x, int, int, float* s) {
        const float v = x < 10 ? 4 * s[5] : (s[3] > 15 ? 0.9f : 0.1f);
        s[0] = v;
        s[1] = 0.5f * v;
        s[2] = 0.25f;
        s[6] = x < 10 ? 0.f : (s[3] > 15 ? 1.f : 0.5f);  // the left half is one surface
        s[7] = 0;
    });
    RpfParams p;
    p.boxes = {15, 9, 5, 3};
    std::vector<float> whole1, whole2;
    rpfFilterRows(all, p, 0, H, whole1, 1);
    rpfFilterRows(all, p, 0, H, whole2, 2);
    ASSERT_EQ(whole1, whole2);
    const int halo = rpfHalo(p);
    EXPECT_EQ(halo, 7 + 4 + 2 + 1);
    for (int y0 = 0; y0 < H; y0 += 16) {
        const int y1 = std::min(H, y0 + 16), a = std::max(0, y0 - halo), e = std::min(H, y1 + halo);
        RpfWindow w = all;
        w.y0 = a;
        w.rows = e - a;
        w.offset.assign(all.offset.begin() + a * W, all.offset.begin() + e * W + 1);
        const uint64_t base = w.offset[0];
        for (uint64_t& o : w.offset) o -= base;
        w.x.assign(all.x.begin() + std::ptrdiff_t(base * 8),
                   all.x.begin() + std::ptrdiff_t(all.offset[size_t(e * W)] * 8));
        std::vector<float> part;
        rpfFilterRows(w, p, y0, y1, part, 2);
        ASSERT_EQ(part.size(), size_t((y1 - y0) * W * 3));
        for (size_t i = 0; i < part.size(); ++i)
            ASSERT_EQ(part[i], whole1[size_t(y0 * W * 3) + i]) << "block " << y0 << " float " << i;
    }
    // And the filter did something: the random-driven half is smoother than its input.
    double inVar = 0, outVar = 0;
    for (int y = 10; y < 60; ++y)
        for (int x = 2; x < 8; ++x) {
            const size_t px = size_t(y * W + x);
            double m = 0;
            for (uint64_t i = all.offset[px]; i < all.offset[px + 1]; ++i) m += all.sample(i)[0];
            m /= 4;
            inVar += (m - 2) * (m - 2);
            outVar += (whole1[px * 3] - 2) * (whole1[px * 3] - 2);
        }
    EXPECT_LT(outVar, 0.25 * inVar);
}

TEST(RpfFilter, OneThreadAndFourGiveTheSameBytesOnASmallImage) {
    // A 32 x 24 image, 4 spp: noise driven by the random parameter on the left, a two-surface
    // texture on the right, a few bright samples, two AOVs (one following R's spikes, one label).
    // Every pass cuts the pixels into chunks of a few pixels on 3 and 4 threads (rpfPass: about 64
    // per thread) handed out as threads free up; the colours, the AOVs and pass 0's report must
    // be the bytes of one thread, with and without section 6.1's spikes. Pass 0's dependencies
    // (eq. 9-16, doubles from sums of c log c over the joint histograms) are compared too: those
    // sums are not exact, so one whose order followed the threads changes them (summing the cells
    // backwards on the worker threads alone fails this test). The colours are floats, which hide
    // a last-bit change of most double sums.
    const int W = 32, H = 24;
    RpfWindow w = makeWindow(W, H, 4, 52, [](int x, int y, int i, float* s) {
        const float v = x < 16 ? 3 * s[5] * s[5] : (s[3] + s[4] > 27 ? 0.8f : 0.15f);
        s[0] = (x * 7 + y * 3 + i) % 41 == 0 ? 40.f * v + 5.f : v;  // a few fireflies
        s[1] = 0.5f * v + 0.01f * float(i);
        s[2] = 0.3f * s[7];
        s[6] = x < 16 ? 0.f : (s[3] + s[4] > 27 ? 1.f : 0.5f);
    });
    w.aovs = 2;
    w.aovFollows = {0, -1};
    w.aovFixed = {false, true};
    for (size_t i = 0; i < w.samples(); ++i) {
        w.aov.push_back(0.7f * w.sample(i)[0]);
        w.aov.push_back(float(i % 3));
    }
    RpfParams p;
    p.boxes = {15, 9, 5, 3};
    for (bool spikes : {false, true}) {
        p.spikes = spikes;
        std::vector<float> rgb1, aov1;
        std::vector<RpfPixelReport> rep1;
        rpfFilterRows(w, p, 0, H, rgb1, 1, {}, &rep1, &aov1);
        ASSERT_EQ(rgb1.size(), size_t(W * H * 3));
        ASSERT_EQ(aov1.size(), size_t(W * H * 2));
        for (int threads : {3, 4}) {
            std::vector<float> rgb, aov;
            std::vector<RpfPixelReport> rep;
            int rows = 0;
            rpfFilterRows(
                w, p, 0, H, rgb, threads, [&](int) { ++rows; }, &rep, &aov);
            ASSERT_EQ(rgb.size(), rgb1.size());
            EXPECT_EQ(std::memcmp(rgb.data(), rgb1.data(), rgb.size() * sizeof(float)), 0)
                << threads << " threads, spikes " << spikes;
            ASSERT_EQ(aov.size(), aov1.size());
            EXPECT_EQ(std::memcmp(aov.data(), aov1.data(), aov.size() * sizeof(float)), 0)
                << threads << " threads, spikes " << spikes;
            ASSERT_EQ(rep.size(), rep1.size());
            for (size_t q = 0; q < rep.size(); ++q) {
                ASSERT_EQ(rep[q].neighbours, rep1[q].neighbours) << q;
                ASSERT_EQ(rep[q].alpha, rep1[q].alpha) << q;
                ASSERT_EQ(rep[q].beta, rep1[q].beta) << q;
                ASSERT_EQ(rep[q].colorOnRandom, rep1[q].colorOnRandom) << q;
                ASSERT_EQ(rep[q].featureOnRandom, rep1[q].featureOnRandom) << q;
            }
            EXPECT_EQ(rows, 4 * H);  // every row of every pass reported once (all passes: H rows)
        }
    }
}

TEST(RpfFilter, ExtremesStayFinite) {
    // One sample per pixel (s = 1: the pixel's deviation is 0, so the clustering floor decides),
    // empty pixels (a pixel without samples is 0 and lends none), a 1e38 sample and denormals:
    // every output is finite; the empty pixel is exactly 0.
    RpfWindow w = makeWindow(12, 10, 1, 4, [](int x, int y, int, float* s) {
        s[0] = s[1] = s[2] = 0.5f;
        if (x == 3 && y == 3) s[0] = s[1] = s[2] = 1e38f;
        if (x == 7 && y == 2) s[0] = s[1] = s[2] = 1e-40f;
    });
    // Empty pixel (5, 5): remove its sample.
    const size_t p = 5 * 12 + 5, at = size_t(w.offset[p]), dims = size_t(w.layout.dims());
    w.x.erase(w.x.begin() + std::ptrdiff_t(at * dims),
              w.x.begin() + std::ptrdiff_t((at + 1) * dims));
    for (size_t q = p + 1; q < w.offset.size(); ++q) --w.offset[q];
    RpfParams prm;
    for (bool spikes : {false, true}) {
        prm.spikes = spikes;
        std::vector<float> rgb;
        rpfFilterRows(w, prm, 0, 10, rgb, 2);
        for (float v : rgb) ASSERT_TRUE(std::isfinite(v)) << v;
        EXPECT_EQ(rgb[p * 3], 0.f);
        // A lone 1e38 sample on a constant surface whose colour does not depend on the random
        // parameter keeps its own value: the colour term separates it from the 0.5s.
        EXPECT_GT(rgb[(3 * 12 + 3) * 3], 1e37f);
    }
}

}  // namespace
}  // namespace mcstat
