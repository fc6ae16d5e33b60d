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

#include <functional>

#include "mcstat/core/pixel_buffers.h"
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

// The same intervals for R, G and B of one pixel at once (PixelKernel::pixelInterval), over its
// m valid buffers `valid` (indices into px, as collectValidBuffers gives them): per channel the
// value that the function above gives on that channel's values, bit for bit (equal values may
// trade places in a sort, so a bound that is a zero may differ in its sign). Why they are faster,
// not different: the three channels' sums run side by side in one loop (three independent chains
// of the same additions in the same order), the quantile is looked up once per pixel, and the
// three channels are sorted together by one sorting network on four-float lanes (Batcher's odd-
// even merge sort, pruned to m), where the per-channel path ran three comparison sorts.
void meanIntervals(const PixelBuffers& px, const int* valid, int m, double level,
                   ValueInterval out[3]);
/// meanIntervals after its first pass: `n` the sum of the m valid buffers' counts and `sum` their
/// count-weighted sums of R, G, B, added in index order (ranking.h, plainMeanPass, gives both
/// while it estimates the mean: the estimate and the interval share that pass).
void meanIntervalsFromSums(const PixelBuffers& px, const int* valid, int m, double n,
                           const double sum[3], double level, ValueInterval out[3]);
/// The plain mean's estimate (plainMeanPass, ranking.h) and meanIntervals of n pixels, out[3 i + c]
/// of px[i]'s channel c: the same bits as the two calls per pixel. With AVX2, two neighbouring
/// pixels of equal M (up to 64) go side by side through both passes, their chains of dependent
/// additions overlapping, and the second pass reads the buffers the first widened.
void meanEstimatesWithIntervals(const PixelBuffers* px, int n, double level, PixelEstimate* e,
                                ValueInterval* out);
void medianIntervals(const PixelBuffers& px, const int* valid, int m, double level,
                     ValueInterval out[3]);
/// medianIntervals of n pixels whose buffers are all valid (pixel i's valid buffers are 0 to
/// px[i].M - 1), out[3 i + c] of px[i]'s channel c: the same values, bit for bit. Two neighbouring
/// pixels of equal M (2 to 32) are sorted by one network on eight-float AVX lanes where the
/// processor has it (each half the four-float network's comparators on one pixel: minima and maxima
/// are exact), any other pixel by medianIntervals.
void medianIntervalsRun(const PixelBuffers* px, int n, double level, ValueInterval* out);
void yuenIntervals(const PixelBuffers& px, const int* valid, int m, int g, double level,
                   ValueInterval out[3]);
/// yuenIntervals of n pixels whose buffers are all valid, `trim(M)` the g of a pixel of M buffers:
/// the same values, bit for bit. Two neighbouring pixels of equal M (2 to 32) and at least two
/// values inside the trim are sorted by medianIntervalsRun's eight-float network, and their sums
/// run side by side on four-double AVX lanes (one lane per channel, the same additions in the same
/// order); any other pixel goes to yuenIntervals.
void yuenIntervalsRun(const PixelBuffers* px, int n, const std::function<int(int)>& trim,
                      double level, ValueInterval* out);

}  // namespace mcstat
