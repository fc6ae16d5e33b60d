// Image-comparison metrics of `mcstat --diff`: pure functions over interleaved RGB float arrays.
// docs/metrics.md defines each one; in short:
// - relMSE: mean over pixels and channels of (x - r)^2 / (r^2 + eps), on scene-linear values.
// - PSNR and SSIM: on display-encoded values (the caller applies the OCIO display transform),
//   clamped to [0, 1]. SSIM (Wang et al. 2004): 11x11 Gaussian window, sigma 1.5, K1 = 0.01,
//   K2 = 0.03, per channel, averaged; the window is renormalised at image borders.
// - firefly pixel: Y > ratio * Y_ref and Y - Y_ref > floor, Y the luminance of scene-linear values
//   (luma coefficients from the OCIO config); defaults ratio 2, floor 0.1 (a tenth of display
//   white).
// - normalised bias and noise (Jung 2016 thesis, eq. 5.25-5.27) on luminance: per pixel
//   E'_i = (Y_i - Yref_i) / max(|Yref_i|, eps) (eps = 0.01 for black reference pixels), bias
//   B = mean of E'_i, noise = mean of (E'_i - B)^2 (the variance of E' over the pixels, 1/N).
// - energy: sum of Y over sum of Y_ref, minus 1, Y the scene-linear luminance: the light an image
//   took (negative) or added, what a robust image must say (docs/keep-light.md).
// - detail: how much of the reference's pixel-scale detail the image holds, on display-encoded
//   values clamped to [0, 1]: with h(v) = v minus the mean of its 3x3 neighbourhood (a high
//   pass), detail = sum h(x) h(r) / sum h(r)^2 over pixels and channels, the least-squares slope
//   of the image's high pass on the reference's. 1: all of it; a blur lowers it toward 0; noise,
//   uncorrelated with the reference, leaves its expectation at 1 (it spreads it, not shifts it).
// Pixels where either image is not finite are left out of every metric and counted.
#pragma once

#include <array>
#include <cstddef>
#include <string>

namespace mcstat {

struct DiffOptions {
    std::array<double, 3> luma{0.0, 0.0, 0.0};
    /// The working space of both images (color_space.h; empty: the OCIO config's scene_linear):
    /// SSIM's display values go through a display transform right for it (applyDisplayTransform).
    std::string space;
    double relmseEpsilon = 0.01;
    double fireflyRatio = 2.0;
    double fireflyFloor = 0.1;
    /// Floor of the normalised error's denominator (eq. 5.25): max(|Yref|, eps), so black
    /// reference pixels measure the absolute error in units of eps instead of dividing by 0.
    double normEpsilon = 0.01;
};

struct DiffMetrics {
    double relMSE = 0.0;
    double psnr = 0.0;  ///< dB; +inf for identical display images
    double ssim = 1.0;
    long fireflies = 0;
    double normBias = 0.0;   ///< Jung eq. 5.26: mean normalised error (signed)
    double normNoise = 0.0;  ///< Jung eq. 5.27: variance of the normalised error over pixels
    double detail = 1.0;  ///< slope of the image's 3x3 high pass on the reference's (NaN: flat ref)
    /// The light the image holds against the reference's: sum of Y / sum of Y_ref - 1 over the
    /// compared pixels (scene-linear luminance; -0.25: a quarter of the light is gone). NaN when
    /// the reference's sum is not positive.
    double energy = 0.0;
    long normFloored = 0;  ///< pixels whose |Yref| < normEpsilon (denominator floored)
    long nonFinite = 0;    ///< pixels left out because a value was NaN or Inf
    long pixels = 0;       ///< pixels compared
};

/// The per-pixel terms the metrics above are built from, for one pixel of scene-linear RGB `x`
/// against the reference `r` (3 floats each). compareImages and errorMap both use it, so the error
/// map shows exactly what relMSE averages and what the firefly count counts.
struct PixelError {
    bool finite = false;   ///< all six values finite; when false the other fields are unset
    double relSum = 0.0;   ///< sum over R, G, B of (x - r)^2 / (r^2 + eps): 3 x the relMSE term
    double y = 0.0;        ///< luminance of x
    double yRef = 0.0;     ///< luminance of r
    bool firefly = false;  ///< y > ratio * yRef and y - yRef > floor
};
PixelError pixelError(const float* x, const float* r, const DiffOptions& opt);

/// Per-pixel error map of scene-linear RGB `lin` against `ref` (npixels*3 floats each):
/// relerr[p] = relSum / 3, the mean over R, G, B of (x - r)^2 / (r^2 + eps), whose mean over the
/// pixels is relMSE; firefly[p] = 1 for a firefly pixel, else 0. Both are NaN where a value of
/// either pixel is NaN or Inf (the pixels every metric leaves out). Either output may be null.
void errorMap(const float* lin, const float* ref, size_t npixels, const DiffOptions& opt,
              float* relerr, float* firefly);

/// `lin`/`ref` are scene-linear RGB, `disp`/`refDisp` the same images display-encoded; all
/// width*height*3 floats.
DiffMetrics compareImages(const float* lin, const float* ref, const float* disp,
                          const float* refDisp, int width, int height, const DiffOptions& opt);

/// SSIM of two single-channel images (stride = floats between consecutive pixels); pixels where
/// mask is false are left out of the average (mask may be null).
double ssimChannel(const float* a, const float* b, size_t stride, int width, int height,
                   const bool* mask);

/// The detail metric of one channel (see the top of this file): sum h(a) h(b) and sum h(b)^2,
/// h(v) = v minus the mean of its 3x3 neighbourhood among the pixels where mask is true (cut at
/// the borders), values clamped to [0, 1], added to `cross` and `refPower`. Pixels where mask is
/// false count neither as a centre nor as a neighbour (mask may be null).
void detailSums(const float* a, const float* b, size_t stride, int width, int height,
                const bool* mask, double& cross, double& refPower);

}  // namespace mcstat
