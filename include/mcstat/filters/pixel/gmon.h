// G-MoN: the adaptive median of means of Buisine, Delepoulle, Renaud, "Fireflies removing in Monte
// Carlo rendering with adaptive Median of meaNs", EGSR 2021, section 4.3: the Gini coefficient of
// the ranked means (eq. 4) decides how many are trimmed from each side (eq. 6), so a pixel whose
// means agree keeps the mean and a pixel with a firefly moves towards the median.
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

/// G-MoN (eq. 6) with c from the Gini coefficient (eq. 4), see gmonTrim (ranking.h).
void estimateGMoN(const PixelBuffers& px, const PixelParams& p, PixelEstimate& out,
                  EstimatorScratch& s);
/// The registry entry "gmon".
Operation gmonOperation();

}  // namespace mcstat
