// The removed light's per-pixel scale and its neighbourhood significance (removed_light.h).
#include "mcstat/filters/removed_light.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "mcstat/core/parallel.h"

namespace mcstat {

namespace {

double lumaOf(const float* rgb, const std::array<double, 3>& luma) {
    return luma[0] * double(rgb[0]) + luma[1] * double(rgb[1]) + luma[2] * double(rgb[2]);
}

}  // namespace

bool isValidBuffer(const PixelBuffers& px, int j) {
    const float* m = px.mean + 3 * j;
    return px.count[j] > 0.f && std::isfinite(m[0]) && std::isfinite(m[1]) && std::isfinite(m[2]);
}

LumaSpread lumaSpread(const PixelBuffers& px, const std::array<double, 3>& luma) {
    LumaSpread out;
    // Each valid buffer's luminance once (on the stack up to 64 buffers); invalid ones marked by
    // a count of 0.
    constexpr int kStack = 64;
    double yStack[kStack], nStack[kStack];
    std::vector<double> yHeap, nHeap;
    double* ys = yStack;
    double* ns = nStack;
    if (px.M > kStack) {
        yHeap.resize(size_t(px.M));
        nHeap.resize(size_t(px.M));
        ys = yHeap.data();
        ns = nHeap.data();
    }
    double n = 0.0, sum = 0.0;
    if (allBuffersValid(px)) {
        // Every buffer valid (the common case): the same sums without the per-buffer tests.
        for (int j = 0; j < px.M; ++j) {
            ns[j] = double(px.count[j]);
            ys[j] = lumaOf(px.mean + 3 * j, luma);
            n += ns[j];
            sum += ns[j] * ys[j];
        }
        out.valid = px.M;
    } else {
        for (int j = 0; j < px.M; ++j) {
            const bool valid = isValidBuffer(px, j);
            ns[j] = valid ? double(px.count[j]) : 0.0;
            if (!valid) continue;
            ys[j] = lumaOf(px.mean + 3 * j, luma);
            ++out.valid;
            n += ns[j];
            sum += ns[j] * ys[j];
        }
    }
    if (out.valid == 0) return out;
    out.mean = sum / n;
    if (out.valid < 2) return out;
    // Second pass over deviations: no cancellation of two large sums of squares.
    double ss = 0.0;
    for (int j = 0; j < px.M; ++j) {
        if (ns[j] == 0.0) continue;
        const double dev = ys[j] - out.mean;
        ss += ns[j] * dev * dev;
    }
    out.se = std::sqrt(ss / double(out.valid - 1) / n);
    return out;
}

double removedZ(double d, double se) {
    if (d == 0.0 || !std::isfinite(d) || !(se > 0.0) || !std::isfinite(se)) return 0.0;
    return d / se;
}

void localRemovedZ(const float* d, const float* se, int width, int height, int radius, float* out,
                   int nthreads) {
    // Separable box sums in double, each window summed directly (rows, then columns): exact zeros
    // stay zero, which running or summed-area tables would not guarantee.
    const size_t w = size_t(width), n = w * size_t(height);
    std::vector<double> rd(n, 0.0), rv(n, 0.0);
    parallelFor(0, height, 0, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y)
            for (int x = 0; x < width; ++x) {
                double a = 0.0, b = 0.0;
                for (int i = std::max(0, x - radius); i < std::min(width, x + radius + 1); ++i) {
                    const size_t p = size_t(y) * w + size_t(i);
                    if (!std::isfinite(d[p]) || !std::isfinite(se[p])) continue;
                    a += double(d[p]);
                    b += double(se[p]) * double(se[p]);
                }
                rd[size_t(y) * w + size_t(x)] = a;
                rv[size_t(y) * w + size_t(x)] = b;
            }
    });
    parallelFor(0, height, 0, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y)
            for (int x = 0; x < width; ++x) {
                double a = 0.0, b = 0.0;
                for (int j = std::max(0, y - radius); j < std::min(height, y + radius + 1); ++j) {
                    a += rd[size_t(j) * w + size_t(x)];
                    b += rv[size_t(j) * w + size_t(x)];
                }
                out[size_t(y) * w + size_t(x)] = float(removedZ(a, std::sqrt(b)));
            }
    });
}

}  // namespace mcstat
