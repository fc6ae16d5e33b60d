// What float rounding alone can make of two values: every sub-buffer value is stored as a float,
// so two results computed from the same floats in other orders (an estimator that trims nothing
// against the mean, a re-encoded file, another thread count) may differ in their last bits. Such
// a difference is neither light (keep_light_image.cpp) nor evidence (compare.cpp).
#pragma once

#include <algorithm>
#include <cmath>

namespace mcstat {

/// Float ulps (2^-23 of the larger magnitude) within which two values count as equal.
inline constexpr double kFloatRoundingUlps = 4.0;

/// Whether |a - b| is within kFloatRoundingUlps float ulps of max(|a|, |b|). False for NaN.
inline bool withinFloatRounding(double a, double b) {
    return std::fabs(a - b) <=
           kFloatRoundingUlps * std::ldexp(std::max(std::fabs(a), std::fabs(b)), -23);
}

}  // namespace mcstat
