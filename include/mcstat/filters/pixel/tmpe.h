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
/// Number of means TMPE trims from each side (Jung eq. 5.1): c = floor(alpha * M + 1e-9) (the 1e-9
/// absorbs the rounding of alpha = i/M), clamped to [0, floor((M - 1) / 2)]. alpha = 0 gives 0 (the
/// mean), alpha >= floor((M-1)/2)/M (e.g. 0.5) gives the cap: MPE (eq. 5.2).
int tmpeTrim(double alpha, int M);

/// TMPE(alpha) (eq. 5.1).
void estimateTMPE(const PixelBuffers& px, const TmpeParams& p, PixelEstimate& out,
                  EstimatorScratch& s);
/// The registry entry "tmpe".
Operation tmpeOperation();

}  // namespace mcstat
