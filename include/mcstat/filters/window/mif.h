// Jung's (weighted) median image filter over an RGB image: MIF (thesis eq. 5.8), WMIF (eq. 5.6 with
// the centre weight of eq. 5.28) and, with alpha < 0.5, the weighted trimmed mean filter WTMIF of
// section 5.1.2; the weighted trimmed mean itself and its rules are in window_rank.h. Jung,
// "Rendering of Teeth and Dental Restorations using Robust Statistical Estimation Techniques", PhD
// thesis, University of Minnesota, 2016. After an estimator they make the hybrids MPE+MIF
// (eq. 5.15) and TMPE+WMIF (eq. 5.14).
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/window/window_rank.h"

namespace mcstat {

// ---- MIF / WMIF over an RGB image ---------------------------------------------------------------

/// WMIF(w(w_c), k x l) at pixel (x, y) (eq. 5.6 with the weights of eq. 5.28; MIF, eq. 5.8, for
/// centreWeight = 1; alpha < 0.5 gives the weighted trimmed mean filter WTMIF of section 5.1.2).
void wmifPixel(const RGBImageView& img, int x, int y, const SpatialParams& p, PixelEstimate& out,
               SpatialScratch& s);
/// wmifPixel over every pixel, one thread; `out` holds width * height * 3 floats (not `img.rgb`).
void wmifImage(const RGBImageView& img, const SpatialParams& p, float* out);

/// The registry entries "mif" and "wmif".
Operation mifOperation();
Operation wmifOperation();

}  // namespace mcstat
