// What every per-pixel estimator (filters/pixel/) takes and gives: a pixel's M sub-buffer means in,
// an estimate with its diagnostics and, on request, its buffer weights out. Pure functions, no I/O,
// no OIIO types, shared by the renderer, the command-line tool, the plugin and the tests.
//
// Rules shared by every estimator (docs/estimators.md has the long form):
// - A buffer is *valid* when its count is > 0 and all its channels are finite. Buffers with count 0
//   (spp < M) are left out silently; buffers holding NaN or +-Inf are left out and counted in
//   PixelEstimate::excluded. Every formula below runs over the valid buffers only (M_v of them).
// - No valid buffer: the estimate is 0 (black), kept = 0.
// - Counts are weights: wherever a formula averages buffer means, it uses
//   sum(n_j * theta_j) / sum(n_j), which is exactly the mean of the samples in those buffers and
//   equals the paper's unweighted average when counts are equal. Ranks, the median and the Gini
//   coefficient use the means unweighted, as in the paper.
// - Negative means: ranking and averaging take them as they are. The Gini coefficient (eq. 4) is
//   defined for non-negative values; below zero it is computed on the magnitudes |x| by default
//   (GiniInput::Magnitudes, ranking.h: a negative outlier counts as a positive one), or on the
//   means shifted by -min (GiniInput::Shifted). Its result is clamped to [0, 1].
//   A zero (or all-equal) set has G = 0: the estimators return the mean, never 0/0.
#pragma once

#include <array>
#include <vector>

#include "mcstat/core/pixel_buffers.h"
#include "mcstat/filters/estimate.h"
#include "mcstat/filters/operation.h"

namespace mcstat {

/// What every per-pixel estimator takes; an estimator with parameters of its own extends it
/// (TmpeParams, MyriadParams...).
struct PixelParams {
    EstimatorMode mode = EstimatorMode::Luminance;
    /// Luminance weights, from the OCIO config (color.h), never hard-coded by callers.
    std::array<double, 3> luma{0.0, 0.0, 0.0};
};

/// The kernel of estimator `estimate` (a function of the pixel, `Params` and the output) with
/// `params` bound: what every BufferMeans operation's bind returns. `Params` derives from
/// PixelParams (its mode decides the diagnostics and whether weights exist).
template <class Params>
PixelKernel pixelKernel(const Params& params,
                        void (*estimate)(const PixelBuffers&, const Params&, PixelEstimate&,
                                         EstimatorScratch&),
                        int smallestRobustM) {
    PixelKernel k;
    k.estimate = [params, estimate](const PixelBuffers& px, PixelEstimate& out,
                                    EstimatorScratch& s) { estimate(px, params, out, s); };
    k.mode = params.mode;
    k.smallestRobustM = smallestRobustM;
    return k;
}

/// PixelParams (mode, luma) from parsed values that hold "mode" (or not: luminance).
PixelParams pixelParams(const ParamValues& values, const std::array<double, 3>& luma);
/// An estimator's own `Params` (derived from PixelParams) with its PixelParams part from `values`;
/// the caller fills in the rest.
template <class Params>
Params pixelParamsAs(const ParamValues& values, const std::array<double, 3>& luma) {
    Params p;
    static_cast<PixelParams&>(p) = pixelParams(values, luma);
    return p;
}

}  // namespace mcstat
