// The light a robust operation removed: is it noise, or real light the estimator is biased
// against? (issue 37, docs/removed-light.md). Pure functions, no I/O, no OIIO types.
//
// Per pixel, the removed energy is d = Y(mean) - Y(robust), in luminance. Its scale is the
// standard error of the mean, se. Under the hypothesis that the robust estimate and the mean
// estimate the same value (the robust operation removed only noise), E[d] = 0, and when one of
// the two is efficient the variance of their difference is the difference of their variances
// (Hausman, "Specification tests in econometrics", Econometrica 1978, lemma 2.1). With Gaussian
// noise the mean is the efficient one: Var(d) = Var(robust) - Var(mean), which is below se^2
// while the robust estimate's variance is under twice the mean's (the median of normal means:
// pi/2 times). With heavy tails the robust estimate is the better one: Var(d) = Var(mean) -
// Var(robust) < se^2. Either way z = d / se is conservative: |z| large says the pixel's buffers
// support the removed light.
//
// A firefly is one buffer far above the others: removing it gives z = 1 exactly whatever its
// size (buffers 0, ..., 0, F: d = F / M, se = F / M), and k of M buffers at F give
// z = sqrt(k (M - 1) / (M - k)). A caustic is seen in many buffers of many pixels: pixels are
// independent, so over a (2r+1)^2 window Z = sum d / sqrt(sum se^2) is N(0, <= 1) under the
// hypothesis, and grows with the number of pixels that lost light. A lone firefly keeps Z <= 1;
// a real caustic the robust estimate darkens reaches Z >> 3.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>

#include "mcstat/core/pixel_buffers.h"

namespace mcstat {

/// The luminance mean of a pixel's valid buffers and its standard error.
struct LumaSpread {
    double mean = 0.0;  ///< count-weighted mean of the buffers' luminances (the plain mean's Y)
    double se = 0.0;    ///< its standard error; 0 with fewer than 2 valid buffers
    int valid = 0;      ///< buffers with count > 0 and finite R, G, B (pixel_estimate.h's rule)
};

/// Whether buffer j of px is valid by pixel_estimate.h's rule: count > 0 and R, G, B finite.
bool isValidBuffer(const PixelBuffers& px, int j);

/// Mean and standard error of the luminance `luma` . rgb over px's valid buffers, in double.
/// Buffer j of count n_j has variance sigma^2 / n_j, so with N = sum n_j and M_v valid buffers,
/// sigma^2 = sum n_j (Y_j - mean)^2 / (M_v - 1) and se = sqrt(sigma^2 / N); equal counts give the
/// textbook s / sqrt(M). No valid buffer: all 0. One valid buffer: se = 0 (nothing to measure).
/// Sums of Y up to 1e38 stay finite: deviations are formed before they are squared, and a
/// square that overflows double makes se +inf (z then 0), never NaN.
LumaSpread lumaSpread(const PixelBuffers& px, const std::array<double, 3>& luma);

/// lumaSpread of n pixels, out[i] of px[i]: the same values, bit for bit. Each of lumaSpread's
/// sums is a chain of M dependent additions, so one pixel's spread waits on the adder's latency;
/// here four pixels of equal M (2 to 64) whose buffers are all valid run as the four lanes of
/// AVX2 registers where the processor has it (each lane the same operations in the same order,
/// without fused multiply-adds), and any other pixel runs lumaSpread.
void lumaSpreads(const PixelBuffers* px, int n, const std::array<double, 3>& luma, LumaSpread* out);

/// lumaSpread of eight pixels of equal M (2 to 64) whose buffers are all valid, from their
/// buffers' luminances and counts as an estimate computed them (EstimatorScratch::LumaKeys: pixel
/// i's buffer j at key[8 j + i], count[8 j + i], Y_j = (l0 R + l1 G) + l2 B in double with
/// lumaSpread's coefficients): the same values, bit for bit, without reading the buffers again.
void lumaSpread8FromKeys(const double* key, const double* count, int M, LumaSpread out[8]);

/// z = d / se for one pixel: 0 when d is 0 or not finite, or se is 0, NaN or +inf (a pixel
/// without the buffers to measure its noise is never called significant).
inline double removedZ(double d, double se) {
    if (d == 0.0 || !std::isfinite(d) || !(se > 0.0) || !std::isfinite(se)) return 0.0;
    return d / se;
}

/// The neighbourhood significance: out[p] = sum d / sqrt(sum se^2) over the (2 radius + 1)^2
/// window around p, clipped to the width x height image (row-major, one value per pixel).
/// Non-finite d or se count as 0 (left out). 0 where the window's sum of se^2 is 0. Rows run on
/// nthreads threads (0: all), each output its own sums: the same values on any thread count.
void localRemovedZ(const float* d, const float* se, int width, int height, int radius, float* out,
                   int nthreads = 1);
/// localRemovedZ over values `stride` floats apart (d[p * stride], se[p * stride]: two channels of
/// an interleaved image), out[p * outStride]; no temporary of the image's size. out's values must
/// not be d's or se's.
void localRemovedZ(const float* d, const float* se, size_t stride, int width, int height,
                   int radius, float* out, size_t outStride, int nthreads);

}  // namespace mcstat
