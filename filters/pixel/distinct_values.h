// Internal to filters/pixel/: what the M-estimators (myriad.cpp, meridian.cpp) share. Both rank
// a pixel's valid values (luminances, or one channel), merge equal values into distinct values
// weighted by their summed counts, and scale their cost by a factor of the values' range (Jung
// 2016, section 4.2), of the range within Hampel's fence (the default), or by an absolute value.
#pragma once

#include "mcstat/filters/pixel/myriad.h"  // ScaleRule
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat::detail {

/// a is better than b (smaller cost; within a relative 1e-12 it is a tie, which the caller breaks).
bool clearlyLess(double a, double b);
/// Usable scale: a scale that underflowed to 0 becomes the smallest normal double (the selection
/// limit), an infinite one the largest (the mean limit).
double saneScale(double scale);
/// s.key[j] for every valid buffer j of s.order: its luminance (ch < 0) or channel ch.
void setKeys(const PixelBuffers& px, const PixelParams& p, EstimatorScratch& s, int ch);
/// Sorts the valid buffers by key (ties by buffer index) and merges equal keys:
/// s.sorted = distinct values ascending, s.weight = their summed counts. Returns the distinct
/// count.
int distinctValues(const PixelBuffers& px, EstimatorScratch& s);
/// The scale (ScaleRule, myriad.h): Range: factor x (max - min) of the distinct values; Hampel:
/// factor x (max - min) of the values within Hampel's fence (hampelRange), 1e-300 x the whole
/// range when that is 0 (the selection limit, in finite arithmetic); Absolute: factor.
/// After distinctValues (s.order ranked, s.sorted the K distinct values).
double scaleFor(double factor, ScaleRule rule, const EstimatorScratch& s, int K);
/// max - min of the valid buffers' keys x_j (s.key over s.order, ranked) within Hampel's fence
/// |x_j - med| <= 3 x 1.4826 x MAD, med the median of the keys and MAD the median of |x_j - med|
/// (buffers unweighted, as the ranks of the rank estimators; even counts average the two middle
/// values). MAD = 0 (more than half of the buffers share one value) gives 0.
double hampelRange(const EstimatorScratch& s);

/// The skeleton both M-estimators share: starts `out` (and the buffer weights when asked, all 0
/// until a buffer is chosen), collects the valid buffers, then for the luminance key (ch = -1) or
/// each channel in turn ranks the keys into distinct values and calls
/// `reduce(ch, K, scaleFor(factor, p.scale, s, K))`, which writes that channel's estimate.
template <class Params, class Reduce>
void estimateLocation(const PixelBuffers& px, const Params& p, double factor, PixelEstimate& out,
                      EstimatorScratch& s, Reduce reduce) {
    out = PixelEstimate{};
    s.bufferWeight.clear();
    if (s.wantWeights && p.mode == EstimatorMode::Luminance)
        s.bufferWeight.assign(size_t(px.M), 0.0);  // stays 0 when no buffer is valid
    if (collectValidBuffers(px, s.order, out.excluded) == 0) return;
    s.key.resize(size_t(px.M));
    const bool lum = p.mode == EstimatorMode::Luminance;
    for (int ch = lum ? -1 : 0; ch < (lum ? 0 : 3); ++ch) {
        setKeys(px, p, s, ch);
        const int K = distinctValues(px, s);
        reduce(ch, K, scaleFor(factor, p.scale, s, K));
    }
}

}  // namespace mcstat::detail
