// Confidence intervals for what the per-pixel estimators estimate, from one pixel's M sub-buffer
// means (issue 37, docs/confidence.md): pure functions over one channel's values in the valid
// buffers, free of I/O and OIIO types, shared by the command-line tool, the plugin and Python
// through PixelKernel::interval (operation.h). Every buffer mean is an independent replicate (one
// seed per render, or samples dealt round-robin from independent streams): the interval comes
// from their spread, never from the samples inside one render.
//
// Per estimator (the kernel's bind chooses):
// - mean (Buisine et al. 2021, eq. 1): Student's t interval, M - 1 degrees of freedom, about the
//   count-weighted mean with the batch-means standard error (core/location_stats.h): exact for
//   normal buffer means, asymptotically right for any finite variance (the central limit theorem
//   applies to each buffer mean already).
// - MoN / MPE (Buisine et al. eq. 2; Jung 2016 eq. 4.6, 5.2), G-MoN (eq. 4, 6), G-MoN_b (eq. 5):
//   the distribution-free order-statistic interval [x_(k), x_(M+1-k)] for the median of the
//   buffer means, k the largest with P(k <= Bin(M, 1/2) <= M - k) >= level (exact for any
//   continuous distribution of the buffer means). G-MoN and G-MoN_b estimate a location between
//   the median of means and the mean (the Gini coefficient chooses how much is trimmed); the
//   median's interval is the one that is exact whatever the tails, and the same for both ends
//   of that range when the buffer means are symmetric (docs/confidence.md measures the rest).
// - TMPE (Jung 2016, eq. 5.1): Yuen's trimmed-mean interval, the trimmed mean +- t_{h-1}
//   times the winsorised standard error (Yuen 1974), with TMPE's own trim g = tmpeTrim(alpha, M).
//   When fewer than two values remain (alpha = 0.5: the median) the median's interval.
//
// Colour: each channel's interval is computed on that channel's values alone (in luminance mode
// the estimate ranks buffers by luminance, so on pixels whose colours vary between buffers the
// estimate can lie outside its channel's interval; docs/confidence.md).
//
// Extremes: values are read as double (float's 1e38 squares without overflow); m = 0: NaN;
// m = 1: [-inf, +inf], full; all values equal: [x, x]; too few buffers for the level (the median
// at 0.95 with M < 6): the range [x_(1), x_(M)], full.
#pragma once

#include "mcstat/filters/estimate.h"
#include "mcstat/filters/interval.h"

namespace mcstat {

/// Student's t interval for the count-weighted mean of `m` values (counts null: all 1).
ValueInterval meanInterval(const double* values, const double* counts, int m, double level);
/// The order-statistic interval for the median of `m` values (sorted in place).
ValueInterval medianInterval(double* values, int m, double level);
/// Yuen's interval for the mean of the values left after cutting `g` from each end of `m` values
/// (sorted in place); fewer than two left: medianInterval.
ValueInterval yuenInterval(double* values, int m, int g, double level);

}  // namespace mcstat
