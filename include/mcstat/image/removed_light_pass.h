// The removed-light layers (removed_light_layers.h, docs/removed-light.md) in two steps that need
// no second read of the buffers: a pixel's five values while the estimate's pass holds its
// buffers (removedLightPixel), then the image-wide sums and the neighbourhood test over the
// finished image (finishRemovedLight). estimate() runs the first step when the caller sets
// PixelKernel::removedLight; appendRemovedLight, for every other operation, reads the buffers
// again for the same first step. Both give the same channels bit for bit.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <array>
#include <string>
#include <vector>

#include "mcstat/core/params.h"

namespace mcstat {

struct Operation;

/// The window and threshold of the neighbourhood test.
struct RemovedLightOptions {
    int radius = 2;       ///< window (2 radius + 1)^2 of the pooled test
    double zLimit = 3.0;  ///< removed.significant is 1 where removed.zlocal > zLimit
};

/// Prefix of the channels appendRemovedLight adds.
inline constexpr const char* kRemovedPrefix = "removed.";

/// The five channels, in order: removed.Y, removed.se, removed.z, removed.zlocal,
/// removed.significant.
std::vector<std::string> removedLightChannels();

/// One pixel's first step, from its result's R, G, B and its buffers' luminance mean and standard
/// error (lumaSpread, rounded to float): out = {d, se, z, the luminance mean, 0}. d = mean -
/// Y(rgb) (0 where not finite), z = removedZ(d, se). The fourth value holds the luminance mean
/// until finishRemovedLight replaces it by zlocal.
void removedLightPixel(const float* rgb, float spreadMean, float spreadSe,
                       const std::array<double, 3>& luma, float out[5]);
/// Where removedLightPixel's `out` holds the standard error and the luminance mean (before
/// finishRemovedLight): an estimate() pass with PixelKernel::removedLight and no finish gives the
/// buffers' luminance spread of every pixel along with the estimate (keep_light_image.cpp).
inline constexpr int kPixelStepSe = 1, kPixelStepLumaMean = 3;

/// The second step over `img`, whose channels [first, first + 5) hold removedLightPixel's values
/// for the R, G, B of channels 0-2: the image's sums (in pixel order), removed.zlocal and
/// removed.significant, and the attributes (removed_light_layers.h). Errors on img.
bool finishRemovedLight(OIIO::ImageBuf& img, int first, const std::array<double, 3>& luma,
                        const RemovedLightOptions& opt, int nthreads);

/// The modifiers removed, removedradius, removedz as operation values (the image layer reads them
/// from there: applyOperation then computes the layers in the estimate's pass) and back.
void setRemovedLightValues(ParamValues& values, const RemovedLightOptions& opt);
bool removedLightValues(const ParamValues& values, RemovedLightOptions& opt);

/// Whether applyOperation computes the layers in its own pass for `op` (a per-pixel estimator
/// without keeplight, whose light given back would change what was removed): else the caller
/// appends them afterwards (appendRemovedLight).
bool removedLightInPass(const Operation& op, bool keepLight);

}  // namespace mcstat
