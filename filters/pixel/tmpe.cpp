// TMPE (tmpe.h): the ranked trimmed mean trimming a fraction alpha per side.
#include "mcstat/filters/pixel/tmpe.h"

#include "mcstat/filters/pixel/confidence.h"
#include "mcstat/filters/pixel/ranking.h"

namespace mcstat {

void estimateTMPE(const PixelBuffers& px, const TmpeParams& p, PixelEstimate& out,
                  EstimatorScratch& s) {
    rankedTrimmedMean(px, p, {TrimRule::Fraction, p.alpha}, out, s);
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
