// The plain mean (Buisine et al. 2021, eq. 1): the ranked trimmed mean with nothing trimmed.
#include "mcstat/filters/pixel/mean.h"

#include "mcstat/filters/pixel/confidence.h"
#include "mcstat/filters/pixel/ranking.h"

namespace mcstat {

void estimateMean(const PixelBuffers& px, const PixelParams& p, PixelEstimate& out,
                  EstimatorScratch& s) {
    rankedTrimmedMean(px, p, TrimRule{}, out, s);  // no trim: the one-pass sum
}

namespace {

PixelKernel bind(const ParamValues& values, const std::array<double, 3>& luma) {
    const PixelParams p = pixelParams(values, luma);
    PixelKernel k = pixelKernel(p, &estimateMean, /*smallestRobustM=*/1);
    // Student's t interval with the batch-means standard error (confidence.h).
    k.intervalTarget =
        "the expected value of the pixel (its true value), by Student t over the buffer means";
    k.interval = [](double* v, const double* n, int m, double level) {
        return meanInterval(v, n, m, level);
    };
    k.pixelInterval = [](const PixelBuffers& px, const int* valid, int m, double level,
                         ValueInterval out[3]) { meanIntervals(px, valid, m, level, out); };
    k.estimatesWithIntervals = &meanEstimatesWithIntervals;
    return k;
}

}  // namespace

Operation meanOperation() {
    return pixelOperation("mean", "mean",
                          "Plain mean of every sample (eq. 1), from the sub-buffers",
                          "Buisine et al. eq. 1", {}, &bind);
}

}  // namespace mcstat
