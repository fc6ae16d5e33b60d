// What review tools show a person: an image display-encoded through the active OCIO config
// (displayTransform) and two images' differences measured as seen (diffImages). Errors are recorded
// on the destination ImageBuf or returned in `err`; nothing throws.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <string>

#include "mcstat/analysis/metrics.h"

namespace mcstat {

/// Display-encodes the R, G, B channels of `src` through the active OCIO config's default display
/// and view (float result, unclamped).
bool displayTransform(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, OIIO::ROI roi = {},
                      int nthreads = 0);
OIIO::ImageBuf displayTransform(const OIIO::ImageBuf& src, OIIO::ROI roi = {}, int nthreads = 0);

/// Compares the RGB of `img` with `ref` (same size): see metrics.h. False with `err` on mismatch.
bool diffImages(const OIIO::ImageBuf& img, const OIIO::ImageBuf& ref, const DiffOptions& opt,
                DiffMetrics& out, std::string& err);

}  // namespace mcstat
