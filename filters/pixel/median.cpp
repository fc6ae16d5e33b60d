// Median of means / MPE (median.h): the ranked trimmed mean trimming all but the middle.
#include "mcstat/filters/pixel/median.h"

#include "mcstat/filters/pixel/confidence.h"
#include "mcstat/filters/pixel/ranking.h"

namespace mcstat {

namespace {

/// Eq. 2: floor((M_v - 1) / 2) per side, the median (odd M_v) or the two middle means (even).
int medianTrim(const TrimRule&, double, int Mv) { return (Mv - 1) / 2; }

}  // namespace

void estimateMoN(const PixelBuffers& px, const PixelParams& p, PixelEstimate& out,
                 EstimatorScratch& s) {
    rankedTrimmedMean(px, p, TrimRule{&medianTrim}, out, s);
}

namespace {

PixelKernel bind(const ParamValues& values, const std::array<double, 3>& luma) {
    const PixelParams p = pixelParams(values, luma);
    PixelKernel k = pixelKernel(p, &estimateMoN, /*smallestRobustM=*/3);
    // The exact order-statistic interval for the median of the buffer means (confidence.h).
    k.intervalTarget =
        "the population median of the buffer means (not the expected value: in a firefly pixel the "
        "mean lies above it)";
    k.interval = [](double* v, const double*, int m, double level) {
        return medianInterval(v, m, level);
    };
    k.pixelInterval = [](const PixelBuffers& px, const int* valid, int m, double level,
                         ValueInterval out[3]) { medianIntervals(px, valid, m, level, out); };
    k.runIntervals = [](const PixelBuffers* px, int n, double level, ValueInterval* out) {
        medianIntervalsRun(px, n, level, out);
    };
    return k;
}

}  // namespace

// The two middle means of M = 2 average to the mean: the first M it can differ at is 3.
Operation monOperation() {
    return pixelOperation("mon", "MoN", "Median of the M sub-buffer means (Buisine et al. eq. 2)",
                          "Buisine et al. eq. 2", {modeParam()}, &bind);
}

Operation medianOperation() {
    return pixelOperation("median", "MPE (median)",
                          "Median pixel estimate MPE (Jung eq. 4.6, 5.2): the same estimator as "
                          "--mon",
                          "Jung eq. 4.6, 5.2", {modeParam()}, &bind);
}

}  // namespace mcstat
