// The expected value's interval: each pixel's spread and its neighbourhood's pooled variance
// (expected_interval.h); the interval itself is filters/interval.h's expectedInterval.
#include "mcstat/image/expected_interval.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "mcstat/core/location_stats.h"
#include "mcstat/core/parallel.h"
#include "mcstat/core/pixel_buffers.h"

namespace mcstat {

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
}  // namespace

std::vector<PixelSpread> pixelSpreads(const StatsImage& src, int nthreads) {
    const size_t n = src.pixelCount();
    std::vector<PixelSpread> out(n);
    parallelFor(0, int64_t(n), 256, nthreads, [&](int64_t begin, int64_t end) {
        std::vector<int> valid;
        std::vector<double> values, counts;
        for (int64_t i = begin; i < end; ++i) {
            const size_t p = size_t(i);
            PixelSpread& s = out[p];
            const PixelBuffers pb = src.pixelBuffers(p);
            if (const float* sp = src.meanOnlySpread(p)) {
                s.buffers = int(sp[0]);
                s.samples = double(pb.count[0]);
                for (int c = 0; c < 3; ++c) {
                    s.mean[c] = double(pb.mean[c]);
                    s.s2[c] = s.buffers >= 2 ? double(sp[spreadIndex(c, c)]) : kNaN;
                }
                continue;
            }
            int excluded = 0;
            const int m = collectValidBuffers(pb, valid, excluded);
            s.buffers = m;
            values.resize(size_t(m));
            counts.resize(size_t(m));
            s.samples = 0.0;
            for (int k = 0; k < m; ++k) {
                counts[size_t(k)] = double(pb.count[valid[size_t(k)]]);
                s.samples += counts[size_t(k)];
            }
            for (int c = 0; c < 3; ++c) {
                for (int k = 0; k < m; ++k)
                    values[size_t(k)] = double(pb.mean[3 * valid[size_t(k)] + c]);
                const LocationSummary l = weightedMeanSummary(values.data(), counts.data(), m);
                s.mean[c] = m > 0 ? l.estimate : kNaN;
                // variance = s^2 / N: back to the per-sample variance.
                s.s2[c] = m >= 2 ? l.variance * s.samples : kNaN;
            }
        }
    });
    return out;
}

std::vector<double> pooledSampleVariance(const std::vector<PixelSpread>& spreads, int width,
                                         int height, int radius, int nthreads) {
    const size_t n = size_t(width) * size_t(height);
    // Two separable passes of sums and counts of the finite values, in double: no running sums
    // (a firefly's 1e10 would leave its rounding in every later window).
    std::vector<double> rowSum(n * 3, 0.0), rowCount(n * 3, 0.0), out(n * 3, kNaN);
    parallelFor(0, height, 1, nthreads, [&](int64_t begin, int64_t end) {
        for (int64_t y = begin; y < end; ++y)
            for (int x = 0; x < width; ++x)
                for (int c = 0; c < 3; ++c) {
                    double sum = 0.0, count = 0.0;
                    for (int u = std::max(0, x - radius); u <= std::min(width - 1, x + radius);
                         ++u) {
                        const double v = spreads[size_t(y) * size_t(width) + size_t(u)].s2[c];
                        if (std::isfinite(v)) sum += v, count += 1.0;
                    }
                    const size_t i = (size_t(y) * size_t(width) + size_t(x)) * 3 + size_t(c);
                    rowSum[i] = sum;
                    rowCount[i] = count;
                }
    });
    parallelFor(0, height, 1, nthreads, [&](int64_t begin, int64_t end) {
        for (int64_t y = begin; y < end; ++y)
            for (int x = 0; x < width; ++x)
                for (int c = 0; c < 3; ++c) {
                    double sum = 0.0, count = 0.0;
                    for (int64_t v = std::max<int64_t>(0, y - radius);
                         v <= std::min<int64_t>(height - 1, y + radius); ++v) {
                        const size_t i = (size_t(v) * size_t(width) + size_t(x)) * 3 + size_t(c);
                        sum += rowSum[i];
                        count += rowCount[i];
                    }
                    if (count > 0.0)
                        out[(size_t(y) * size_t(width) + size_t(x)) * 3 + size_t(c)] = sum / count;
                }
    });
    return out;
}

}  // namespace mcstat
