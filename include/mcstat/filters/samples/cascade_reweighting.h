// Zirr, Hanika and Dachsbacher, "Re-weighting Firefly Samples for Improved Finite-Sample Monte
// Carlo Estimates", Computer Graphics Forum 37(6), 2018: every sample of a pixel is split by its
// luminance between two neighbouring cascades of a geometric series of luminance scales
// (start * base^i); the estimate sums the cascades, each weighted by how well its scale is
// supported by samples in the pixel and its 3x3 neighbourhood (kappa: how many samples a scale
// needs to be trusted), so that a lone sample far brighter than its neighbourhood's is
// down-weighted. The details (the split weights, the top cascade's clamp, the reliability from
// the pixel's and the 3x3 block's counts of the cascade and its two neighbours, the colour-based
// term with its constants 0.05 and 0.6) follow the authors' public reference implementation
// (github.com/tszirr/ic.js, rw/split.cpp and rw/reweight.fs); docs/reweighting.md is the long
// form and says which detail comes from where.
//
// Pure and deterministic: no I/O, no OIIO types. The renderer (online), `mcstat --reweight`
// (offline, from the per-sample records) and the tests share these functions, so online and
// offline cascades are equal bit for bit when they see the same float32 samples in the same
// order. The image-wide steps (reweightImage, scatterRemoved) run on `nthreads` threads
// (core/parallel.h) and give the same bits for any thread count: every pixel's sums run in one
// fixed order, whichever thread computes it.
//
// Conventions:
// - Luminance Y = luma . rgb in double. Y <= start (zero, negative, dark) goes to cascade 0
//   whole. A sample with a non-finite component is skipped and counted (it changes no sum).
// - Sums are doubles; a pixel's cascade i holds the sum of its samples' shares (not divided).
// - A pixel without samples estimates 0.
// - Pixels outside the image repeat the nearest edge pixel (the reference's texture clamp).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace mcstat {

/// The method's parameters. count, base and start shape the cascades (fixed while rendering);
/// kappa only the reweighting.
struct ReweightParams {
    int count = 6;        ///< cascades (reference implementation, split.cpp: "paper default")
    double base = 8.0;    ///< ratio between neighbouring cascades' scales (idem)
    double start = 1.0;   ///< scale of cascade 0 (idem)
    double kappa = 32.0;  ///< samples a scale needs to be reliable (viewer default, rw.html)
    /// Not the paper's: 0 is its method. r > 0 scatters what the weights removed from each pixel
    /// (its mean minus its estimate, RGB) evenly over the image pixels of its (2r+1)^2 window,
    /// so that the image's total energy is the mean's (docs/reweighting.md, "Energy").
    int spread = 0;
    std::array<double, 3> luma{0.2126, 0.7152, 0.0722};  ///< from the colour config (color.h)
};

/// Range checks; `err` is one line naming the parameter ("reweight: base must be ...").
bool validateReweightParams(const ReweightParams& p, std::string& err);

/// Where one sample goes: cascades `lower` and `lower + 1` with weights wLower, wUpper.
struct CascadeSplit {
    int lower = 0;
    double wLower = 1.0, wUpper = 0.0;
};
/// The split of a sample of luminance `y` (finite). For start*base^j < y < start*base^(j+1),
/// wLower = (s_j / y - 1 / base) / (1 - 1 / base), wUpper = 1 - wLower, so that the sample's
/// "count" wLower * y / s_j + wUpper * y / s_(j+1) is exactly 1. y <= start: cascade 0 whole.
/// Above the top scale s_(count-1): wLower = 0, wUpper = s_(count-1) / y (the sample is clamped
/// to the top scale's luminance).
CascadeSplit splitSample(double y, const ReweightParams& p);

/// One pixel's cascades while samples arrive: count * 3 double sums, the samples taken and the
/// non-finite ones skipped.
struct CascadePixel {
    std::vector<double> sum;  ///< [i * 3 + c]
    uint64_t n = 0;           ///< finite samples splatted
    uint64_t skipped = 0;     ///< samples with a non-finite component (or luminance)
};

/// Adds sample `rgb` (float32 radiance) to `px` (its sums sized count * 3 on first use). A
/// non-finite sample only increments `skipped`.
void splatSample(CascadePixel& px, const float rgb[3], const ReweightParams& p);

/// The cascades of a whole image: the reweighting's input.
struct CascadeImage {
    int width = 0, height = 0, count = 0;
    std::vector<double> sum;  ///< [(p * count + i) * 3 + c], p = y * width + x
    std::vector<uint64_t> n;  ///< [p] finite samples
};

/// The reweighted estimate of every pixel into `rgb` ([p * 3 + c]), from cascades `img` built
/// with `p`'s count/base/start. Per pixel and cascade i, with S_j(q) pixel q's cascade j sum,
/// s_j its scale, N the pixel's sample count and lum() the luminance:
///   c_i(q)   = lum(S_(i-1)(q) / s_(i-1) + S_i(q) / s_i + S_(i+1)(q) / s_(i+1))   (counts)
///   local    = c_i(p) / kappa,  global = mean over the 3x3 block of c_i / kappa
///   r        = global - 1/kappa, or local - 1/kappa when that is >= 0
///   colour   = max(lum(E_(i-1)), 0.05) * N / (kappa s_i) * mix(1 + 0.6 (base - 1), 1, min(1,
///   1/kappa)) w_i      = clamp((r + colour) / 2, 0, 1),   E_i = E_(i-1) + w_i S_i(p) / N
/// (E_(-1) = 0; the missing neighbours of cascades 0 and count-1 are left out). Optionally each
/// pixel's weights into `weights` ([p * count + i]). With p.spread > 0 the removed energy is then
/// scattered (ReweightParams::spread). Deterministic, the same for any `nthreads` (0: all
/// cores).
void reweightImage(const CascadeImage& img, const ReweightParams& p, std::vector<float>& rgb,
                   std::vector<double>* weights = nullptr, int nthreads = 1);

/// What the estimate keeps of one sample of luminance `y` given its pixel's cascade weights `w`
/// (reweightImage's): `kept` = w_j wLower + w_(j+1) wUpper and `taken` = wLower + wUpper (1 but
/// above the top scale). The estimate is sum_k kept_k rgb_k / N exactly, so the AOVs follow the
/// beauty with the same per-sample weights (docs/aovs.md).
void sampleShares(double y, const ReweightParams& p, const double* w, double& kept, double& taken);
/// The spread variant's step: each pixel's `removed` (nch values) added evenly to the image
/// pixels of its (2 radius + 1)^2 window, clipped to the image; `add` gets the sums.
/// Pixel q's sum adds the shares of the pixels whose windows hold it in scanline order (as a
/// scatter in scanline order would), so it is the same for any `nthreads` (0: all cores).
void scatterRemoved(int width, int height, int radius, size_t nch,
                    const std::vector<double>& removed, std::vector<double>& add, int nthreads = 1);

}  // namespace mcstat
