// TMPE (tmpe.h): the ranked trimmed mean trimming a fraction alpha per side.
#include "mcstat/filters/pixel/tmpe.h"

#include <algorithm>
#include <cmath>

#include "mcstat/filters/pixel/confidence.h"
#include "mcstat/filters/pixel/ranking.h"

namespace mcstat {

int tmpeTrim(double alpha, int M) {
    if (M < 2 || !(alpha > 0.0)) return 0;
    // Jung eq. 5.1 sums ranks 1 + alpha*m .. m - alpha*m: alpha*m means are dropped per side. alpha
    // is meant to be i/m; floor(alpha*M + 1e-9) maps any alpha to an integer count, and the 1e-9
    // keeps alpha = i/M (rounded in binary) from becoming i - 1.
    const double c = std::floor(std::min(alpha, 1.0) * double(M) + 1e-9);
    return std::clamp(int(c), 0, (M - 1) / 2);
}

namespace {

/// Eq. 5.1's trim with alpha = rule.value.
int fractionTrim(const TrimRule& rule, double, int Mv) { return tmpeTrim(rule.value, Mv); }

}  // namespace

void estimateTMPE(const PixelBuffers& px, const TmpeParams& p, PixelEstimate& out,
                  EstimatorScratch& s) {
    rankedTrimmedMean(px, p, TrimRule{&fractionTrim, false, p.alpha}, out, s);
}

namespace {

/// The first M at which tmpeTrim(alpha, M) >= 1; beyond a statistics file's largest M (alpha = 0:
/// TMPE is the mean at every M).
int firstTrimmingM(double alpha) {
    constexpr int kLargestM = 999;
    for (int M = 1; M <= kLargestM; ++M)
        if (tmpeTrim(alpha, M) >= 1) return M;
    return kLargestM + 1;
}

}  // namespace

namespace {

PixelKernel bind(const ParamValues& values, const std::array<double, 3>& luma) {
    auto p = pixelParamsAs<TmpeParams>(values, luma);
    p.alpha = values.at("alpha").real;
    PixelKernel k = pixelKernel(p, &estimateTMPE, firstTrimmingM(p.alpha));
    // Yuen's interval with TMPE's own trim per side (confidence.h).
    k.intervalTarget = "the trimmed mean of the buffer means (Yuen), not the expected value";
    k.interval = [alpha = p.alpha](double* v, const double*, int m, double level) {
        return yuenInterval(v, m, tmpeTrim(alpha, m), level);
    };
    k.pixelInterval = [alpha = p.alpha](const PixelBuffers& px, const int* valid, int m,
                                        double level, ValueInterval out[3]) {
        yuenIntervals(px, valid, m, tmpeTrim(alpha, m), level, out);
    };
    k.runIntervals = [alpha = p.alpha](const PixelBuffers* px, int n, double level,
                                       ValueInterval* out) {
        yuenIntervalsRun(
            px, n, [alpha](int m) { return tmpeTrim(alpha, m); }, level, out);
    };
    return k;
}

}  // namespace

Operation tmpeOperation() {
    return pixelOperation("tmpe", "TMPE",
                          "Trimmed mean TMPE(alpha) (Jung eq. 5.1): drops floor(alpha*M) means per "
                          "side, averages the rest",
                          "Jung eq. 5.1",
                          {modeParam(), realParam("alpha", 0.0, 0.5, false, "0.25",
                                                  "breakdown point: 0 = mean, 0.5 = median (MPE)")},
                          &bind);
}

}  // namespace mcstat
