// Internal to filters/pixel/: what the M-estimators (myriad.cpp, meridian.cpp) share. Both rank
// a pixel's valid values (luminances, or one channel), merge equal values into distinct values
// weighted by their summed counts, and scale their cost by a factor of the values' range (Jung
// 2016, section 4.2).
#pragma once

#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat::detail {

/// a is better than b (smaller cost; within a relative 1e-12 it is a tie, which the caller breaks).
bool clearlyLess(double a, double b);
/// Usable scale: a scale that underflowed to 0 becomes the smallest normal double (the selection
/// limit), an infinite one the largest (the mean limit).
double saneScale(double scale);
/// s.key[j] for every valid buffer j of s.order: its luminance (ch < 0) or channel ch.
void setKeys(const PixelBuffers& px, const PixelParams& p, EstimatorScratch& s, int ch);
/// Sorts the valid buffers by key (ties by buffer index) and merges equal keys:
/// s.sorted = distinct values ascending, s.weight = their summed counts. Returns the distinct
/// count.
int distinctValues(const PixelBuffers& px, EstimatorScratch& s);
/// The scale: factor x (max - min) of the distinct values when relative, else factor.
double scaleFor(double factor, bool relative, const EstimatorScratch& s, int K);

}  // namespace mcstat::detail
