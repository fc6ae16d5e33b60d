// G-MoN_b: the binary variant of Buisine, Delepoulle, Renaud, "Fireflies removing in Monte Carlo
// rendering with adaptive Median of meaNs", EGSR 2021, eq. 5: the mean when the Gini coefficient
// of the means (eq. 4) is at most a threshold, the median of means (eq. 2) otherwise.
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/pixel/gmon.h"  // GmonParams
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

struct GmonbParams : GmonParams {
    double threshold = 0.25;  ///< Gini threshold (eq. 5): mean when G <= threshold, else MoN
};
/// G-MoN_b (eq. 5).
void estimateGMoNb(const PixelBuffers& px, const GmonbParams& p, PixelEstimate& out,
                   EstimatorScratch& s);
/// The registry entry "gmonb".
Operation gmonbOperation();

}  // namespace mcstat
