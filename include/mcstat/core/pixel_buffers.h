// One pixel's sub-buffers as every per-pixel operation takes them: the view the statistics file
// (exr-deep) hands out and the estimators (filters/pixel) read, and the rule of valid buffers
// every operation over them shares, and the views of a whole grid of them (or of an RGB image)
// that the window operations read. Core types: they depend on nothing.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
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

/// Asks the processor to bring the `bytes` bytes from p into cache, line by line (at most the
/// first kPrefetchBytesMost: a thousand buffers would be more than the cache holds). A hint that
/// reads and changes nothing. Always inlined: GCC 12 takes a function whose only effect is a
/// prefetch for one without effects, and drops its calls (ipa-pure-const).
[[gnu::always_inline]] inline void prefetchLines(const void* p, size_t bytes) {
    constexpr size_t kPrefetchBytesMost = 2048;
    bytes = bytes < kPrefetchBytesMost ? bytes : kPrefetchBytesMost;
    const char* b = static_cast<const char*>(p);
    for (size_t i = 0; i < bytes; i += 64) __builtin_prefetch(b + i);
    __builtin_prefetch(b + bytes - 1);  // the last line when b is not on a line's start
}

/// Asks the processor to bring px's buffers (means and counts) into cache (prefetchLines). A pass
/// over pixels asks kPrefetchPixels ahead of the one it works on: the hardware's own prefetch does
/// not always follow the buffers' stream (on this project's 2-core virtual machine, the mean's
/// pass over a 1080p, M = 21 image waited on memory for most of its time).
[[gnu::always_inline]] inline void prefetchBuffers(const PixelBuffers& px) {
    if (px.M <= 0) return;
    prefetchLines(px.mean, 3 * sizeof(float) * size_t(px.M));
    prefetchLines(px.count, sizeof(float) * size_t(px.M));
}

/// How many pixels ahead a pass asks for buffers (prefetchBuffers): a pixel's M = 21 buffers are
/// 336 bytes, which its estimate takes about 50 to 100 ns to read, about a memory access's latency.
inline constexpr int kPrefetchPixels = 4;

/// Whether every buffer of px is valid (count > 0, count and every channel finite), the common
/// case, tested on the floats' bits in a loop the compiler vectorises: every mean finite (exponent
/// bits not all ones) and every count a finite float above 0 (as an int, in (0, 0x7f800000)).
inline bool allBuffersValid(const PixelBuffers& px) {
    uint32_t anyBad = 0;
    for (int i = 0; i < 3 * px.M; ++i) {
        uint32_t u;
        std::memcpy(&u, px.mean + i, sizeof u);
        anyBad |= uint32_t((u & 0x7f800000u) == 0x7f800000u);
    }
    for (int j = 0; j < px.M; ++j) {
        int32_t c;
        std::memcpy(&c, px.count + j, sizeof c);
        anyBad |= uint32_t(c <= 0) | uint32_t(c >= 0x7f800000);
    }
    return anyBad == 0;
}

/// Fills `order` with the indices of the valid buffers (count > 0, count and every channel finite),
/// in index order, and sets `excluded` to the number of NaN/Inf buffers. Returns M_v.
inline int collectValidBuffers(const PixelBuffers& px, std::vector<int>& order, int& excluded) {
    // Without branches (a mispredicted branch per buffer cost more than the test): x - x is 0
    // for a finite float and NaN for NaN/Inf, so `fin` is 0 exactly when the count and the three
    // channels are finite; a count of 0 (or -0) is an empty buffer (spp < M): no information, not
    // an error. Every index is written and the next write overwrites it unless it was taken.
    order.resize(size_t(px.M > 0 ? px.M : 0));
    if (allBuffersValid(px)) {
        for (int j = 0; j < px.M; ++j) order[size_t(j)] = j;
        excluded = 0;
        return px.M;
    }
    int n = 0, bad = 0;
    for (int j = 0; j < px.M; ++j) {
        const float c = px.count[j];
        const float* m = px.mean + 3 * j;
        const float fin = ((c - c) + (m[0] - m[0])) + ((m[1] - m[1]) + (m[2] - m[2]));
        const int isBad = int(fin != 0.f) | int(c < 0.f);  // NaN != 0
        order[size_t(n)] = j;
        n += (isBad ^ 1) & int(c != 0.f);
        bad += isBad;
    }
    order.resize(size_t(n));
    excluded = bad;
    return n;
}

}  // namespace mcstat
