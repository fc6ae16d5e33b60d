// G-MoN (gmon.h): the ranked trimmed mean with the Gini-driven trim.
#include "mcstat/filters/pixel/gmon.h"

#include "mcstat/filters/pixel/ranking.h"

namespace mcstat {

void estimateGMoN(const PixelBuffers& px, const PixelParams& p, PixelEstimate& out,
                  EstimatorScratch& s) {
    rankedTrimmedMean(px, p, {TrimRule::Gini, 0.0}, out, s);
}

namespace {

PixelKernel bind(const ParamValues& values, const std::array<double, 3>& luma) {
    const PixelParams p = pixelParams(values, luma);
    return pixelKernel(p, &estimateGMoN, /*smallestRobustM=*/4);
}

}  // namespace

// G-MoN trims c = floor(k G) <= floor((M - 1) / 2), k = floor(M / 2), and for M = 3 the Gini
// coefficient of three values stays below 1: the first M it can differ from the mean at is 4.
Operation gmonOperation() {
    return pixelOperation(
        "gmon", "G-MoN",
        "Adaptive median of means: trims c = floor(G*floor(M/2)) means per side (eq. 4, 6)",
        "Buisine et al. eq. 4, 6", {modeParam()}, &bind);
}

}  // namespace mcstat
