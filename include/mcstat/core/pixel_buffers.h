// One pixel's sub-buffers as every per-pixel operation takes them: the view the statistics file
// (exr-deep) hands out and the estimators (filters/pixel) read, and the rule of valid buffers
// every operation over them shares, and the views of a whole grid of them (or of an RGB image)
// that the window operations read. Core types: they depend on nothing.
#pragma once

#include <cmath>
#include <vector>

namespace mcstat {

/// One pixel's sub-buffers: M means (RGB interleaved) and M counts.
struct PixelBuffers {
    const float* mean = nullptr;   ///< [j*3 + c]
    const float* count = nullptr;  ///< [j]
    int M = 0;
};

/// How the buffers of a 3D filter's window vote in the ranking (docs/spatial_filters.md).
enum class BufferVotes {
    /// One vote per buffer, eq. 5.19: buffer j of pixel q is w_q copies and its count n_j weighs
    /// the average (r_i n_i). For fixed-M files, whose buffers hold equal counts up to one sample.
    PerBuffer,
    /// One vote per sample, for adaptive M (M_p buffers of n / M_p samples next to one-buffer
    /// pixels of n samples): buffer j of pixel q is w_q n_j copies in the ranking, each copy one
    /// sample in the average (sum r_i x_i / sum r_i). n_j must be an integer in [1,
    /// kMaxBufferVoteCount], else the buffer is invalid (excluded). Sums of copies stay below 2^63
    /// for any window, centre
    /// weight and count allowed and up to 500,000 buffers per pixel (kMaxBuffers is 999): at most
    /// (kMaxCentreWeight + 255^2 - 1) * M * 2^24 < 1.8e16 for M = 999.
    PerSample,
};

/// Read access to a width x height grid of pixels' sub-buffers, what a window operation over
/// sub-buffers reads (operation.h): at(x, y) returns pixel (x, y)'s buffers. Each pixel may have
/// its own M (adaptive buffer counts); the filters never assume a fixed M. `votes` says how
/// buffers vote: image/ takes PerSample for adaptive-M statistics (StatsHeader::adaptiveM),
/// PerBuffer otherwise; a view built by hand chooses.
struct BufferView {
    int width = 0, height = 0;
    const void* ctx = nullptr;
    PixelBuffers (*fn)(const void* ctx, int x, int y) = nullptr;
    BufferVotes votes = BufferVotes::PerBuffer;
    PixelBuffers at(int x, int y) const { return fn(ctx, x, y); }
};

/// An interleaved RGB float image, as a window operation over pixels reads it: pixel (x, y) at
/// rgb[(y * width + x) * 3 + c].
struct RGBImageView {
    const float* rgb = nullptr;
    int width = 0, height = 0;
};

/// Fills `order` with the indices of the valid buffers (count > 0, count and every channel finite),
/// in index order, and sets `excluded` to the number of NaN/Inf buffers. Returns M_v.
inline int collectValidBuffers(const PixelBuffers& px, std::vector<int>& order, int& excluded) {
    order.clear();
    excluded = 0;
    for (int j = 0; j < px.M; ++j) {
        const float n = px.count[j];
        const float* m = px.mean + 3 * j;
        if (!std::isfinite(n) || n < 0.f || !std::isfinite(m[0]) || !std::isfinite(m[1]) ||
            !std::isfinite(m[2])) {
            ++excluded;
            continue;
        }
        if (n == 0.f) continue;  // empty buffer (spp < M): no information, not an error
        order.push_back(j);
    }
    return int(order.size());
}

}  // namespace mcstat
