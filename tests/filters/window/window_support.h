// The window filters' ImageBuf forms with hand-built parameters, as the tests call them: the image
// layer takes a bound kernel (windowFilter), the window family binds it (windowKernel).
#pragma once

#include <OpenImageIO/imagebuf.h>

#include "mcstat/filters/window/window_kernel.h"
#include "mcstat/image/imageops.h"

namespace mcstat::testing {

/// Jung's 3D filters with `p` over the sub-buffers of `s`.
inline OIIO::ImageBuf filter3D(const StatsImage& s, const SpatialParams& p, OIIO::ROI roi = {},
                               int nthreads = 0) {
    return windowFilter(s, windowKernel(Neighbourhood::SubBuffers, p), roi, nthreads);
}

/// Jung's (weighted) median image filter with `p` over the R, G, B of `img`.
inline OIIO::ImageBuf medianImageFilter(const OIIO::ImageBuf& img, const SpatialParams& p,
                                        OIIO::ROI roi = {}, int nthreads = 0) {
    return windowFilter(img, windowKernel(Neighbourhood::Image, p), roi, nthreads);
}

}  // namespace mcstat::testing
