// The removed-light layers of an operation's result over a statistics file (docs/removed-light.md):
// where the robust operation took light the buffers support, and where it took noise. The
// statistics are filters/removed_light.h's; this layer reads the buffers and appends channels.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <array>

#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/image/removed_light_pass.h"

namespace mcstat {

/// The luminance of each pixel's valid buffers over `roi` of `src`, in one float image whose R, G,
/// B are their count-weighted mean, its standard error and their number (lumaSpread), read by
/// blocks and in parallel through estimate(). Errors on dst.
bool lumaSpreadImage(OIIO::ImageBuf& dst, const StatsImage& src, const std::array<double, 3>& luma,
                     OIIO::ROI roi, int nthreads = 0);
bool lumaSpreadImage(OIIO::ImageBuf& dst, StatsBlockSource& src, const std::array<double, 3>& luma,
                     OIIO::ROI roi, int nthreads = 0);

/// Appends to `robust`, an operation's result over `src` (R, G, B first; same data window), five
/// channels in luminance (the luma weights of the file's working space):
///   removed.Y           d = Y(plain mean) - Y(result): the energy removed (negative: added)
///   removed.se          the plain mean's standard error from the buffers (lumaSpread)
///   removed.z           d / se, the pixel's own evidence (a lone firefly: 1)
///   removed.zlocal      sum d / sqrt(sum se^2) over the window (localRemovedZ)
///   removed.significant 1 where zlocal > opt.zLimit: light the buffers support was removed
/// and the attributes mcstat:removed:energyFraction (sum d / sum Y(mean) over the image) and
/// mcstat:removed:significantFraction (the share of sum d in significant pixels),
/// mcstat:removed:zImage (the test over the whole image as one window: light removed thinly
/// everywhere is real in sum though no region shows it), :radius and :zLimit. Errors on `robust`.
bool appendRemovedLight(OIIO::ImageBuf& robust, const StatsImage& src,
                        const std::array<double, 3>& luma, const RemovedLightOptions& opt = {},
                        int nthreads = 0);
bool appendRemovedLight(OIIO::ImageBuf& robust, StatsBlockSource& src,
                        const std::array<double, 3>& luma, const RemovedLightOptions& opt = {},
                        int nthreads = 0);

}  // namespace mcstat
