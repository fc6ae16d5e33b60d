// The confidence interval for a pixel's expected value (`:ci=LEVEL:citarget=expected`,
// docs/confidence.md): Student's t about the pixel's count-weighted mean, with the per-sample
// variance the larger of the pixel's own (the spread of its buffer means) and the mean of its
// neighbours' within a (2R + 1)^2 window (R = `cipool`).
//
// Why the neighbourhood: on a firefly scene most pixels never draw the rare bright path that
// carries part of their expected value, so their buffers agree, their own variance is small and
// the t interval sits narrow and low (it held an 8,192-spp reference in 71-73 % of pixel channels
// of the fixture's default and caustic scenes at 256 spp, M = 16). Neighbouring pixels see the
// same light paths with about the same probability; their variances, fireflies included, say how
// wide the pixel's distribution is. Pooled over 9 x 9 pixels the interval held the reference in
// 93 % of them (measured in docs/confidence.md).
#pragma once

#include <vector>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat {

/// One pixel's count-weighted mean, per-sample variance s^2 = sum n_j (y_j - mean)^2 / (m - 1) of
/// R, G, B over its m valid buffers (NaN when m < 2), its samples N = sum n_j and m. A compact
/// file's pixel that kept only its mean gives its stored spread.
struct PixelSpread {
    double mean[3] = {0.0, 0.0, 0.0};
    double s2[3] = {0.0, 0.0, 0.0};
    double samples = 0.0;
    int buffers = 0;
};

/// Every pixel's PixelSpread, in the image's pixel order.
std::vector<PixelSpread> pixelSpreads(const StatsImage& src, int nthreads);

/// Per pixel and channel (p * 3 + c) the mean of the finite s^2 of the pixels within `radius`
/// (a (2 radius + 1)^2 window clipped to the image), NaN where none is finite.
std::vector<double> pooledSampleVariance(const std::vector<PixelSpread>& spreads, int width,
                                         int height, int radius, int nthreads);

}  // namespace mcstat
