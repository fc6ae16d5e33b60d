// The median of the M sub-buffer means: Buisine, Delepoulle, Renaud, "Fireflies removing in Monte
// Carlo rendering with adaptive Median of meaNs", EGSR 2021, eq. 2 (MoN), which is also Jung's
// median pixel estimate MPE(m) (Jung, "Rendering of Teeth and Dental Restorations using Robust
// Statistical Estimation Techniques", PhD thesis, University of Minnesota, 2016, eq. 4.6, 5.2),
// even-M rule included: eq. 5.2 with even m trims floor((m-1)/2) = m/2 - 1 per side and averages
// the two middle means. The registry lists it under both names, `mon` and `median`.
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

/// Median of means (eq. 2). Even M_v: the average of the two middle means (count-weighted).
void estimateMoN(const PixelBuffers& px, const PixelParams& p, PixelEstimate& out,
                 EstimatorScratch& s);
/// The registry entries "mon" (Buisine et al.) and "median" (Jung's MPE).
Operation monOperation();
Operation medianOperation();

}  // namespace mcstat
