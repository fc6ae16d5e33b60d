// G-MoN_b (gmonb.h): the ranked trimmed mean, nothing or all but the middle trimmed.
#include "mcstat/filters/pixel/gmonb.h"

#include "mcstat/filters/pixel/confidence.h"
#include "mcstat/filters/pixel/ranking.h"

namespace mcstat {

namespace {

/// Eq. 5: nothing when G <= the threshold (rule.value), else the median's floor((M_v - 1) / 2).
int thresholdTrim(const TrimRule& rule, double G, int Mv) {
    return G <= rule.value ? 0 : (Mv - 1) / 2;
}

}  // namespace

void estimateGMoNb(const PixelBuffers& px, const GmonbParams& p, PixelEstimate& out,
                   EstimatorScratch& s) {
    rankedTrimmedMean(px, p, TrimRule{&thresholdTrim, true, p.threshold, p.gini}, out, s);
}

namespace {

PixelKernel bind(const ParamValues& values, const std::array<double, 3>& luma) {
    auto p = pixelParamsAs<GmonbParams>(values, luma);
    p.threshold = values.at("threshold").real;
    p.gini = giniInput(values);
    PixelKernel k = pixelKernel(p, &estimateGMoNb, /*smallestRobustM=*/3);
    // The median of means' order-statistic interval, as for G-MoN (confidence.h).
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

Operation gmonbOperation() {
    return pixelOperation(
        "gmonb", "G-MoN_b", "Mean when the Gini coefficient G <= threshold, else MoN (eq. 5)",
        "Buisine et al. eq. 5",
        {modeParam(), realParam("threshold", 0.0, 1.0, false, "0.25", "Gini threshold"),
         giniParam()},
        &bind);
}

}  // namespace mcstat
