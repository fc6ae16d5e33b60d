// The ranked trimmed mean every rank estimator is made of (mean, MoN / MPE, G-MoN, G-MoN_b, TMPE):
// rank the valid means (by luminance, or per channel), trim c from each side, average the rest
// with the counts as weights. The estimators differ only in how c is chosen: a TrimRule each
// estimator supplies from its own file (its trim, with its equation); this file holds the ranking,
// the Gini coefficient and the fast path for M <= 64 (portable and AVX2, the same bits), and names
// no estimator.
//
// The Gini coefficient: Buisine, Delepoulle, Renaud, "Fireflies removing in Monte Carlo rendering
// with adaptive Median of meaNs", EGSR 2021, eq. 4.
#pragma once

#include <cstddef>
#include <vector>

#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

/// What the Gini coefficient of G-MoN and G-MoN_b (eq. 4, defined for non-negative values) is
/// computed on. Both are the paper's G on non-negative means, bit for bit.
enum class GiniInput {
    /// The magnitudes |x_j| (giniMagnitudes): a buffer far below zero weighs as one as far above
    /// it, so a negative outlier raises G as a positive one does. The default.
    Magnitudes,
    /// The means shifted by -min when the smallest is negative (giniSorted): the form before issue
    /// 38. A negative outlier becomes the one zero among equal values: G ~ 1/M, no trim.
    Shifted,
};

/// How many means a ranked estimator trims from each side, once the valid means are ranked: the
/// policy an estimator supplies (gmon.cpp, tmpe.cpp, ...); the ranking calls it and knows no
/// estimator.
struct TrimRule {
    /// The means trimmed from each side of the M_v >= 1 ranked valid means, in
    /// [0, floor((M_v - 1) / 2)] (the median or the two middle means always stay); `G` is their
    /// Gini coefficient when `usesGini`, else 0. Null: the plain mean, nothing ranked or trimmed
    /// (summed in one pass).
    int (*trim)(const TrimRule& rule, double G, int Mv) = nullptr;
    bool usesGini = false;                   ///< G is computed (on `gini`) for `trim`
    double value = 0.0;                      ///< the estimator's own parameter (alpha, threshold)
    GiniInput gini = GiniInput::Magnitudes;  ///< with usesGini: what G is computed on
};

/// The ranked trimmed mean of `px` under `rule`: rgb, Gini coefficient (rules that use it), kept
/// and excluded buffers and, with s.wantWeights, the buffer weights (pixel_estimate.h).
void rankedTrimmedMean(const PixelBuffers& px, const PixelParams& p, const TrimRule& rule,
                       PixelEstimate& out, EstimatorScratch& s);

/// The plain mean's pass (rankedTrimmedMean with no trim, without weights: the same
/// bits) that also leaves what it found for the mean's interval (confidence.h,
/// meanIntervalsFromSums): the valid buffers' indices in index order in `valid`, the sum of their
/// counts in `n` and the count-weighted sums of R, G, B in `sum`. Returns the number of valid
/// buffers.
int plainMeanPass(const PixelBuffers& px, PixelEstimate& out, std::vector<int>& valid, double& n,
                  double sum[3]);

/// Gini coefficient of `values` already sorted ascending (Buisine et al. eq. 4), computed in
/// double, with the negative-value and zero-sum rules of pixel_estimate.h. n == 0 or 1 gives 0.
double giniSorted(const double* values, size_t n);

/// Gini coefficient (eq. 4) of the magnitudes |x_j| of `values` sorted ascending (GiniInput::
/// Magnitudes): the negative values, reversed, and the others are merged into ascending order of
/// magnitude. When values[0] >= 0 it is giniSorted(values, n), bit for bit.
double giniMagnitudes(const double* values, size_t n);

}  // namespace mcstat
