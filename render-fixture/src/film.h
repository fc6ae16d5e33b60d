// Per-pixel accumulation in double, stored once as float32 into a StatsImage.
// PixelMoments holds what does not depend on sub-buffers: Welford's running mean and M2 over every
// kept sample, the luminance's for eq. 4.15, and the first hits' features. Two accumulators add the
// sub-buffers, one per sample-to-buffer rule (exr-deep/FORMAT.md):
// - PixelAccumulator, "roundrobin": sample i -> buffer i mod M (fixed M; adaptive M by pilot).
//   One per thread, reset for every pixel.
// - GrowingPixel, "leastcount": the buffer holding the fewest samples, lowest index on ties;
//   buffers are added between rounds (adaptive M growing during the render, docs/adaptive-m.md).
//   One per pixel for the whole render, so it is kept small.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "integrator.h"
#include "mcstat/core/moments.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/render-fixture/render.h"

namespace mcstat::render {

/// Running luminance statistics (core/moments.h): the pilot and the growing render share them, so
/// their sigmas agree bit for bit.
using RunningVariance = mcstat::RunningMoments;

/// Eq. 4.15's luminance (weights in render.h).
inline double sigmaLuma(const Vec3& L) {
    return kSigmaLuma[0] * L[0] + kSigmaLuma[1] * L[1] + kSigmaLuma[2] * L[2];
}

/// A pixel's statistics apart from its sub-buffers.
class PixelMoments {
  public:
    /// Adds a sample; returns false, and keeps nothing of it, when its radiance is not finite.
    bool add(const PathSample& s);
    /// Writes beauty, moments and features of pixel `p` of `img`.
    void store(StatsImage& img, size_t p) const;
    int64_t count() const { return n_; }
    /// Sum of the kept samples' radiance, channel c (the beauty's numerator).
    double sum(int c) const { return sum_[c]; }
    /// Luminance statistics of the kept samples (eq. 4.15's sigma_pixel).
    const RunningVariance& luminance() const { return luma_; }

  private:
    int64_t n_ = 0;          ///< kept samples
    RunningMoments rgb_[3];  ///< mean and M2 of R, G, B
    double sum_[3] = {0, 0, 0};
    int64_t hits_ = 0;
    Vec3 normalSum_, positionSum_, albedoSum_;
    double depthSum_ = 0;
    RunningVariance luma_;
};

/// One sub-buffer being accumulated: the radiance sum and the number of samples.
struct BufferSum {
    double sum[3] = {0, 0, 0};
    int64_t count = 0;
    void add(const Vec3& L) {
        for (int c = 0; c < 3; ++c) sum[c] += L[c];
        ++count;
    }
};

/// Stores buffer j's mean and count at buffer slot k of `img` (0 for an empty buffer).
void storeBuffer(StatsImage& img, size_t k, const double sum[3], int64_t count);

/// The AOV channels of a render with AOVs (RenderOptions::aovs), in the order of
/// fixtureAovChannels(): A (the camera ray hit geometry: 1, else 0), then R, G, B of every
/// light-path AOV (LightPathAov).
inline constexpr int kFixtureAovFloats = 1 + 3 * kLightPathAovs;
/// A sample's values of those channels.
void fixtureAovValues(const PathSample& s, double out[kFixtureAovFloats]);

/// Round robin: sample i goes to buffer i mod M.
class PixelAccumulator {
  public:
    /// `M` is the largest buffer count reset() will be given (the storage is reserved once);
    /// with `aovs` each buffer also sums the fixture's AOVs (fixtureAovValues), stored in
    /// StatsImage::aov.
    explicit PixelAccumulator(int M, bool aovs = false);
    void reset();
    /// Starts a pixel with `M` buffers (1 .. the constructor's M).
    void reset(int M);
    /// Adds sample `index` (0-based, in the order taken) to buffer index mod M. Returns false,
    /// and keeps nothing of the sample, when its radiance is not finite.
    bool add(int64_t index, const PathSample& s);
    /// Writes this pixel's statistics into every array of `img` at pixel `p`, whose buffer count
    /// (img.buffersOf(p)) must be this accumulator's M.
    void store(StatsImage& img, size_t p) const;

  private:
    int M_;
    std::vector<BufferSum> buffers_;
    std::vector<double> aovSums_;  ///< [j * kFixtureAovFloats + a]; empty without AOVs
    PixelMoments moments_;
};

/// Least count, with buffers added mid-render. A pixel with one buffer stores none of its own:
/// its buffer is the pixel's sum (PixelMoments), which it equals bit for bit; grow() copies that
/// sum into buffer 0. So the many pixels that never grow cost only their moments.
class GrowingPixel {
  public:
    /// Adds a sample to the buffer holding the fewest samples, the lowest index on ties. With
    /// balanced buffers this is round robin; after grow() it fills the new, empty buffers first.
    /// Returns false, keeping nothing, when the radiance is not finite.
    bool add(const PathSample& s);
    /// Appends empty buffers up to `M`; never shrinks.
    void grow(int M);
    int buffers() const { return buffers_.empty() ? 1 : int(buffers_.size()); }
    /// The largest number of samples in one buffer.
    int64_t maxBufferCount() const;
    const RunningVariance& luminance() const { return moments_.luminance(); }
    /// Writes every array of `img` at pixel `p`, whose buffer count must be buffers().
    void store(StatsImage& img, size_t p) const;

  private:
    PixelMoments moments_;
    std::vector<BufferSum> buffers_;  ///< empty while the pixel has one buffer
};

/// Mean-only accumulation for reference images.
struct MeanAccumulator {
    double sum[3] = {0, 0, 0};
    int64_t n = 0;
    bool add(const Vec3& L);
    void store(float* rgb) const;
};

}  // namespace mcstat::render
