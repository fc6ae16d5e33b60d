// Intervals from a pixel's stored spread rather than its buffers (docs/confidence.md): what a
// compact file's buffer-free pixels give, and the expected value's interval (`citarget=expected`),
// which any estimator's caller may ask for. Pure functions over numbers, named by no estimator
// family, so the image layer calls them directly; implemented with the per-estimator intervals
// (filters/pixel/confidence.cpp), whose Student quantile they share.
#pragma once

#include "mcstat/filters/estimate.h"

namespace mcstat {

/// Student's t interval for a pixel's count-weighted mean from a stored spread, as meanInterval
/// gives it on the buffers themselves: `perSampleVariance` is s^2 = sum n_j (y_j - mean)^2 /
/// (buffers - 1) (a compact file's spread, FORMAT.md "Version 7"), `samples` N = sum n_j, df =
/// buffers - 1. Fewer than two buffers, or a spread that is not a finite non-negative number:
/// [-inf, +inf], full. What a compact file's buffer-free pixels give (docs/confidence.md).
ValueInterval spreadInterval(double mean, double perSampleVariance, double samples, int buffers,
                             double level);
/// The interval for a pixel's expected value (`citarget=expected`, image/expected_interval.h):
/// mean +- t_{(1+L)/2, buffers-1} sqrt(max(s2, pooledS2) / samples), s2 the pixel's per-sample
/// variance and pooledS2 its neighbourhood's (either may be NaN: not known; both NaN, or fewer
/// than two buffers: [-inf, +inf], full; mean NaN: NaN).
ValueInterval expectedInterval(double mean, double s2, double pooledS2, double samples, int buffers,
                               double level);

}  // namespace mcstat
