// Test helper: accumulates Monte Carlo samples into a StatsImage exactly as a renderer would
// (double sums per sub-buffer, Welford per pixel, feature sums), rounding to float32 once at the
// end.
#pragma once

#include <algorithm>
#include <cstdint>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::test {

/// One camera sample: its radiance and first-hit features.
struct Sample {
    double rgb[3] = {0, 0, 0};
    bool hit = false;
    double normal[3] = {0, 0, 0};
    double position[3] = {0, 0, 0};
    double albedo[3] = {0, 0, 0};  // 0 on a miss
    double depth = 0;              // meaningful only on a hit
};

/// A deterministic pseudo-random sample for (seed, pixel, index): radiance in [0, 4) with
/// occasional fireflies up to 400, hits with probability 0.75.
Sample makeSample(uint64_t seed, int pixel, int index);

class SampleAccumulator {
  public:
    SampleAccumulator(int width, int height, int M, int originX = 0, int originY = 0);
    /// Adds a sample of pixel (x, y) (0-based within the data window) to sub-buffer `buffer`.
    void add(int x, int y, const Sample& s, int buffer);
    /// Adds the next sample of pixel (x, y) with the round-robin rule: the i-th sample this
    /// accumulator receives for the pixel goes to buffer i mod M.
    void addRoundRobin(int x, int y, const Sample& s);
    /// The statistics image; `base` supplies the string/spp header fields.
    StatsImage finish(const StatsHeader& base) const;

  private:
    struct Pixel {
        int64_t n = 0, hits = 0;
        double mean[3] = {0, 0, 0}, m2[3] = {0, 0, 0};
        double sumN[3] = {0, 0, 0}, sumP[3] = {0, 0, 0}, sumAlbedo[3] = {0, 0, 0}, sumZ = 0;
    };
    int width_, height_, M_, originX_, originY_;
    std::vector<Pixel> pixels_;
    std::vector<double> bufSum_;  // [(p*M + j)*3 + c]
    std::vector<int64_t> bufN_;   // [p*M + j]
};

/// Renders `spp(x, y)` samples per pixel with seed `seed` (sample index i uses makeSample(seed, p,
/// i)) into a fresh image, round robin.
template <class SppFn>
StatsImage renderImage(int width, int height, int M, uint64_t seed, SppFn spp, int originX = 0,
                       int originY = 0) {
    SampleAccumulator acc(width, height, M, originX, originY);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
            for (int i = 0; i < spp(x, y); ++i)
                acc.addRoundRobin(x, y, makeSample(seed, y * width + x, i));
    StatsHeader h;
    h.renderer = "test-renderer 1.0";
    h.seeds = std::to_string(seed);
    int64_t maxSpp = 0;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) maxSpp = std::max<int64_t>(maxSpp, spp(x, y));
    h.spp = maxSpp;
    return acc.finish(h);
}

/// An adaptive image whose pixel (x, y) has mFn(x, y) buffers and sppFn(x, y) samples
/// (makeSample(seed, p, i), sample i -> buffer i mod m_p): built from fixed-M renders with M = m_p,
/// which hold exactly those buffers.
template <class MFn, class SppFn>
StatsImage adaptiveImage(int w, int h, int mMax, uint64_t seed, MFn mFn, SppFn sppFn, int ox = 0,
                         int oy = 0) {
    std::map<int, StatsImage> byM;
    std::vector<uint32_t> m(size_t(w) * size_t(h));
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const int mp = mFn(x, y);
            m[size_t(y) * size_t(w) + size_t(x)] = uint32_t(mp);
            if (!byM.count(mp)) byM[mp] = renderImage(w, h, mp, seed, sppFn, ox, oy);
        }
    StatsImage out;
    out.header = byM.begin()->second.header;
    out.header.M = mMax;
    out.header.formatVersion = kStatsFormatVersionAdaptive;
    std::string err;
    if (!out.allocateAdaptive(m, err)) throw std::runtime_error(err);
    const StatsImage& any = byM.begin()->second;
    out.beauty = any.beauty;
    out.count = any.count;
    out.mean = any.mean;
    out.variance = any.variance;
    out.normal = any.normal;
    out.position = any.position;
    out.albedo = any.albedo;
    out.depth = any.depth;
    out.coverage = any.coverage;
    for (size_t p = 0; p < m.size(); ++p) {
        const PixelBuffers src = byM[int(m[p])].pixelBuffers(p);
        const size_t k = out.bufferBegin(p);
        std::copy(src.mean, src.mean + 3 * src.M, out.bufferMean.begin() + long(k * 3));
        std::copy(src.count, src.count + src.M, out.bufferCount.begin() + long(k));
    }
    return out;
}

}  // namespace mcstat::test
