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

namespace mcstat {

/// How an estimator treats colour.
enum class EstimatorMode {
    PerChannel,  ///< R, G and B ranked and reduced independently (each channel has its own G and c)
    Luminance,   ///< buffers ranked by luminance; the chosen buffers' RGB are returned (hue never
                 ///< mixes across channels of different buffers); G is computed on luminance
};

/// What every per-pixel estimator takes; an estimator with parameters of its own extends it
/// (TmpeParams, MyriadParams...).
struct PixelParams {
    EstimatorMode mode = EstimatorMode::Luminance;
    /// Luminance weights, from the OCIO config (color.h), never hard-coded by callers.
    std::array<double, 3> luma{0.0, 0.0, 0.0};
};

/// An estimate and its diagnostics. In Luminance mode the three diagnostic channels are equal.
struct PixelEstimate {
    std::array<float, 3> rgb{0.f, 0.f, 0.f};
    std::array<float, 3> gini{0.f, 0.f, 0.f};  ///< Gini coefficient used (0 where not computed)
    std::array<int, 3> kept{0, 0, 0};          ///< buffers that entered the final average
    int excluded = 0;                          ///< buffers left out for NaN/Inf values
};

/// Per-thread scratch space so the per-pixel functions never allocate after warm-up. The rank
/// estimators (mean, MoN, G-MoN, G-MoN_b, TMPE) use none up to M = 64: they rank on the stack.
struct EstimatorScratch {
    std::vector<int> order;
    std::vector<double> key;
    std::vector<double> sorted;
    std::vector<double> weight;  ///< per distinct value (filters/pixel/myriad.cpp)
    /// Set by the caller before an estimate to also get the estimate's buffer weights (AOVs,
    /// docs/aovs.md). Every estimator in luminance mode is a convex combination of whole buffers:
    /// it then fills bufferWeight with px.M weights w_j >= 0 summing to 1 (0 for buffers that did
    /// not enter, all 0 when no buffer is valid) such that rgb = sum_j w_j mean_j up to float
    /// rounding. The same weights applied to any other channel of the buffers (applyBufferWeights)
    /// keep every linear relation the buffers share with the beauty: AOVs that sum to the beauty
    /// in each buffer sum to the estimate. In channel mode R, G and B are ranked separately and
    /// no such weights exist: bufferWeight is left empty.
    bool wantWeights = false;
    std::vector<double> bufferWeight;
};

/// Fills `order` with the indices of the valid buffers (count > 0, count and every channel finite),
/// in index order, and sets `excluded` to the number of NaN/Inf buffers. Returns M_v.
int collectValidBuffers(const PixelBuffers& px, std::vector<int>& order, int& excluded);

}  // namespace mcstat
