// Robust pixel estimators over a pixel's M sub-buffer means: pure functions, no I/O, no OIIO types,
// shared by the renderer, the command-line tool, the plugin and the tests.
//
// Paper: Buisine, Delepoulle, Renaud, "Fireflies removing in Monte Carlo rendering with adaptive
// Median of meaNs", EGSR 2021 (../shared/papers/buisine2021-gmon-median-of-means.txt).
//
// Rules shared by every estimator (docs/estimators.md has the long form):
// - A buffer is *valid* when its count is > 0 and all its channels are finite. Buffers with count 0
//   (spp < M) are left out silently; buffers holding NaN or +-Inf are left out and counted in
//   PixelEstimate::excluded. Every formula below runs over the valid buffers only (M_v of them).
// - No valid buffer: the estimate is 0 (black), kept = 0.
// - Counts are weights: wherever a formula averages buffer means, it uses sum(n_j * theta_j) / sum(n_j),
//   which is exactly the mean of the samples in those buffers and equals the paper's unweighted
//   average when counts are equal. Ranks, the median and the Gini coefficient use the means unweighted,
//   as in the paper.
// - Negative means: ranking and averaging take them as they are. The Gini coefficient (eq. 4) is
//   defined for non-negative values, so when the smallest mean is negative it is computed on the
//   means shifted by -min (the smallest becomes 0). Its result is clamped to [0, 1].
//   A zero (or all-equal) set has G = 0: the estimators return the mean, never 0/0.
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace mcstat {

/// How an estimator treats colour.
enum class EstimatorMode {
    PerChannel,  ///< R, G and B ranked and reduced independently (each channel has its own G and c)
    Luminance,   ///< buffers ranked by luminance; the chosen buffers' RGB are returned (hue never mixes
                 ///< across channels of different buffers); G is computed on luminance
};

struct EstimatorParams {
    EstimatorMode mode = EstimatorMode::Luminance;
    /// Luminance weights, from the OCIO config (color.h), never hard-coded by callers.
    std::array<double, 3> luma{0.0, 0.0, 0.0};
    /// G-MoN_b threshold (eq. 5): mean when G <= threshold, MoN otherwise.
    double giniThreshold = 0.25;
};

/// One pixel's sub-buffers: M means (RGB interleaved) and M counts.
struct PixelBuffers {
    const float* mean = nullptr;   ///< [j*3 + c]
    const float* count = nullptr;  ///< [j]
    int M = 0;
};

/// An estimate and its diagnostics. In Luminance mode the three diagnostic channels are equal.
struct PixelEstimate {
    std::array<float, 3> rgb{0.f, 0.f, 0.f};
    std::array<float, 3> gini{0.f, 0.f, 0.f};  ///< Gini coefficient used (0 where not computed)
    std::array<int, 3> kept{0, 0, 0};          ///< buffers that entered the final average
    int excluded = 0;                          ///< buffers left out for NaN/Inf values
};

/// Per-thread scratch space so the per-pixel functions never allocate after warm-up.
struct EstimatorScratch {
    std::vector<int> order;
    std::vector<double> key;
    std::vector<double> sorted;
};

// ---- building blocks (exposed for tests and for later estimators) --------------------------------

/// Gini coefficient of `values` already sorted ascending (eq. 4), computed in double, with the
/// negative-value and zero-sum rules above. n == 0 or 1 gives 0.
double giniSorted(const double* values, size_t n);

/// Number of means trimmed from each side by G-MoN (section 4.3): c = floor(k - (1 - G) k) with
/// k = floor(M/2), clamped to floor((M-1)/2) so that at least one mean (odd M) or the two middle
/// means (even M) remain — the paper's c = k would divide by zero for even M.
int gmonTrim(double G, int M);

// ---- the estimators ------------------------------------------------------------------------------

/// Plain mean of all samples: sum(n_j theta_j) / sum(n_j) over the valid buffers (eq. 1).
void estimateMean(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                  EstimatorScratch& s);
/// Median of means (eq. 2). Even M_v: the average of the two middle means (count-weighted).
void estimateMoN(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                 EstimatorScratch& s);
/// G-MoN (eq. 6) with c from the Gini coefficient (eq. 4), see gmonTrim.
void estimateGMoN(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                  EstimatorScratch& s);
/// G-MoN_b (eq. 5): the mean when G <= p.giniThreshold, else MoN.
void estimateGMoNb(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                   EstimatorScratch& s);

}  // namespace mcstat
