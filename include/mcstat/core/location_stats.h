// The statistics of a location from independent replicates (sub-buffer means), shared by the
// two-sample tests behind `mcstat --compare` (analysis/two_sample.h) and the per-pixel confidence
// intervals (filters/pixel/confidence.h): the count-weighted mean with its standard error, Yuen's
// trimmed mean with its winsorised standard error, Student's t quantile, and the ranks of the
// distribution-free order-statistic interval for a median. One implementation of each, pure,
// accumulated in double (values up to float's 1e38 square without overflow).
#pragma once

namespace mcstat {

/// A location estimate, the variance of that estimate (its squared standard error) and the
/// degrees of freedom of that variance (0: no variance estimate).
struct LocationSummary {
    double estimate = 0.0;
    double variance = 0.0;
    double df = 0.0;
};

/// The count-weighted mean of `m` finite values y_j with counts n_j > 0 (null: every count 1) and
/// its variance from the spread of the values (the batch-means estimate):
///   mean = sum n_j y_j / N,   s^2 = sum n_j (y_j - mean)^2 / (m - 1),   variance = s^2 / N,
/// N = sum n_j, df = m - 1. s^2 is the between-group mean square of a one-way ANOVA, unbiased for
/// the per-sample variance when buffer j averages n_j independent samples; with equal counts
/// variance is the textbook s_y^2 / m. m < 2: df 0, variance 0. m = 0: estimate NaN.
LocationSummary weightedMeanSummary(const double* values, const double* counts, int m);

/// Yuen's trimmed mean of `m` finite values sorted ascending, `g` cut from each end (Yuen, "The
/// two-sample trimmed t for unequal population variances", Biometrika 61(1), 1974; Wilcox,
/// "Introduction to Robust Estimation and Hypothesis Testing", section 5.3 and 4.4.3): h = m - 2g
/// remain,
///   estimate = mean of the h middle values,
///   variance = (m - 1) s_w^2 / (h (h - 1)),   df = h - 1,
/// s_w^2 the variance (denominator m - 1) of the winsorised values (each cut value replaced by the
/// nearest kept one). g is clamped to [0, (m - 1) / 2]; h < 2: df 0, variance 0.
LocationSummary yuenSummary(const double* sorted, int m, int g);

/// The p-quantile of Student's t with `df` > 0 degrees of freedom (df >= 1e7: the normal's);
/// NaN for p outside (0, 1) or df <= 0 (Boost.Math).
double studentQuantile(double p, double df);

/// P(k <= B <= m - k) for B ~ Binomial(m, 1/2): the exact coverage of the order-statistic
/// interval [x_(k), x_(m+1-k)] for the median of any continuous distribution (the sign-test
/// interval; e.g. Hollander, Wolfe and Chicken, "Nonparametric Statistical Methods", section 3.6;
/// David and Nagaraja, "Order Statistics", section 7.1). 0 when k < 1 or 2k > m.
double medianIntervalCoverage(int m, int k);

/// The largest k >= 1 with medianIntervalCoverage(m, k) >= level (the shortest such
/// order-statistic interval), or 0 when even the full range [x_(1), x_(m)] (coverage
/// 1 - 2^(1-m)) falls short of `level`: at 0.95 that is m < 6, at 0.99 m < 8.
int medianIntervalRank(int m, double level);

}  // namespace mcstat
