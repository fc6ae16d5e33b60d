// Spatial and hybrid robust filters of Jung's thesis, chapter 5: the (weighted) median image filter
// MIF / WMIF (eq. 5.6-5.8, weights eq. 5.28) over an RGB image, and the 3D filters 3DWTMF, 3DWMF,
// 3DMF (eq. 5.19-5.21) over the sub-buffers of a k x l window of pixels. Pure functions over plain
// arrays, no I/O, no OIIO types; the ImageBuf forms are in imageops.h.
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
// - Counts weight the final average, not the ranks (as in every estimator of estimators.h): if r_i
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

#include "mcstat/filters/pixel/ranking.h"

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
struct SpatialScratch {
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
    /// AOVs (docs/aovs.md), luminance mode: with wantWeights set by the caller, a filtered pixel
    /// leaves in `weights` every element that entered its average with its share (the shares sum
    /// to 1): MIF/WMIF's element i is the window pixel source[i]; a 3D filter's element (list l,
    /// buffer j) is buffer j of the window pixel source[l]. Empty in channel mode, where R, G and B
    /// keep different elements. `source` (window pixels, image coordinates of the view) is
    /// filled whenever wantWeights is set.
    struct WeightedElement {
        int element;  ///< MIF: element index; 3D: list index
        int buffer;   ///< 3D: the buffer j; MIF: -1
        double weight;
    };
    bool wantWeights = false;
    std::vector<WeightedElement> weights;
    std::vector<std::pair<int, int>> source;
};

/// The weighted trimmed mean of eq. 5.6 / 5.19 over elems (rules at the top of this file);
/// p.windowWidth/Height are not used. Sets out.rgb, out.kept (elements with a surviving copy, per
/// channel) and leaves out.excluded as it is. No element: black, kept = 0.
void weightedTrimmedMean(const WindowElement* elems, int n, const SpatialParams& p,
                         PixelEstimate& out, SpatialScratch& s);

// ---- MIF / WMIF over an RGB image ---------------------------------------------------------------

/// An interleaved RGB float image: pixel (x, y) at rgb[(y * width + x) * 3 + c].
struct RGBImageView {
    const float* rgb = nullptr;
    int width = 0, height = 0;
};

/// WMIF(w(w_c), k x l) at pixel (x, y) (eq. 5.6 with the weights of eq. 5.28; MIF, eq. 5.8, for
/// centreWeight = 1; alpha < 0.5 gives the weighted trimmed mean filter WTMIF of section 5.1.2).
void wmifPixel(const RGBImageView& img, int x, int y, const SpatialParams& p, PixelEstimate& out,
               SpatialScratch& s);
/// wmifPixel over every pixel, one thread; `out` holds width * height * 3 floats (not `img.rgb`).
void wmifImage(const RGBImageView& img, const SpatialParams& p, float* out);

// ---- 3D filters over pixel buffers --------------------------------------------------------------

/// How the buffers of a 3D filter's window vote in the ranking (docs/spatial_filters.md).
enum class BufferVotes {
    /// One vote per buffer, eq. 5.19: buffer j of pixel q is w_q copies and its count n_j weighs
    /// the average (r_i n_i). For fixed-M files, whose buffers hold equal counts up to one sample.
    PerBuffer,
    /// One vote per sample, for adaptive M (M_p buffers of n / M_p samples next to one-buffer
    /// pixels of n samples): buffer j of pixel q is w_q n_j copies in the ranking, each copy one
    /// sample in the average (sum r_i x_i / sum r_i). n_j must be an integer in [1,
    /// kMaxBufferVoteCount],
    /// else the buffer is invalid (excluded). Sums of copies stay below 2^63 for any window, centre
    /// weight and count allowed and up to 500,000 buffers per pixel (kMaxBuffers is 999): at most
    /// (kMaxCentreWeight + 255^2 - 1) * M * 2^24 < 1.8e16 for M = 999.
    PerSample,
};

/// Read access to a width x height grid of pixels' sub-buffers: at(x, y) returns pixel (x, y)'s
/// buffers. Each pixel may have its own M (adaptive buffer counts); the filters never assume a
/// fixed M. `votes` says how buffers vote: filter3D takes PerSample for adaptive-M statistics
/// (StatsHeader::adaptiveM), PerBuffer otherwise; a view built by hand chooses.
struct BufferView {
    int width = 0, height = 0;
    const void* ctx = nullptr;
    PixelBuffers (*fn)(const void* ctx, int x, int y) = nullptr;
    BufferVotes votes = BufferVotes::PerBuffer;
    PixelBuffers at(int x, int y) const { return fn(ctx, x, y); }
};

