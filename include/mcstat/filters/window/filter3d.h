// Jung's 3D filters over the sub-buffers of a k x l window of pixels: 3DWTMF (thesis eq. 5.19),
// 3DWMF (eq. 5.20) and 3DMF (eq. 5.21), with the centre weight of eq. 5.28 and the k-way merge of
// eq. 5.24; the weighted trimmed mean itself and its rules (votes per buffer or per sample) are in
// window_rank.h. Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical
// Estimation Techniques", PhD thesis, University of Minnesota, 2016.
#pragma once

#include <vector>

#include "mcstat/filters/operation.h"
#include "mcstat/filters/window/window_rank.h"

namespace mcstat {

// ---- 3D filters over pixel buffers --------------------------------------------------------------

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

/// The registry entries "3dmf", "3dwmf" and "3dwtmf".
Operation filter3dmfOperation();
Operation filter3dwmfOperation();
Operation filter3dwtmfOperation();

}  // namespace mcstat
