// The two-sample tests of --compare against closed forms, hand-computed values and textbook
// examples (include/mcstat/analysis/two_sample.h).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "mcstat/analysis/two_sample.h"

namespace mcstat {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(StudentTail, ClosedFormsForOneAndTwoDegreesOfFreedomAndTheNormal) {
    for (double t : {-3.0, -0.5, 0.0, 0.7, 2.0, 12.0}) {
        // df = 1 is the Cauchy distribution: P(T > t) = 1/2 - atan(t) / pi.
        EXPECT_NEAR(studentTail(t, 1.0), 0.5 - std::atan(t) / M_PI, 1e-14) << t;
        // df = 2: P(T > t) = 1/2 - t / (2 sqrt(2 + t^2)).
        EXPECT_NEAR(studentTail(t, 2.0), 0.5 - t / (2.0 * std::sqrt(2.0 + t * t)), 1e-14) << t;
        EXPECT_NEAR(studentTail(t, kInf), 0.5 * std::erfc(t / std::sqrt(2.0)), 1e-15) << t;
    }
    // The far tail without cancellation: df = 2, P(T > t) = 1 / (2 + t^2 + t sqrt(2 + t^2)).
    const double t = 1e4;
    const double exact = 1.0 / (2.0 + t * t + t * std::sqrt(2.0 + t * t));
    EXPECT_NEAR(studentTail(t, 2.0) / exact, 1.0, 1e-10);
    EXPECT_EQ(studentTail(kInf, 5.0), 0.0);
    EXPECT_EQ(studentTail(-kInf, 5.0), 1.0);
    EXPECT_TRUE(std::isnan(studentTail(kNaN, 5.0)));
    EXPECT_TRUE(std::isnan(studentTail(1.0, 0.0)));
}

// The smallest difference found with probability 0.8, against scipy's root of
// nct.sf(t, df, ncp) + nct.cdf(-t, df, ncp) = 0.8 (norm for df = Inf): 2.8016 standard errors at
// level 0.05 for the normal (1.96 + 0.8416, less a hair for the far tail), 4.2559 at df 3, 5.2306
// at df 14 and level 0.005 / 6 (compare's tile family, test_compare.cpp).
TEST(DetectableDifference, NonCentralTAgainstScipyAndTheExtremes) {
    EXPECT_NEAR(detectableDifference(1.0, HUGE_VAL, 0.0, 0.05, 0.8), 2.80158, 1e-4);
    EXPECT_NEAR(detectableDifference(2.0, HUGE_VAL, 0.5, 0.05, 0.8), 0.5 + 2.0 * 2.80158, 2e-4);
    EXPECT_NEAR(detectableDifference(1.0, 3.0, 0.0, 0.05, 0.8), 4.25590, 1e-3);
    EXPECT_NEAR(detectableDifference(0.1, 14.0, 0.0, 0.005 / 6.0, 0.8), 0.52306, 1e-4);
    // One degree of freedom at a tiny level: huge, finite, no exception.
    const double far = detectableDifference(1.0, 1.0, 0.0, 1e-9, 0.8);
    EXPECT_TRUE(std::isfinite(far));
    EXPECT_GT(far, 1e8);
    EXPECT_TRUE(std::isnan(detectableDifference(0.0, 14.0, 0.0, 0.05, 0.8)));
    EXPECT_TRUE(std::isnan(detectableDifference(1.0, 0.0, 0.0, 0.05, 0.8)));
    EXPECT_TRUE(std::isnan(detectableDifference(HUGE_VAL, 14.0, 0.0, 0.05, 0.8)));
    EXPECT_TRUE(std::isnan(detectableDifference(1.0, 14.0, 0.0, 0.05, 1.0)));
}

TEST(MeanSummary, EqualCountsIsTheTextbookStandardErrorOfTheBufferMeans) {
    const double y[] = {1, 2, 3, 6};
    const double n[] = {2, 2, 2, 2};
    // mean 3; s_y^2 = (4 + 1 + 0 + 9) / 3 = 14/3; var(mean) = s_y^2 / 4 = 7/6, with or without
    // the counts (N = 8, s^2 = 2 * 14/3, s^2 / N = 7/6).
    for (const double* counts :
         {static_cast<const double*>(n), static_cast<const double*>(nullptr)}) {
        const SideSummary s = meanSummary(y, counts, 4);
        EXPECT_DOUBLE_EQ(s.estimate, 3.0);
        EXPECT_NEAR(s.variance, 7.0 / 6.0, 1e-15);
        EXPECT_EQ(s.df, 3.0);
        EXPECT_EQ(s.buffers, 4);
        EXPECT_TRUE(s.finite);
    }
}

TEST(MeanSummary, UnequalCountsWeightTheBuffersAndSkipEmptyOnes) {
    // y = {1, 3} with n = {1, 3} (and an empty buffer): N = 4, mean = 10 / 4 = 2.5,
    // sum n (y - mean)^2 = 1 * 2.25 + 3 * 0.25 = 3, df 1, variance 3 / 1 / 4 = 0.75.
    const double y[] = {1, 99, 3};
    const double n[] = {1, 0, 3};
    const SideSummary s = meanSummary(y, n, 3);
    EXPECT_DOUBLE_EQ(s.estimate, 2.5);
    EXPECT_DOUBLE_EQ(s.variance, 0.75);
    EXPECT_EQ(s.df, 1.0);
    EXPECT_EQ(s.buffers, 2);
}

TEST(MeanSummary, VarianceIsUnbiasedForUnequalCounts) {
    // Buffers of n_j iid N(0, 1) samples: E[variance] = 1 / N. Without the counts the spread of
    // the buffer means would say about twice as much here (the 1-sample buffer dominates it).
    std::mt19937_64 rng(7);
    std::normal_distribution<double> normal;
    const int counts[] = {1, 2, 4, 8, 16};
    double N = 0.0;
    for (int c : counts) N += c;
    double sum = 0.0;
    const int trials = 40000;
    for (int t = 0; t < trials; ++t) {
        double y[5], n[5];
        for (int j = 0; j < 5; ++j) {
            double s = 0.0;
            for (int k = 0; k < counts[j]; ++k) s += normal(rng);
            y[j] = s / counts[j];
            n[j] = counts[j];
        }
        sum += meanSummary(y, n, 5).variance;
    }
    // Standard error of the average: var(s^2 / N) = 2 / (df N^2) for a chi-square / df; about
    // 1.2 % of 1/N over 40000 trials, so 5 % is well outside chance.
    EXPECT_NEAR(sum / trials * N, 1.0, 0.05);
}

TEST(MeanSummary, OneBufferHasNoVarianceAndNonFiniteIsFlagged) {
    const double one[] = {4.0};
    const SideSummary s = meanSummary(one, nullptr, 1);
    EXPECT_EQ(s.estimate, 4.0);
    EXPECT_EQ(s.df, 0.0);
    const double bad[] = {1.0, kNaN, 2.0};
    EXPECT_FALSE(meanSummary(bad, nullptr, 3).finite);
    const double inf[] = {1.0, kInf};
    EXPECT_FALSE(meanSummary(inf, nullptr, 2).finite);
    // A NaN in an empty buffer is not data.
    const double n[] = {1, 0, 1};
    EXPECT_TRUE(meanSummary(bad, n, 3).finite);
    const double zero[] = {0, 0};
    EXPECT_TRUE(std::isnan(meanSummary(one, zero, 1).estimate));
}

TEST(TrimmedSummary, YuensTrimmedMeanAndWinsorizedVariance) {
    // M = 5, trim 0.2: g = 1, h = 3. Trimmed mean (2 + 3 + 4) / 3 = 3; winsorized {2, 2, 3, 4, 4}:
    // mean 3, sum of squares 4, variance (M - 1) s_w^2 / (h (h - 1)) = 4 / 6; df = h - 1 = 2.
    const double y[] = {4, 1, 100, 3, 2};
    SideSummary s = trimmedSummary(y, nullptr, 5, 0.2);
    EXPECT_DOUBLE_EQ(s.estimate, 3.0);
    EXPECT_DOUBLE_EQ(s.variance, 4.0 / 6.0);
    EXPECT_EQ(s.df, 2.0);
    // A firefly of any size in one buffer changes nothing.
    const double firefly[] = {4, 1, 1e30, 3, 2};
    const SideSummary f = trimmedSummary(firefly, nullptr, 5, 0.2);
    EXPECT_DOUBLE_EQ(f.estimate, s.estimate);
    EXPECT_DOUBLE_EQ(f.variance, s.variance);
    // Trim 0 is the plain mean and its variance.
    const SideSummary m = meanSummary(y, nullptr, 5);
    s = trimmedSummary(y, nullptr, 5, 0.0);
    EXPECT_DOUBLE_EQ(s.estimate, m.estimate);
    EXPECT_NEAR(s.variance, m.variance, 1e-12);
    EXPECT_EQ(s.df, m.df);
    // Empty buffers are skipped before trimming: three values, g = 0.
    const double n[] = {1, 1, 0, 1, 0};
    s = trimmedSummary(y, n, 5, 0.2);
    EXPECT_EQ(s.buffers, 3);
    EXPECT_DOUBLE_EQ(s.estimate, (4.0 + 1.0 + 3.0) / 3.0);
}

TEST(WelchTest, DifferenceZAndSatterthwaiteDegreesOfFreedom) {
    SideSummary a{0.0, 1.0, 10.0, 11, true}, b{3.0, 1.0, 10.0, 11, true};
    TwoSampleResult r = welchTest(a, b);
    EXPECT_DOUBLE_EQ(r.difference, 3.0);
    EXPECT_DOUBLE_EQ(r.se, std::sqrt(2.0));
    EXPECT_DOUBLE_EQ(r.z, 3.0 / std::sqrt(2.0));
    EXPECT_DOUBLE_EQ(r.df, 4.0 / (0.1 + 0.1));  // (v_a + v_b)^2 / (v_a^2/df_a + v_b^2/df_b)
    // Unequal variances: v = 4 and 1 with df 3 and 20: df = 25 / (16/3 + 1/20).
    a = {0.0, 4.0, 3.0, 4, true};
    b = {1.0, 1.0, 20.0, 21, true};
    EXPECT_NEAR(welchTest(a, b).df, 25.0 / (16.0 / 3.0 + 1.0 / 20.0), 1e-12);
}

TEST(WelchTest, PValueMatchesStudentTables) {
    // t_{0.975} with 20 degrees of freedom is 2.08596 (tables): two-sided p = 0.05.
    const double t975 = 2.085963447;
    const SideSummary a{0.0, 0.5, 10.0, 11, true}, b{t975, 0.5, 10.0, 11, true};
    EXPECT_NEAR(welchTest(a, b).p, 0.05, 1e-8);
    // Symmetric in the two sides.
    EXPECT_NEAR(welchTest(b, a).p, 0.05, 1e-8);
    EXPECT_DOUBLE_EQ(welchTest(b, a).z, -welchTest(a, b).z);
    // Against an exact value (a reference pixel): one-sample t with b's df; t_{0.995, 10}
    // = 3.16927.
    const SideSummary ref = exactSummary(0.0), c{3.169272673, 1.0, 10.0, 11, true};
    const TwoSampleResult r = welchTest(ref, c);
    EXPECT_DOUBLE_EQ(r.df, 10.0);
    EXPECT_NEAR(r.p, 0.01, 1e-8);
}

TEST(WelchTest, MarginTurnsItIntoAMinimumEffectTest) {
    // d = 1, se = 1, normal (df Inf): margin 0 is two-sided, 2 P(Z > 1); margin 1 puts the
    // observation on the boundary, p = P(Z > 0) + P(Z > 2).
    const SideSummary a = {0.0, 0.5, kInf, 2, true}, b = {1.0, 0.5, kInf, 2, true};
    EXPECT_NEAR(welchTest(a, b, 0.0).p, std::erfc(1.0 / std::sqrt(2.0)), 1e-14);
    EXPECT_NEAR(welchTest(a, b, 1.0).p, 0.5 + 0.5 * std::erfc(2.0 / std::sqrt(2.0)), 1e-14);
    // A difference inside the margin is never evidence, however small the noise.
    const SideSummary c = {0.0, 1e-20, kInf, 2, true}, d = {1e-6, 1e-20, kInf, 2, true};
    EXPECT_LT(welchTest(c, d, 0.0).p, 1e-10);
    EXPECT_GT(welchTest(c, d, 1e-5).p, 0.99);
}

TEST(WelchTest, EquivalenceIsTwoOneSidedTests) {
    // d = 0.5, se = 1, normal: max(P(Z > (0.5 + 3)), P(Z > (3 - 0.5))) = P(Z > 2.5).
    const SideSummary a = {0.0, 0.5, kInf, 2, true}, b = {0.5, 0.5, kInf, 2, true};
    const TwoSampleResult r = welchTest(a, b, 3.0, TwoSampleTest::Equivalence);
    EXPECT_NEAR(r.p, 0.5 * std::erfc(2.5 / std::sqrt(2.0)), 1e-14);
    // No margin: agreement can never be shown.
    EXPECT_EQ(welchTest(a, b, 0.0, TwoSampleTest::Equivalence).p, 1.0);
}

TEST(WelchTest, ConstantSidesAreExactAndOneBufferOrNonFiniteIsUntestable) {
    const SideSummary zero{0.0, 0.0, 3.0, 4, true}, half{0.5, 0.0, 3.0, 4, true};
    EXPECT_EQ(welchTest(zero, zero).p, 1.0);  // black on both sides
    EXPECT_EQ(welchTest(zero, zero).z, 0.0);
    EXPECT_EQ(welchTest(zero, half).p, 0.0);  // constant and different: certainly different
    EXPECT_EQ(welchTest(zero, half).z, kInf);
    EXPECT_EQ(welchTest(zero, half, 1.0).p, 1.0);  // ... but within the tolerance
    EXPECT_EQ(welchTest(zero, zero, 0.1, TwoSampleTest::Equivalence).p, 0.0);
    EXPECT_EQ(welchTest(zero, half, 0.1, TwoSampleTest::Equivalence).p, 1.0);
    const SideSummary one{1.0, 0.0, 0.0, 1, true}, noisy{1.0, 0.3, 5.0, 6, true};
    EXPECT_TRUE(std::isnan(welchTest(one, noisy).p));
    SideSummary bad = noisy;
    bad.finite = false;
    EXPECT_TRUE(std::isnan(welchTest(bad, noisy).p));
    EXPECT_TRUE(std::isnan(welchTest(noisy, noisy, -1.0).p));
}

TEST(RejectionThreshold, BenjaminiHochbergHolmAndUncorrectedOnATextbookFamily) {
    // m = 10, q = 0.05: k q / m = 0.005, 0.010, 0.015, ...; p_(2) = 0.008 <= 0.010 is the last
    // step-up crossing (BH rejects 2). Holm: 0.001 <= 0.05/10 but 0.008 > 0.05/9 (1 rejected).
    const std::vector<float> p = {0.041f, 0.001f, 0.205f, 0.008f, 0.039f,
                                  0.212f, 0.042f, 0.06f,  0.074f, 0.216f};
    size_t m = 0;
    EXPECT_FLOAT_EQ(float(rejectionThreshold(p, 0.05, Multiplicity::FDR, &m)), 0.008f);
    EXPECT_EQ(m, 10u);
    EXPECT_FLOAT_EQ(float(rejectionThreshold(p, 0.05, Multiplicity::FWER)), 0.001f);
    EXPECT_FLOAT_EQ(float(rejectionThreshold(p, 0.05, Multiplicity::None)), 0.042f);
    // Step-up, not step-down: a later p-value under its line rejects everything before it.
    const std::vector<float> up = {0.02f, 0.03f, 0.035f, 0.04f};  // 0.04 <= 4 * 0.05 / 4
    EXPECT_FLOAT_EQ(float(rejectionThreshold(up, 0.05, Multiplicity::FDR)), 0.04f);
    // NaN entries are untested: not in m.
    std::vector<float> withNaN = p;
    withNaN.insert(withNaN.end(), 90, std::numeric_limits<float>::quiet_NaN());
    EXPECT_FLOAT_EQ(float(rejectionThreshold(withNaN, 0.05, Multiplicity::FDR, &m)), 0.008f);
    EXPECT_EQ(m, 10u);
    EXPECT_EQ(rejectionThreshold({0.5f, 0.9f}, 0.05, Multiplicity::FDR), -1.0);
    EXPECT_EQ(rejectionThreshold({}, 0.05, Multiplicity::FDR), -1.0);
}

}  // namespace
}  // namespace mcstat
