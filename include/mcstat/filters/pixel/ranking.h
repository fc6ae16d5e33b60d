// Robust pixel estimators over a pixel's M sub-buffer means: pure functions, no I/O, no OIIO types,
// shared by the renderer, the command-line tool, the plugin and the tests.
//
// Paper: Buisine, Delepoulle, Renaud, "Fireflies removing in Monte Carlo rendering with adaptive
// Median of meaNs", EGSR 2021.
//
// Rules shared by every estimator (docs/estimators.md has the long form):
// - A buffer is *valid* when its count is > 0 and all its channels are finite. Buffers with count 0
//   (spp < M) are left out silently; buffers holding NaN or +-Inf are left out and counted in
//   PixelEstimate::excluded. Every formula below runs over the valid buffers only (M_v of them).
// - No valid buffer: the estimate is 0 (black), kept = 0.
// - Counts are weights: wherever a formula averages buffer means, it uses sum(n_j * theta_j) /
// sum(n_j),
//   which is exactly the mean of the samples in those buffers and equals the paper's unweighted
//   average when counts are equal. Ranks, the median and the Gini coefficient use the means
//   unweighted, as in the paper.
// - Negative means: ranking and averaging take them as they are. The Gini coefficient (eq. 4) is
//   defined for non-negative values, so when the smallest mean is negative it is computed on the
//   means shifted by -min (the smallest becomes 0). Its result is clamped to [0, 1].
//   A zero (or all-equal) set has G = 0: the estimators return the mean, never 0/0.
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "mcstat/core/pixel_buffers.h"

namespace mcstat {

/// How an estimator treats colour.
enum class EstimatorMode {
    PerChannel,  ///< R, G and B ranked and reduced independently (each channel has its own G and c)
    Luminance,   ///< buffers ranked by luminance; the chosen buffers' RGB are returned (hue never
                 ///< mixes across channels of different buffers); G is computed on luminance
};

struct EstimatorParams {
    EstimatorMode mode = EstimatorMode::Luminance;
    /// Luminance weights, from the OCIO config (color.h), never hard-coded by callers.
    std::array<double, 3> luma{0.0, 0.0, 0.0};
    /// G-MoN_b threshold (eq. 5): mean when G <= threshold, MoN otherwise.
    double giniThreshold = 0.25;
    /// TMPE breakdown point alpha in [0, 0.5] (Jung eq. 5.1): floor(alpha * M_v + 1e-9) means are
    /// trimmed from each side, capped at floor((M_v - 1) / 2). 0 is the mean, 0.5 the median.
    double alpha = 0.25;
    /// Myriad scale gamma (Jung eq. 4.7) and meridian scale delta (eq. 4.8), both > 0. With
    /// scaleRelative they are factors of the pixel's input range (max - min of the valid values the
    /// estimator ranks): the thesis used 0.05 x range (section 4.2). Otherwise absolute values.
    double gamma = 0.05;
    double delta = 0.05;
    bool scaleRelative = true;
};

/// An estimate and its diagnostics. In Luminance mode the three diagnostic channels are equal.
struct PixelEstimate {
    std::array<float, 3> rgb{0.f, 0.f, 0.f};
    std::array<float, 3> gini{0.f, 0.f, 0.f};  ///< Gini coefficient used (0 where not computed)
    std::array<int, 3> kept{0, 0, 0};          ///< buffers that entered the final average
    int excluded = 0;                          ///< buffers left out for NaN/Inf values
};

/// Per-thread scratch space so the per-pixel functions never allocate after warm-up. The rank
/// estimators (mean, MoN, G-MoN, G-MoN_b, TMPE) use none up to M = 64: they rank on the stack.
struct EstimatorScratch {
    std::vector<int> order;
    std::vector<double> key;
    std::vector<double> sorted;
    std::vector<double> weight;  ///< per distinct value (filters/pixel/myriad.cpp)
    /// Set by the caller before an estimate to also get the estimate's buffer weights (AOVs,
    /// docs/aovs.md). Every estimator in luminance mode is a convex combination of whole buffers:
    /// it then fills bufferWeight with px.M weights w_j >= 0 summing to 1 (0 for buffers that did
    /// not enter, all 0 when no buffer is valid) such that rgb = sum_j w_j mean_j up to float
    /// rounding. The same weights applied to any other channel of the buffers (applyBufferWeights)
    /// keep every linear relation the buffers share with the beauty: AOVs that sum to the beauty
    /// in each buffer sum to the estimate. In channel mode R, G and B are ranked separately and
    /// no such weights exist: bufferWeight is left empty.
    bool wantWeights = false;
    std::vector<double> bufferWeight;
};

// ---- building blocks (exposed for tests and for later estimators) -------------------------------

/// Gini coefficient of `values` already sorted ascending (eq. 4), computed in double, with the
/// negative-value and zero-sum rules above. n == 0 or 1 gives 0.
double giniSorted(const double* values, size_t n);

/// Number of means trimmed from each side by G-MoN (section 4.3): c = floor(k - (1 - G) k) with
/// k = floor(M/2), clamped to floor((M-1)/2) so that at least one mean (odd M) or the two middle
/// means (even M) remain — the paper's c = k would divide by zero for even M.
int gmonTrim(double G, int M);

/// Fills `order` with the indices of the valid buffers (count > 0, count and every channel finite),
/// in index order, and sets `excluded` to the number of NaN/Inf buffers. Returns M_v.
int collectValidBuffers(const PixelBuffers& px, std::vector<int>& order, int& excluded);

namespace detail {
/// Test hook: with false, the rank estimators' fast path runs its portable code even on a CPU with
/// AVX2 (both versions give the same bits; the bit-identity test checks each). true restores the
/// CPU's choice. Returns the previous setting. Not thread-safe: call it between estimates.
bool setUseAvx2(bool on);
/// For filters/pixel/myriad.cpp: order[r] = the position of the key of rank r, in the order "key
/// ascending, ties by position", for n <= 64 keys, none NaN. `key` must have room for n rounded up
/// to a multiple of 8 (the padding is overwritten). The rank estimators' fast ranking.
void rankKeys(double* key, int n, int* order);
}  // namespace detail

// ---- the estimators -----------------------------------------------------------------------------

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

// ---- Jung 2016 thesis, chapters 4 and 5 ---------------------------------------------------------
// Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical Estimation
// Techniques", PhD thesis, University of Minnesota, 2016; myriad and meridian:
// filters/pixel/myriad.h The median pixel estimate MPE(m) (eq. 4.6, 5.2) *is* estimateMoN,
// including the even-M rule: eq. 5.2 with even m trims floor((m-1)/2) = m/2 - 1 per side and
// averages the two middle means. The registry lists it a second time as `median`.

/// Number of means TMPE trims from each side (eq. 5.1): c = floor(alpha * M + 1e-9) (the 1e-9
/// absorbs the rounding of alpha = i/M), clamped to [0, floor((M - 1) / 2)]. alpha = 0 gives 0 (the
/// mean), alpha >= floor((M-1)/2)/M (e.g. 0.5) gives the cap: MPE (eq. 5.2).
int tmpeTrim(double alpha, int M);

/// Trimmed mean pixel estimate TMPE(alpha) (eq. 5.1): rank the valid means, drop tmpeTrim(alpha,
/// M_v) from each side, count-weighted average of the rest (same ranking/weighting as G-MoN).
void estimateTMPE(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                  EstimatorScratch& s);

}  // namespace mcstat
