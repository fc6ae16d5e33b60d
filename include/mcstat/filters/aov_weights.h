// AOVs through robust operations: one shared step that applies an operation's weights to every
// channel that is not the beauty (alpha, light groups, light-path passes, data passes, ID mattes).
// Pure functions, no I/O, no OIIO types.
//
// Why weights: every operation decides from the beauty how much each of its inputs counts (a
// sub-buffer for the per-pixel estimators, a window pixel's sub-buffer for the 3D filters, a
// sample for the per-sample operations). Applying those same convex weights to every other
// channel keeps any linear relation that holds in each input (AOVs summing to the beauty,
// premultiplied colour against alpha) in the output, up to float rounding. docs/aovs.md has the
// classes, the rules and the guarantees.
#pragma once

#include <cstddef>
#include <vector>

#include "mcstat/exr-deep/stats_file.h"  // AovClass

namespace mcstat {

/// Per-thread scratch of applyAovWeights (no allocation after warm-up).
struct AovScratch {
    std::vector<double> sum, weight;
};

/// One output pixel of `A` AOV channels from `n` weighted inputs: input i has weight
/// `weight[i]` (>= 0; the operation's, summing to 1 over the inputs it used) and values
/// `aov[i * A + a]`. Per class (`cls[a]`):
/// - alpha, light, data: sum_i w_i x_ia. A non-finite x_ia is left out of channel a alone and
///   the weights of the rest are renormalised (a broken pass of one render does not blank the
///   pixel); with no finite weighted value, or no weight at all, the result is 0, as the beauty
///   of a pixel without a valid input is.
/// - id: labels are never averaged: x_ia of the input of largest weight (the lowest index on
///   ties; input 0 when every weight is 0), whatever it holds.
/// Sums run in double in input order, rounded once to float.
void applyAovWeights(const double* weight, size_t n, const float* aov, size_t A,
                     const AovClass* cls, float* out, AovScratch& scratch);

/// The classes of `aovs` as an array (for applyAovWeights).
std::vector<AovClass> aovClasses(const std::vector<AovChannel>& aovs);

}  // namespace mcstat
