// G-MoN (gmon.h): the ranked trimmed mean with the Gini-driven trim.
#include "mcstat/filters/pixel/gmon.h"

#include <algorithm>
#include <cmath>

#include "mcstat/filters/pixel/confidence.h"
#include "mcstat/filters/pixel/ranking.h"

namespace mcstat {

int gmonTrim(double G, int M) {
    if (M < 2) return 0;
    // Section 4.3: c = floor(k - (1 - G) k), k = floor(M / 2).
    const int k = M / 2;
    int c = int(std::floor(double(k) - (1.0 - G) * double(k)));
    // Keep at least the median mean (odd M) or the two middle means (even M): c = k with even M
    // would leave M - 2c = 0 means in eq. 6.
    return std::clamp(c, 0, (M - 1) / 2);
}

namespace {

/// gmonTrim for G in [0, 1] (the Gini coefficient's range): there k - (1 - G) k >= 0 (1 - G <= 1
/// and the product rounds monotonically), so the conversion to int truncates exactly as floor
/// would, and the call to floor (not inlined without SSE4.1) is saved. Same value as gmonTrim.
int gmonTrimUnit(const TrimRule&, double G, int M) {
    if (M < 2) return 0;
    const int k = M / 2;
    const int c = int(double(k) - (1.0 - G) * double(k));
    return std::clamp(c, 0, (M - 1) / 2);
}

}  // namespace

void estimateGMoN(const PixelBuffers& px, const GmonParams& p, PixelEstimate& out,
                  EstimatorScratch& s) {
    // Eq. 6: the trim from the Gini coefficient of the ranked means.
    rankedTrimmedMean(px, p, TrimRule{&gmonTrimUnit, true, 0.0, p.gini}, out, s);
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
    k.runIntervals = [](const PixelBuffers* px, int n, double level, ValueInterval* out) {
        medianIntervalsRun(px, n, level, out);
    };
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
