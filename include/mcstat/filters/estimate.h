// What every operation's kernel computes with (operation.h): how it treats colour, the estimate
// of one output pixel with its diagnostics, and the per-thread scratch of a per-pixel kernel and
// of a window kernel's pass.
// Shared by every family (filters/pixel, filters/window) without one reaching into another.
#pragma once

#include <array>
#include <utility>
#include <vector>

namespace mcstat {

/// How an estimator treats colour.
enum class EstimatorMode {
    PerChannel,  ///< R, G and B ranked and reduced independently (each channel has its own G and c)
    Luminance,   ///< buffers ranked by luminance; the chosen buffers' RGB are returned (hue never
                 ///< mixes across channels of different buffers); G is computed on luminance
};

/// An estimate and its diagnostics. In Luminance mode the three diagnostic channels are equal.
struct PixelEstimate {
    std::array<float, 3> rgb{0.f, 0.f, 0.f};
    std::array<float, 3> gini{0.f, 0.f, 0.f};  ///< Gini coefficient used (0 where not computed)
    std::array<int, 3> kept{0, 0, 0};          ///< buffers that entered the final average
    int excluded = 0;                          ///< buffers left out for NaN/Inf values
};

/// A confidence interval for one channel of one pixel (filters/pixel/confidence.h): [low, high]
/// at the level asked for, or wider when the pixel's buffers cannot give that level (`full`: the
/// interval is then the range of the values, [-inf, +inf] for one value). No value: NaN.
struct ValueInterval {
    double low = 0.0, high = 0.0;
    bool full = false;
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
    /// Set by the caller before an estimate to also get the buffers' luminances as the estimate
    /// computed them, for the removed light's spread (removed_light.h, lumaSpread8FromKeys):
    /// key[j * stride] = (l0 R_j + l1 G_j) + l2 B_j in double, count[j * stride] = n_j. The rank
    /// estimators' fast path leaves them, and sets `given`, when it ranked by luminance with
    /// exactly these coefficients and every buffer is valid (count > 0 and finite, finite means);
    /// otherwise `given` stays false and the caller computes the spread from the buffers.
    struct LumaKeys {
        double* key = nullptr;
        double* count = nullptr;
        int stride = 1;
        std::array<double, 3> luma{0.0, 0.0, 0.0};
        bool given = false;
    } lumaKeys;
};

/// Per-thread scratch of a window kernel's pass (operation.h: WindowPass). The family derives its
/// own scratch from it; the image layer reads only the weights it asked for. AOVs (docs/aovs.md),
/// luminance mode: with wantWeights set by the caller, a filtered pixel leaves in `weights` every
/// element that entered its average with its share (the shares sum to 1). An element is a window
/// pixel source[element] (over an image: buffer -1) or buffer `buffer` of the window pixel
/// source[element] (over sub-buffers). Empty in channel mode, where R, G and B keep different
/// elements. `source` (window pixels, coordinates of the pass's input) is filled whenever
/// wantWeights is set.
struct WindowScratch {
    struct WeightedElement {
        int element;  ///< index into source
        int buffer;   ///< the sub-buffer j, or -1 for an image pixel
        double weight;
    };
    virtual ~WindowScratch() = default;
    bool wantWeights = false;
    std::vector<WeightedElement> weights;
    std::vector<std::pair<int, int>> source;
};

}  // namespace mcstat
