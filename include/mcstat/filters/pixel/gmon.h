// G-MoN: the adaptive median of means of Buisine, Delepoulle, Renaud, "Fireflies removing in Monte
// Carlo rendering with adaptive Median of meaNs", EGSR 2021, section 4.3: the Gini coefficient of
// the ranked means (eq. 4) decides how many are trimmed from each side (eq. 6), so a pixel whose
// means agree keeps the mean and a pixel with a firefly moves towards the median.
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/pixel/pixel_estimate.h"
#include "mcstat/filters/pixel/ranking.h"  // GiniInput

namespace mcstat {

struct GmonParams : PixelParams {
    /// What G is computed on (ranking.h): the magnitudes |x_j| by default, so that a negative
    /// outlier is seen as a positive one is; Shifted is the form before issue 38. Both are eq. 4
    /// on non-negative means.
    GiniInput gini = GiniInput::Magnitudes;
};

/// Number of means trimmed from each side by G-MoN (Buisine et al. section 4.3):
/// c = floor(k - (1 - G) k) with k = floor(M/2), clamped to floor((M-1)/2) so that at least one
/// mean (odd M) or the two middle means (even M) remain: the paper's c = k would divide by zero for
/// even M.
int gmonTrim(double G, int M);

/// G-MoN (eq. 6) with c from the Gini coefficient (eq. 4), see gmonTrim.
void estimateGMoN(const PixelBuffers& px, const GmonParams& p, PixelEstimate& out,
                  EstimatorScratch& s);
/// Parameter "gini" (abs / shift) of G-MoN and G-MoN_b.
ParamSpec giniParam();
/// GiniInput from the parsed value of giniParam (absent: the default, Magnitudes).
GiniInput giniInput(const ParamValues& values);
/// The registry entry "gmon".
Operation gmonOperation();

}  // namespace mcstat
