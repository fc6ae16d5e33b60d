// Per-pixel accumulation in double, stored once as float32 into a StatsImage.
// Sample i of a pixel goes to sub-buffer i mod M ("roundrobin", M = M_p with adaptive M); the
// moments are Welford's running mean and M2 over every kept sample; features average the first
// hits.
#pragma once

#include <cstdint>
#include <vector>

#include "integrator.h"
#include "mcstat/stats_file.h"

namespace mcstat::render {

class PixelAccumulator {
  public:
    /// `M` is the largest buffer count reset() will be given (the storage is reserved once).
    explicit PixelAccumulator(int M);
    void reset();
    /// Starts a pixel with `M` buffers (1 .. the constructor's M).
    void reset(int M);
    /// Adds sample `index` (0-based, in the order taken). Returns false, and keeps nothing of the
    /// sample, when its radiance is not finite.
    bool add(int64_t index, const PathSample& s);
    /// Writes this pixel's statistics into every array of `img` at pixel `p`, whose buffer count
    /// (img.buffersOf(p)) must be this accumulator's M.
    void store(StatsImage& img, size_t p) const;

  private:
    int M_;
    std::vector<double> bufSum_;     ///< [j*3 + c]
    std::vector<int64_t> bufCount_;  ///< [j]
    int64_t n_ = 0;                  ///< kept samples
    double mean_[3] = {0, 0, 0}, m2_[3] = {0, 0, 0};
    double sum_[3] = {0, 0, 0};
    int64_t hits_ = 0;
    Vec3 normalSum_, positionSum_, albedoSum_;
    double depthSum_ = 0;
};

/// Mean-only accumulation for reference images.
struct MeanAccumulator {
    double sum[3] = {0, 0, 0};
    int64_t n = 0;
    bool add(const Vec3& L);
    void store(float* rgb) const;
};

}  // namespace mcstat::render
