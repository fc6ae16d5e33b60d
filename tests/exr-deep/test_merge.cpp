// mergeStats: merging renders equals one render that took all their samples, within a tolerance
// derived from float32 rounding (FORMAT.md "Merge"); associativity, order independence, errors.
#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <cstring>
#include <functional>

#include "mcstat/exr-deep/stats_file.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

constexpr int W = 10, H = 8, M = 4;
constexpr double u = FLT_EPSILON / 2;  // unit roundoff of float32, 2^-24

int sppA(int x, int y) { return (x * 7 + y * 3) % 9; }
int sppB(int x, int y) { return (x * 5 + y * 11) % 6; }
int sppC(int x, int y) { return ((x + y) % 3) * 5; }

struct Render {
    uint64_t seed;
    std::function<int(int, int)> spp;
};

/// One accumulator fed with every sample of every render, each render assigning its i-th sample of
/// a pixel to buffer i mod M (what merge promises to reproduce).
StatsImage reference(const std::vector<Render>& renders) {
    SampleAccumulator acc(W, H, M);
    for (const Render& r : renders)
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x)
                for (int i = 0; i < r.spp(x, y); ++i)
                    acc.add(x, y, makeSample(r.seed, y * W + x, i), i % M);
    return acc.finish(StatsHeader());
}

/// Largest magnitude of the radiance and depth samples of each pixel (error scale S).
struct Scales {
    std::vector<double> rgb, depth;
};
Scales scales(const std::vector<Render>& renders) {
    Scales s{std::vector<double>(W * H, 0.0), std::vector<double>(W * H, 0.0)};
    for (const Render& r : renders)
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x)
                for (int i = 0; i < r.spp(x, y); ++i) {
                    const Sample smp = makeSample(r.seed, y * W + x, i);
                    for (double c : smp.rgb) s.rgb[y * W + x] = std::max(s.rgb[y * W + x], c);
                    if (smp.hit) s.depth[y * W + x] = std::max(s.depth[y * W + x], smp.depth);
                }
    return s;
}

/// Checks `got` (after `k` levels of merging) against the all-samples reference.
/// Means: each stored input mean is off by <= u*S, the weighted average keeps that bound, each
/// level's rounding adds u*S, the reference's own rounding u*S: (k + 2) * u * S.
/// Variance: first order, each level adds the rounding u*var and, through the delta of the rounded
/// means (error <= (j + 1) * u * S at level j, |delta| <= S, na*nb/(n*(n-1)) <= 1/2),
/// (j + 1) * u * S^2; with the reference's rounding: (k + 2) * u * var + sum_j (j + 1) * u * S^2.
void expectCloseToReference(const StatsImage& got, const StatsImage& ref, const Scales& sc, int k) {
    ASSERT_EQ(got.pixelCount(), ref.pixelCount());
    double varS2 = 0;
    for (int j = 1; j <= k; ++j) varS2 += j + 1;
    const double tiny = 1e-12;  // double-precision accumulation, far below float32 rounding
    for (size_t p = 0; p < ref.pixelCount(); ++p) {
        SCOPED_TRACE("pixel " + std::to_string(p));
        // counts and coverage are exact
        ASSERT_EQ(got.count[p], ref.count[p]);
        ASSERT_EQ(got.coverage[p], ref.coverage[p]);
        for (int j = 0; j < M; ++j)
            ASSERT_EQ(got.bufferCount[p * M + j], ref.bufferCount[p * M + j]);
        const double S = sc.rgb[p];
        const double tolMean = (k + 2) * u * S + tiny * S;
        for (int c = 0; c < 3; ++c) {
            const size_t i = p * 3 + c;
            EXPECT_NEAR(got.mean[i], ref.mean[i], tolMean);
            EXPECT_NEAR(got.beauty[i], ref.mean[i], tolMean);
            const double tolVar = (k + 2) * u * ref.variance[i] + varS2 * u * S * S + tiny * S * S;
            EXPECT_NEAR(got.variance[i], ref.variance[i], tolVar);
            for (int j = 0; j < M; ++j)
                EXPECT_NEAR(got.bufferMean[(p * M + j) * 3 + c],
                            ref.bufferMean[(p * M + j) * 3 + c], tolMean);
            // unit normals |N| <= 1, positions |P| <= 10, albedo <= 1
            EXPECT_NEAR(got.normal[i], ref.normal[i], (k + 2) * u * 1.0 + tiny);
            EXPECT_NEAR(got.position[i], ref.position[i], (k + 2) * u * 10.0 + tiny);
            EXPECT_NEAR(got.albedo[i], ref.albedo[i], (k + 2) * u * 1.0 + tiny);
        }
        if (std::isinf(ref.depth[p])) {
            EXPECT_TRUE(std::isinf(got.depth[p]));
        } else {
            EXPECT_NEAR(got.depth[p], ref.depth[p], (k + 2) * u * sc.depth[p] + tiny);
        }
    }
}

