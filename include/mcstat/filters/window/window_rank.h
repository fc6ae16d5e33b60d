// The weighted trimmed mean over a window that every window filter of Jung's thesis, chapter 5, is
// made of: the (weighted) median image filter MIF / WMIF (eq. 5.6-5.8, weights eq. 5.28) over an
// RGB image (mif.h), and the 3D filters 3DWTMF, 3DWMF, 3DMF (eq. 5.19-5.21) over the sub-buffers
// of a k x l window of pixels (filter3d.h). Pure functions over plain arrays, no I/O, no OIIO
// types; the ImageBuf forms are in image/imageops.h.
//
// Thesis: Jung, "Robust statistical pixel estimation", 2016
// (Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical Estimation
// Techniques", PhD thesis, University of Minnesota, 2016). docs/spatial_filters.md has the long
// form. The hybrids are compositions: MPE+MIF (eq. 5.15) = estimateMoN then MIF, TMPE+WMIF
// (eq. 5.14) = estimateTMPE then WMIF.
//
// One rule covers every filter here, the weighted trimmed mean of eq. 5.6 / 5.19:
// - The window holds *elements*: pixels (MIF/WMIF) or the valid sub-buffers of the window's pixels
//   (3D filters). Element i has a value x_i (RGB), an integer weight w_i and a count n_i (its
//   samples; 1 for image pixels).
// - w_i duplicates x_i (eq. 5.7): w_i = centreWeight for the element(s) of the centre pixel, 1 for
//   every other pixel (eq. 5.28, generalised to k x l); in 3D every buffer of the centre pixel gets
//   the centre weight ("the same weight is applied to the sample radiance mean for the same
//   pixel"). s = sum w_i.
// - The s duplicated values are sorted (luminance or per channel, see EstimatorMode; ties by
//   element order: window row, column, buffer index) and c = floor(alpha * s + 1e-9) are dropped
//   from each side, capped at floor((s - 1) / 2). alpha >= that cap over s (e.g. 0.5) is the
//   weighted median of eq. 5.6 / 5.20: for odd s the middle value, for even s the two middle values
//   averaged.
// - Counts weight the final average, not the ranks (as in every estimator of filters/pixel/): if
// r_i
//   of element i's copies survive the trimming, the result is sum r_i n_i x_i / sum r_i n_i. With
//   equal counts this is eq. 5.19's plain average of the kept copies; with a 1 x 1 window it makes
//   3DMF exactly MPE (estimateMoN) and 3DWTMF(alpha, w = 1) exactly TMPE(alpha), including unequal
//   counts; with alpha = 0 and w = 1 it is the mean of every sample in the window.
// - Adaptive M (BufferVotes::PerSample, which filter3D takes for StatsHeader::adaptiveM): every
//   *sample* votes once in the ranking. Buffer j of pixel q, holding n_j samples, is the element
//   (x_j, n_j, w_q n_j): w_q n_j copies, so a pixel's samples weigh the same in the ranking
//   whatever its M_p (a 17-buffer pixel no longer outvotes a one-buffer neighbour 17 to 1), and s
//   and the trimming count copies of samples. Each copy is one sample, so the average is
//   sum r_i x_i / sum r_i, r_i of the w_q n_j copies kept: the mean of the kept samples, as
//   r_i n_i is for one vote per buffer (alpha = 0, w = 1: the window's sample mean). Counts must be
//   integers in [1, kMaxBufferVoteCount]; other finite positive counts (never in a validated file)
//   make the buffer invalid. Fixed-M data votes per buffer (PerBuffer), as above.
// - Borders (the thesis does not say): the window is clipped to the image. Only pixels inside the
//   image are elements, so s shrinks at borders and corners (a 3x3 corner window has 4 pixels,
//   hence an even s and a two-value median). No padding value is invented and no pixel counted
//   twice.
// - Invalid elements are left out and counted in PixelEstimate::excluded: an image pixel with a
//   NaN/Inf channel, a buffer with a NaN/Inf channel or count or a negative count (as
//   collectValidBuffers), with PerSample votes also a count that is not an integer or is above
//   kMaxBufferVoteCount. Empty buffers (count 0) are left out silently. A window with no valid
//   element gives black (kept = 0). A NaN centre pixel with valid neighbours is therefore replaced
//   by the (weighted) median of the neighbours.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "mcstat/core/params.h"
#include "mcstat/core/pixel_buffers.h"
#include "mcstat/filters/estimate.h"
#include "mcstat/filters/operation.h"

