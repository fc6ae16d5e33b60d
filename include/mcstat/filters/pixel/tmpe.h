// TMPE: the trimmed mean pixel estimate of Jung, "Rendering of Teeth and Dental Restorations using
// Robust Statistical Estimation Techniques", PhD thesis, University of Minnesota, 2016, eq. 5.1:
// rank the valid means, drop tmpeTrim(alpha, M_v) from each side, average the rest with counts as
// weights (the same ranking and weighting as G-MoN). alpha = 0 is the mean, 0.5 the median (MPE).
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

struct TmpeParams : PixelParams {
    /// Breakdown point alpha in [0, 0.5]: floor(alpha * M_v + 1e-9) means trimmed from each side,
    /// capped at floor((M_v - 1) / 2).
    double alpha = 0.25;
};
/// TMPE(alpha) (eq. 5.1).
void estimateTMPE(const PixelBuffers& px, const TmpeParams& p, PixelEstimate& out,
                  EstimatorScratch& s);
/// The registry entry "tmpe".
Operation tmpeOperation();

}  // namespace mcstat
