// Two-sample tests on sub-buffer means, the statistics behind `mcstat --compare`
// (docs/compare.md): pure functions over one pixel's (or one tile's) buffer values, free of I/O.
//
// The unit of observation is a sub-buffer mean, not a sample. Buffers are independent by
// construction (one seed per render, or samples dealt round-robin from independent streams),
// whereas the samples inside one render are not (QMC and stratified samplers correlate them), so
// a variance taken from the samples would be wrong and one taken from the buffers is not: the
// batch-means method, as Jung, Hanika and Dachsbacher ("Detecting Bias in Monte Carlo Renderers
// using Welch's t-test", JCGT 9(2), 2020, section 3) use per-pixel sums and sums of squares of
// independent estimates.
//
// Every p-value is for the null hypothesis named by its function; NaN when the data do not allow
// the test (non-finite values, too few buffers). Accumulation is in double.
#pragma once

#include <cstddef>
#include <vector>

namespace mcstat {

/// What a side contributes to a two-sample test: its estimate, the variance of that estimate,
/// and the degrees of freedom of that variance.
struct SideSummary {
    double estimate = 0.0;  ///< the mean (or trimmed mean) of the side
    double variance = 0.0;  ///< estimated variance of `estimate` (squared standard error)
    double df = 0.0;        ///< degrees of freedom of `variance`; 0: no variance estimate
    int buffers = 0;        ///< buffers that entered (non-empty ones)
    bool finite = true;     ///< false when a non-empty buffer holds NaN or Inf
};

/// The count-weighted mean of `M` buffer values y_j with sample counts n_j (buffers with n_j <= 0
/// are empty and skipped) and its variance, from the spread of the buffer means: with N = sum n_j,
///   mean = sum n_j y_j / N,   s^2 = sum n_j (y_j - mean)^2 / (M' - 1),   variance = s^2 / N,
/// M' the non-empty buffers and df = M' - 1. s^2 is the between-group mean square of a one-way
/// ANOVA, unbiased for the per-sample variance when every buffer averages n_j independent samples
/// of one distribution (var y_j = sigma^2 / n_j), so `variance` is unbiased for var(mean). With
/// equal counts it is the textbook s_y^2 / M of the buffer means. `counts` may be null (every
/// buffer counts 1). M' < 2: df 0 (no variance).
SideSummary meanSummary(const double* values, const double* counts, int M);

/// Yuen's trimmed mean and its variance (Yuen, "The two-sample trimmed t for unequal population
/// variances", Biometrika 61(1), 1974; Wilcox, "Introduction to Robust Estimation and Hypothesis
/// Testing", section 5.3): of the M' non-empty buffers (counts <= 0 skipped; the values are
/// treated alike, not weighted), g = floor(trim M') are cut from each end, h = M' - 2g remain;
///   estimate = mean of the h middle values,
///   variance = (M' - 1) s_w^2 / (h (h - 1)),   df = h - 1,
/// s_w^2 the variance (denominator M' - 1) of the winsorized values (each cut value replaced by
/// the nearest kept one). A firefly in one buffer moves the mean and inflates s^2 by its square;
/// it moves neither the trimmed mean nor s_w^2 beyond the kept values. trim in [0, 0.5); trim 0
/// is meanSummary without counts. h < 2: df 0.
SideSummary trimmedSummary(const double* values, const double* counts, int M, double trim);

/// The summary of a value known without noise (a reference image's pixel): variance 0, df
/// infinite.
SideSummary exactSummary(double value);

/// The difference of two sides, b minus a, and what it says.
struct TwoSampleResult {
    double difference = 0.0;  ///< b.estimate - a.estimate
    double se = 0.0;          ///< sqrt(a.variance + b.variance)
    double z = 0.0;           ///< difference / se (standard errors; +-Inf when se = 0, 0 for 0/0)
    double df = 0.0;          ///< Welch-Satterthwaite degrees of freedom (Inf for two exact sides)
    double margin = 0.0;      ///< the tolerance delta the p-value was computed with
    double p = 0.0;           ///< p-value of the test asked for; NaN: not testable
};

/// How a TwoSampleResult's p-value is read.
enum class TwoSampleTest {
    /// H0: |b - a| <= margin; small p: they differ by more than the margin. Margin 0 is Welch's
    /// two-sided t-test (Welch, Biometrika 34, 1947), p = 2 P(T > |z|); a margin > 0 makes it a
    /// minimum-effect test, p = P(T > (|d| - margin) / se) + P(T < (-|d| - margin) / se), the
    /// probability at the boundary |b - a| = margin, so differences within the margin (float
    /// rounding of a new compiler) never count as evidence.
    Difference,
    /// H0: |b - a| >= margin; small p: they agree within the margin. Schuirmann's two one-sided
    /// tests (J. Pharmacokinetics and Biopharmaceutics 15(6), 1987): p = max(P(T > (d + margin) /
    /// se), P(T < (d - margin) / se)). Margin 0 can never be shown (p = 1).
    Equivalence,
};

/// Welch's test of b against a: difference, standard error, Welch-Satterthwaite degrees of freedom
///   df = (v_a + v_b)^2 / (v_a^2 / df_a + v_b^2 / df_b)
/// (a side with variance 0 adds nothing) and the p-value of `test` with tolerance `margin` >= 0.
/// The t distribution with df degrees of freedom gives the tails; df = Inf is the normal. se = 0
/// (both sides constant): the difference is exact, p is 0 or 1 (equivalence: 0 when it is inside
/// the margin or exactly 0). NaN p when a side is not finite
/// or has variance but no degrees of freedom (one buffer), or when both sides lack a variance
/// estimate (df 0) while the difference is not exact.
TwoSampleResult welchTest(const SideSummary& a, const SideSummary& b, double margin = 0.0,
                          TwoSampleTest test = TwoSampleTest::Difference);

/// Mitsuba 3's render-test z-test of one channel (mitsuba-renderer/mitsuba3,
/// src/render/tests/test_renders.py, z_test): a render's mean `mean` of `samples` samples against
/// a reference value `ref` whose per-sample variance `refVariance` stands for the render's own,
/// floored at `varianceFloor`: z = (mean - ref) sqrt(samples / max(refVariance, varianceFloor)),
/// p = 2 (1 - Phi(|z|)). The reference's own noise is not counted. NaN p for a non-finite input
/// or no samples.
TwoSampleResult mitsubaZTest(double mean, double samples, double ref, double refVariance,
                             double varianceFloor);

/// P(T > t) for Student's t with `df` degrees of freedom (df = Inf: the standard normal), exact in
/// its far tail (no cancellation): Boost.Math's complement of the cdf.
double studentTail(double t, double df);

/// The t exceeded with probability `tail` in (0, 1): studentTail(t, df) = tail (df = Inf or above
/// 1e7: the standard normal's). NaN for a tail outside (0, 1) or df <= 0.
double studentUpperQuantile(double tail, double df);

/// The smallest difference |b - a| that a two-sided test of per-hypothesis level `alpha` finds with
/// probability `power`: margin + ncp se, ncp the non-centrality at which Student's non-central t
/// of `df` degrees of freedom exceeds the critical t_{alpha/2} in absolute value with that
/// probability (the t test's exact power for a known noise ratio; Cohen 1988, ch. 2), the normal's
/// beyond 1e7 degrees of freedom. NaN when se is not finite and > 0, df <= 0 or power not in (0,
/// 1).
double detectableDifference(double se, double df, double margin, double alpha, double power);

/// Multiple-testing control over a family of p-values (NaN entries are untested and not counted
/// in m).
enum class Multiplicity {
    FDR,   ///< Benjamini and Hochberg (J. R. Stat. Soc. B 57(1), 1995): false discovery rate <= q
    FWER,  ///< Holm (Scand. J. Statistics 6(2), 1979): family-wise error rate <= q
    None,  ///< each p-value against q alone
};

/// The largest p-value still rejected when `p` is tested as one family at level q, or -1 when
/// none is: reject exactly the p_i <= threshold. FDR: p_(k*) with k* the largest k such that
/// p_(k) <= k q / m (step-up). FWER: step-down, p_(k) <= q / (m - k + 1) for every k up to k*.
/// None: the largest p_i <= q. `tested` receives m.
double rejectionThreshold(const std::vector<float>& p, double q, Multiplicity control,
                          size_t* tested = nullptr);

}  // namespace mcstat