class Merge : public testing::Test {
  protected:
    Render ra{1, sppA}, rb{2, sppB}, rc{3, sppC};
    StatsImage a = renderImage(W, H, M, 1, sppA), b = renderImage(W, H, M, 2, sppB),
               c = renderImage(W, H, M, 3, sppC);
    std::string err;
};

TEST_F(Merge, EqualsOneRenderOfAllSamples) {
    StatsImage ab;
    ASSERT_TRUE(mergeStats(a, b, ab, err)) << err;
    expectCloseToReference(ab, reference({ra, rb}), scales({ra, rb}), 1);
    EXPECT_TRUE(validateStats(ab, "merged", err)) << err;
    EXPECT_EQ(ab.header.spp, a.header.spp + b.header.spp);
    EXPECT_EQ(ab.header.seeds, "1,2");
    EXPECT_EQ(ab.header.renderer, "test-renderer 1.0");
    // A pixel without samples in either input stays empty.
    EXPECT_EQ(ab.count[0], 0.f);
    EXPECT_TRUE(std::isinf(ab.depth[0]));
}

TEST_F(Merge, IsAssociativeWithinRounding) {
    StatsImage ab, ab_c, bc, a_bc;
    ASSERT_TRUE(mergeStats(a, b, ab, err)) << err;
    ASSERT_TRUE(mergeStats(ab, c, ab_c, err)) << err;
    ASSERT_TRUE(mergeStats(b, c, bc, err)) << err;
    ASSERT_TRUE(mergeStats(a, bc, a_bc, err)) << err;
    const StatsImage ref = reference({ra, rb, rc});
    const Scales sc = scales({ra, rb, rc});
    expectCloseToReference(ab_c, ref, sc, 2);
    expectCloseToReference(a_bc, ref, sc, 2);
    EXPECT_EQ(ab_c.header.seeds, "1,2,3");
    EXPECT_EQ(a_bc.header.seeds, "1,2,3");
}

TEST_F(Merge, IsOrderIndependentWithinRounding) {
    StatsImage ab, ba, cb, cb_a;
    ASSERT_TRUE(mergeStats(a, b, ab, err)) << err;
    ASSERT_TRUE(mergeStats(b, a, ba, err)) << err;
    expectCloseToReference(ba, reference({ra, rb}), scales({ra, rb}), 1);
    // Sub-buffer means are symmetric sums: exactly equal in either order.
    EXPECT_EQ(ab.bufferMean, ba.bufferMean);
    EXPECT_EQ(ba.header.seeds, "2,1");
    ASSERT_TRUE(mergeStats(c, b, cb, err)) << err;
    ASSERT_TRUE(mergeStats(cb, a, cb_a, err)) << err;
    expectCloseToReference(cb_a, reference({ra, rb, rc}), scales({ra, rb, rc}), 2);
}