/// The fixed-M arrays of a StatsImage: means [(p*M + j)*3 + c], counts [p*M + j], p = y*width + x.
struct FixedBufferGrid {
    const float* bufferMean = nullptr;
    const float* bufferCount = nullptr;
    int width = 0, height = 0, M = 0;
    PixelBuffers at(int x, int y) const;
    /// A view of *this (which must outlive it).
    BufferView view() const;
};

// The 3D filters rank as the thesis' cost model assumes (eq. 5.24, T = m log m + m n log n): each
// pixel's valid buffers are sorted once by the rank key, and a window merges its n pixels' sorted
// lists (a k-way merge with a tournament tree keyed by (key, window order)), walking the merged
// order only up to the last kept rank. The merged order is exactly the order of one full sort of
// the window's elements (ascending key, ties by window row, column, buffer index), so the result is
// the same bit for bit as sorting all m n elements per pixel.

/// 3DWTMF(alpha, w(w_c), m x k x l) at pixel (x, y) (eq. 5.19): the elements are the valid buffers
/// of every pixel in the clipped k x l window, the centre pixel's buffers weighted w_c, each buffer
/// voting as v.votes says. 3DWMF (eq. 5.20) is alpha = 0.5, 3DMF (eq. 5.21) alpha = 0.5 and
/// centreWeight = 1. out.excluded counts the invalid buffers of the whole window. A single pixel
/// has no sorted neighbours to reuse: this sorts each window pixel's buffers, then merges; whole
/// images go through RankedBufferGrid.
void filter3DPixel(const BufferView& v, int x, int y, const SpatialParams& p, PixelEstimate& out,
                   SpatialScratch& s);
/// filter3DPixel over every pixel, one thread, each pixel's buffers sorted once
/// (RankedBufferGrid); `out` holds width * height * 3 floats.
void filter3DImage(const BufferView& v, const SpatialParams& p, float* out);

/// The pre-sorted buffers of eq. 5.24 for a rectangle of a BufferView: every pixel's valid buffers
/// sorted once by rank key (O(m log m) per pixel), so that filterPixel only merges the window's
/// sorted lists (O(m n log n)). Results equal filter3DPixel's bit for bit.
/// Memory: one rank array as large as the buffer means, 12 bytes per buffer (luminance: an int32
/// index and a 64-bit key; per channel: three int32 indices), plus 24 bytes per pixel.
class RankedBufferGrid {
  public:
    /// Covers pixels [x0, x1) x [y0, y1) of v (v's context must outlive *this), ranked by
    /// p.mode / p.luma, filtered with p. O(pixels): allocates, reads only each pixel's M.
    void reset(const BufferView& v, const SpatialParams& p, int x0, int y0, int x1, int y1);
    /// Sorts the pixels of [xa, xb) x [ya, yb), inside the rectangle. Calls on disjoint
    /// rectangles may run concurrently (each with its own scratch).
    void sortRect(int xa, int ya, int xb, int yb, SpatialScratch& s);
    /// filter3DPixel(v, x, y, p, ...) from the sorted buffers: the window around (x, y), clipped to
    /// the view, must lie inside the rectangle and be sorted.
    void filterPixel(int x, int y, PixelEstimate& out, SpatialScratch& s) const;

  private:
    struct PixelRank {
        uint64_t begin = 0;  ///< first slot: key_[begin + i], order_[ranks * begin + ...]
        int32_t n = 0;       ///< valid buffers
        int32_t excluded = 0;
        int64_t votes = 0;  ///< RankedList::votes
    };
    BufferView view_;
    SpatialParams params_;
    int x0_ = 0, y0_ = 0, width_ = 0, height_ = 0;
    std::vector<PixelRank> pixels_;  ///< [(y - y0) * width + x - x0]
    /// Per pixel, M slots per ranking (1 for luminance, 3 per channel): ranking r of a pixel with M
    /// buffers at order_[ranks * begin + r * M + i], i < n.
    std::vector<int32_t> order_;
    std::vector<uint64_t> key_;  ///< luminance only: key_[begin + i] of order_[begin + i]
};

}  // namespace mcstat