namespace mcstat {

/// Largest window side accepted (k, l <= this, odd).
inline constexpr int kMaxSpatialWindow = 255;
/// Largest centre weight accepted (w_c of eq. 5.28).
inline constexpr int64_t kMaxCentreWeight = 1000000;
/// Largest buffer count that votes with BufferVotes::PerSample: 2^24, the largest count a
/// statistics file may hold (exr-deep/FORMAT.md: every integer up to it is exact in a float32).
inline constexpr int64_t kMaxBufferVoteCount = int64_t(1) << 24;

struct SpatialParams {
    /// Luminance: elements ranked by luminance, the chosen elements' RGB averaged (a window's
    /// result is a mix of whole pixels / buffers, never R of one with G of another). PerChannel:
    /// R, G, B ranked and trimmed independently.
    EstimatorMode mode = EstimatorMode::Luminance;
    /// Luminance weights, from the OCIO config (color.h).
    std::array<double, 3> luma{0.0, 0.0, 0.0};
    /// Window width k and height l in pixels, odd, in [1, kMaxSpatialWindow], centred on the pixel.
    int windowWidth = 3;
    int windowHeight = 3;
    /// Integer weight w_c of the centre pixel (eq. 5.28), in [1, kMaxCentreWeight]; 1 is MIF/3DMF.
    int64_t centreWeight = 1;
    /// Breakdown point in [0, 0.5] (eq. 5.19): c = floor(alpha * s + 1e-9) copies trimmed per side,
    /// capped at floor((s-1)/2). 0.5 is the (weighted) median of MIF/WMIF/3DMF/3DWMF.
    double alpha = 0.5;
};

/// Checks the ranges above; false with a one-line message naming the field and value.
bool validateSpatialParams(const SpatialParams& p, std::string& err);

/// Number of copies trimmed from each side of s weighted copies (eq. 5.6, 5.19):
/// clamp(floor(alpha * s + 1e-9), 0, floor((s - 1) / 2)); 0 for s < 2.
int64_t spatialTrim(double alpha, int64_t s);

/// One element of a window: a pixel or a sub-buffer.
struct WindowElement {
    const float* rgb = nullptr;  ///< 3 finite floats
    double count = 1.0;          ///< n_i > 0: weight of the value in the final average
    int64_t weight = 1;          ///< w_i >= 1: duplication in the ranking (eq. 5.7)
};

/// One window pixel of a 3D filter: its valid buffers in rank order (ascending key, ties by buffer
/// index), as the k-way merge of eq. 5.24 takes them. Filled by filter3DPixel and
/// RankedBufferGrid; the merge never looks at invalid buffers.
struct RankedList {
    const float* mean = nullptr;   ///< the pixel's buffers: PixelBuffers::mean, ::count
    const float* count = nullptr;  ///<
    /// Luminance: order[0][i] is the i-th buffer index by luminance. PerChannel: order[c][i] the
    /// i-th by channel c.
    std::array<const int32_t*, 3> order{nullptr, nullptr, nullptr};
    /// Luminance: key[i] is the luminance of order[0][i] as order-preserving bits (-0 = +0).
    const uint64_t* key = nullptr;
    int n = 0;           ///< valid buffers (> 0)
    int64_t weight = 1;  ///< w_i of every buffer of the pixel (eq. 5.28)
    /// Copies of the pixel's buffers before the weight: n (BufferVotes::PerBuffer) or the sum of
    /// the valid buffers' counts (PerSample). The pixel holds weight * votes copies.
    int64_t votes = 0;
};

/// Per-thread scratch so the per-pixel functions do not allocate after warm-up.
struct SpatialScratch : WindowScratch {
    std::vector<WindowElement> elems;
    std::vector<std::pair<double, int>> ranked;  ///< (rank key, element index)
    std::vector<int> valid;                      ///< collectValidBuffers' output
    // 3D filters (eq. 5.24): the window's rank lists, the merge's tournament tree and list
    // positions, and filter3DPixel's own per-window ranking (RankedBufferGrid keeps its ranking
    // for the whole image instead).
    std::vector<RankedList> lists;
    std::vector<uint64_t> treeKey;
    std::vector<int> treeList, cursor;
    std::vector<int32_t> order;
    std::vector<uint64_t> key;
    // wantWeights, weights, source: WindowScratch (estimate.h). MIF/WMIF's element i is the
    // window pixel source[i]; a 3D filter's element (list l, buffer j) is buffer j of source[l].
};

/// The weighted trimmed mean of eq. 5.6 / 5.19 over elems (rules at the top of this file);
/// p.windowWidth/Height are not used. Sets out.rgb, out.kept (elements with a surviving copy, per
/// channel) and leaves out.excluded as it is. No element: black, kept = 0.
void weightedTrimmedMean(const WindowElement* elems, int n, const SpatialParams& p,
                         PixelEstimate& out, SpatialScratch& s);

// ---- the window filters' parameters (their registry entries: mif.h, filter3d.h) -----------------

/// "size": the window, KxL odd in [1, kMaxSpatialWindow].
ParamSpec windowSizeParam();
/// "w": the centre weight (eq. 5.28); `fixed` for the unweighted filters.
ParamSpec centreWeightParam(const std::string& def, bool fixed);
/// "alpha": the breakdown point (eq. 5.19); `fixed` for the median filters.
ParamSpec breakdownParam(const std::string& def, bool fixed);
/// "mode": luminance or per channel.
ParamSpec windowModeParam();
/// SpatialParams from parsed values (size, w, alpha, mode) and the luminance weights.
SpatialParams spatialParams(const ParamValues& values, const std::array<double, 3>& luma);

}  // namespace mcstat