TEST_F(Merge, WithAnEmptyRenderIsIdentity) {
    StatsImage empty = renderImage(W, H, M, 9, [](int, int) { return 0; });
    StatsImage ae, ea;
    ASSERT_TRUE(mergeStats(a, empty, ae, err)) << err;
    ASSERT_TRUE(mergeStats(empty, a, ea, err)) << err;
    for (const StatsImage* m : {&ae, &ea}) {
        EXPECT_EQ(m->bufferMean, a.bufferMean);
        EXPECT_EQ(m->bufferCount, a.bufferCount);
        EXPECT_EQ(m->mean, a.mean);
        EXPECT_EQ(m->variance, a.variance);
        EXPECT_EQ(m->normal, a.normal);
        EXPECT_EQ(m->albedo, a.albedo);
        EXPECT_EQ(m->coverage, a.coverage);
        EXPECT_EQ(0, std::memcmp(m->depth.data(), a.depth.data(), a.depth.size() * 4));
    }
}

TEST_F(Merge, OutputMayAliasAnInput) {
    StatsImage ab;
    ASSERT_TRUE(mergeStats(a, b, ab, err)) << err;
    StatsImage acc = a;
    ASSERT_TRUE(mergeStats(acc, b, acc, err)) << err;
    EXPECT_EQ(acc.mean, ab.mean);
    EXPECT_EQ(acc.count, ab.count);
}

TEST_F(Merge, DifferentRenderersAreJoined) {
    b.header.renderer = "other 2.0";
    StatsImage ab;
    ASSERT_TRUE(mergeStats(a, b, ab, err)) << err;
    EXPECT_EQ(ab.header.renderer, "test-renderer 1.0 + other 2.0");
}

TEST_F(Merge, RejectsDifferentSizeOriginOrM) {
    StatsImage out;
    const StatsImage wide = renderImage(W + 1, H, M, 5, sppA);
    EXPECT_FALSE(mergeStats(a, wide, out, err));
    EXPECT_TRUE(contains(err, "sizes differ (10x8 vs 11x8)")) << err;
    const StatsImage moved = renderImage(W, H, M, 5, sppA, 1, 0);
    EXPECT_FALSE(mergeStats(a, moved, out, err));
    EXPECT_TRUE(contains(err, "origins differ")) << err;
    const StatsImage m8 = renderImage(W, H, 8, 5, sppA);
    EXPECT_FALSE(mergeStats(a, m8, out, err));
    EXPECT_TRUE(contains(err, "M differs (4 vs 8)")) << err;
    b.header.colorSpace = "ACEScg";
    EXPECT_FALSE(mergeStats(a, b, out, err));
    EXPECT_TRUE(contains(err, "colour spaces differ")) << err;
    EXPECT_TRUE(out.count.empty());
}

TEST_F(Merge, RejectsOverlappingSeedsUnlessOneIsEmpty) {
    StatsImage out;
    a.header.seeds = "1, 2";
    b.header.seeds = "3,2";
    EXPECT_FALSE(mergeStats(a, b, out, err));
    EXPECT_TRUE(contains(err, "seed 2 is in both inputs")) << err;
    EXPECT_FALSE(mergeStats(a, a, out, err));
    b.header.seeds = "";
    EXPECT_TRUE(mergeStats(a, b, out, err)) << err;
    EXPECT_EQ(out.header.seeds, "1, 2");
    b.header.seeds = "12,21";  // no seed in common with "1, 2"
    EXPECT_TRUE(mergeStats(a, b, out, err)) << err;
    EXPECT_EQ(out.header.seeds, "1, 2,12,21");
}

TEST_F(Merge, RejectsInvalidInput) {
    b.count[3] += 1.f;
    StatsImage out;
    EXPECT_FALSE(mergeStats(a, b, out, err));
    EXPECT_TRUE(contains(err, "second merge input: pixel (3, 0)")) << err;
}

// ---- N inputs in one pass (FORMAT.md "Merge of N files") ----

