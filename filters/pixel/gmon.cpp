// G-MoN (gmon.h): the ranked trimmed mean with the Gini-driven trim.
#include "mcstat/filters/pixel/gmon.h"

#include "mcstat/filters/pixel/confidence.h"
#include "mcstat/filters/pixel/ranking.h"

namespace mcstat {

void estimateGMoN(const PixelBuffers& px, const GmonParams& p, PixelEstimate& out,
                  EstimatorScratch& s) {
    rankedTrimmedMean(px, p, {TrimRule::Gini, 0.0, p.gini}, out, s);
}

ParamSpec giniParam() {
    // Eq. 4 is defined for non-negative values, where both choices are it. Below zero, abs weighs
    // a buffer by its distance from zero whatever its sign, so a negative firefly (the ring a
    // Mitchell or Lanczos filter leaves around a positive one) raises G as a positive one does;
    // shift computes G on x - min, where a negative outlier is the one zero among equal values
    // (G ~ 1/M, no trim). Gini of deviations from the median, or of max - x, were the other
    // candidates: both are large on every smooth pixel (the mean's efficiency lost everywhere).
    return enumParam("gini", {"abs", "shift"}, "abs",
                     "what the Gini coefficient is computed on: abs: the magnitudes |x| (a "
                     "negative outlier counts as a positive one); shift: the means shifted by "
                     "-min (blind to a negative outlier). Both are eq. 4 on non-negative means",
                     {{"magnitude", "abs"}, {"shifted", "shift"}});
}

GiniInput giniInput(const ParamValues& values) {
    const auto it = values.find("gini");  // absent (values bound by hand): the default
    return it != values.end() && it->second.text == "shift" ? GiniInput::Shifted
                                                            : GiniInput::Magnitudes;
}

namespace {

PixelKernel bind(const ParamValues& values, const std::array<double, 3>& luma) {
    auto p = pixelParamsAs<GmonParams>(values, luma);
    p.gini = giniInput(values);
    PixelKernel k = pixelKernel(p, &estimateGMoN, /*smallestRobustM=*/4);
    // The median of means' order-statistic interval (confidence.h: G-MoN estimates a location
    // between the median of means and the mean; the median's interval is exact whatever the tails).
    k.intervalTarget =
        "the population median of the buffer means (not the expected value: in a firefly pixel the "
        "mean lies above it)";
    k.interval = [](double* v, const double*, int m, double level) {
        return medianInterval(v, m, level);
    };
    k.pixelInterval = [](const PixelBuffers& px, const int* valid, int m, double level,
                         ValueInterval out[3]) { medianIntervals(px, valid, m, level, out); };
    return k;
}

}  // namespace

// G-MoN trims c = floor(k G) <= floor((M - 1) / 2), k = floor(M / 2), and for M = 3 the Gini
// coefficient of three values stays below 1: the first M it can differ from the mean at is 4.
Operation gmonOperation() {
    return pixelOperation(
        "gmon", "G-MoN",
        "Adaptive median of means: trims c = floor(G*floor(M/2)) means per side (eq. 4, 6)",
        "Buisine et al. eq. 4, 6", {modeParam(), giniParam()}, &bind);
}

}  // namespace mcstat
