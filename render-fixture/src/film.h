// Per-pixel accumulation in double, stored once as float32 into a StatsImage.
// Two rules assign samples to sub-buffers: "roundrobin" (sample i -> buffer i mod M; fixed M and
// the pilot strategy of adaptive M) and "leastcount" (the buffer holding fewest samples, lowest
// index on ties; adaptive M growing during the render, docs/adaptive-m.md). The moments are
// Welford's running mean and M2 over every kept sample, plus the luminance's for eq. 4.15;
// features average the first hits.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "integrator.h"
#include "mcstat/render/render.h"
#include "mcstat/stats_file.h"

namespace mcstat::render {

/// Welford's running mean and M2 of one value: numerically stable even when the mean dwarfs the
/// spread. The pilot and the growing render share it, so their sigmas agree bit for bit.
struct RunningVariance {
    int64_t n = 0;
    double mean = 0, m2 = 0;
    void add(double v) {
        ++n;
        const double d = v - mean;
        mean += d / double(n);
        m2 += d * (v - mean);
    }
    /// The unbiased standard deviation; 0 with fewer than two values.
    double sigma() const { return n > 1 ? std::sqrt(m2 / double(n - 1)) : 0.0; }
};

/// Eq. 4.15's luminance (weights in render.h).
inline double sigmaLuma(const Vec3& L) {
    return kSigmaLuma[0] * L[0] + kSigmaLuma[1] * L[1] + kSigmaLuma[2] * L[2];
}

class PixelAccumulator {
  public:
    /// `M` is the largest buffer count reset() will be given (the storage is reserved once).
    explicit PixelAccumulator(int M);
    void reset();
    /// Starts a pixel with `M` buffers (1 .. the constructor's M).
    void reset(int M);
    /// Adds sample `index` (0-based, in the order taken) to buffer index mod M ("roundrobin").
    /// Returns false, and keeps nothing of the sample, when its radiance is not finite.
    bool add(int64_t index, const PathSample& s);
    /// Adds a sample to the buffer holding the fewest samples, the lowest index on ties
    /// ("leastcount"). With balanced buffers this is round robin; after grow() it fills the new,
    /// empty buffers first. Returns false, keeping nothing, when the radiance is not finite.
    bool addLeastCount(const PathSample& s);
    /// Appends empty buffers up to `M` (>= the current count): adaptive M growing mid-render.
    void grow(int M);
    int buffers() const { return M_; }
    /// The largest number of samples in one buffer.
    int64_t maxBufferCount() const;
    /// Luminance statistics of the kept samples (eq. 4.15's sigma_pixel).
    const RunningVariance& luminance() const { return luma_; }
    /// Writes this pixel's statistics into every array of `img` at pixel `p`, whose buffer count
    /// (img.buffersOf(p)) must be this accumulator's M.
    void store(StatsImage& img, size_t p) const;

  private:
    void addMoments(size_t j, const PathSample& s);

    int M_;
    std::vector<double> bufSum_;     ///< [j*3 + c]
    std::vector<int64_t> bufCount_;  ///< [j]
    int64_t n_ = 0;                  ///< kept samples
    double mean_[3] = {0, 0, 0}, m2_[3] = {0, 0, 0};
    double sum_[3] = {0, 0, 0};
    int64_t hits_ = 0;
    Vec3 normalSum_, positionSum_, albedoSum_;
    double depthSum_ = 0;
    RunningVariance luma_;
};

/// Mean-only accumulation for reference images.
struct MeanAccumulator {
    double sum[3] = {0, 0, 0};
    int64_t n = 0;
    bool add(const Vec3& L);
    void store(float* rgb) const;
};

}  // namespace mcstat::render