TEST_F(Merge, NInputsInOnePassRoundOnce) {
    StatsImage abc;
    ASSERT_TRUE(mergeStats({&a, &b, &c}, abc, err)) << err;
    // One rounding after the double sums: the bound of one level (k = 1), tighter than the
    // two pairwise merges' k = 2.
    expectCloseToReference(abc, reference({ra, rb, rc}), scales({ra, rb, rc}), 1);
    EXPECT_EQ(abc.header.seeds, "1,2,3");
    EXPECT_EQ(abc.header.spp, a.header.spp + b.header.spp + c.header.spp);
    // The pooled variance by hand at a pixel where all three hold samples:
    // M2 = sum_i [var_i (n_i - 1) + n_i (mean_i - mean)^2], var = M2 / (n - 1).
    const size_t p = 3 * W + 4;
    ASSERT_GT(a.count[p] * b.count[p] * c.count[p], 0.f);
    for (size_t ch = 0; ch < 3; ++ch) {
        const size_t e = p * 3 + ch;
        double n = 0, s = 0, m2 = 0;
        for (const StatsImage* i : {&a, &b, &c}) {
            n += i->count[p];
            s += double(i->count[p]) * i->mean[e];
        }
        const double mean = s / n;
        for (const StatsImage* i : {&a, &b, &c}) {
            const double d = double(i->mean[e]) - mean;
            m2 += double(i->variance[e]) * (i->count[p] - 1.0) + i->count[p] * d * d;
        }
        EXPECT_EQ(abc.mean[e], float(mean));
        EXPECT_EQ(abc.variance[e], float(m2 / (n - 1)));
    }
}

TEST_F(Merge, NInputsDoNotDependOnTheThreadCount) {
    StatsImage one, four;
    ASSERT_TRUE(mergeStats({&c, &a, &b}, one, err, 1)) << err;
    ASSERT_TRUE(mergeStats({&c, &a, &b}, four, err, 4)) << err;
    EXPECT_EQ(
        0, std::memcmp(one.bufferMean.data(), four.bufferMean.data(), one.bufferMean.size() * 4));
    EXPECT_EQ(0, std::memcmp(one.variance.data(), four.variance.data(), one.variance.size() * 4));
    EXPECT_EQ(0, std::memcmp(one.depth.data(), four.depth.data(), one.depth.size() * 4));
}

TEST_F(Merge, CanonicalOrderIsBySeedsNumbersByValue) {
    std::vector<StatsHeader> h(6);
    h[0].seeds = "10";
    h[1].seeds = "9";
    h[2].seeds = "h00ab";
    h[3].seeds = "2,5";
    h[4].seeds = "";
    h[5].seeds = "2,40";
    std::vector<const StatsHeader*> ptrs;
    for (const StatsHeader& x : h) ptrs.push_back(&x);
    // "" first, then 2,5 < 2,40 < 9 < 10 (by value, not as text), then the non-numeric seed.
    EXPECT_EQ(mergeOrder(ptrs), (std::vector<size_t>{4, 3, 5, 1, 0, 2}));
}

TEST_F(Merge, NInputsRefusalNamesTheInputs) {
    b.header.seeds = "5";
    c.header.seeds = "5,6";
    StatsHeader out;
    EXPECT_FALSE(mergeHeaders({&a.header, &b.header, &c.header}, out, err, {"a", "b", "c"}));
    EXPECT_TRUE(contains(err, "seed 5 is in both b and c")) << err;
    c.header.seeds = "6";
    c.header.colorSpace = "ACEScg";
    EXPECT_FALSE(mergeHeaders({&a.header, &b.header, &c.header}, out, err, {"a", "b", "c"}));
    EXPECT_TRUE(contains(err, "a and c: cannot merge: colour spaces differ")) << err;
    // Renderer names once each, whatever the grouping: the same header from any tree.
    c.header.colorSpace = a.header.colorSpace;
    b.header.renderer = "other 2.0";
    StatsHeader ab, ab_c, abc;
    ASSERT_TRUE(mergeHeaders(a.header, b.header, ab, err)) << err;
    ASSERT_TRUE(mergeHeaders(ab, c.header, ab_c, err)) << err;
    ASSERT_TRUE(mergeHeaders({&a.header, &b.header, &c.header}, abc, err)) << err;
    EXPECT_EQ(ab_c.renderer, "test-renderer 1.0 + other 2.0");
    EXPECT_EQ(abc.renderer, ab_c.renderer);
    EXPECT_EQ(abc.seeds, ab_c.seeds);
}

}  // namespace
}  // namespace mcstat::test
