// The plain mean of every sample, from the sub-buffers (Buisine, Delepoulle, Renaud, "Fireflies
// removing in Monte Carlo rendering with adaptive Median of meaNs", EGSR 2021, eq. 1): what a
// renderer's beauty holds, and the reference every robust estimator is measured against.
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

/// sum(n_j theta_j) / sum(n_j) over the valid buffers (eq. 1).
void estimateMean(const PixelBuffers& px, const PixelParams& p, PixelEstimate& out,
                  EstimatorScratch& s);
/// The registry entry "mean".
Operation meanOperation();

}  // namespace mcstat
