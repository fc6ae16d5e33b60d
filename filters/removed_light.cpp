// The removed light's per-pixel scale and its neighbourhood significance (removed_light.h).
#include "mcstat/filters/removed_light.h"

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "mcstat/core/cpu_features.h"
#include "mcstat/core/parallel.h"

namespace mcstat {

namespace {

/// Largest M of lumaSpread's stack arrays, and of the four-pixel path.
constexpr int kSpreadStackM = 64;

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
    double yStack[kSpreadStackM], nStack[kSpreadStackM];
    std::vector<double> yHeap, nHeap;
    double* ys = yStack;
    double* ns = nStack;
    if (px.M > kSpreadStackM) {
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

namespace {

/// Four pixels' lumaSpread, one per lane: px[0..3] share M in [2, kSpreadStackM] and every
/// buffer is valid. Each lane computes lumaSpread's all-valid path: Y_j = (l0 R + l1 G) + l2 B,
/// n += n_j, sum += n_j Y_j, mean = sum / n, ss += (n_j dev) dev, se = sqrt(ss / (M - 1) / n),
/// the same roundings in the same order (no "fma" target: nothing is contracted).
__attribute__((target("avx2"))) void lumaSpread4(const PixelBuffers* px,
                                                 const std::array<double, 3>& luma,
                                                 LumaSpread* out) {
    const int M = px[0].M;
    alignas(32) double ys[kSpreadStackM][4], ns[kSpreadStackM][4];
    const __m256d l0 = _mm256_set1_pd(luma[0]), l1 = _mm256_set1_pd(luma[1]),
                  l2 = _mm256_set1_pd(luma[2]);
    __m256d n = _mm256_setzero_pd(), sum = _mm256_setzero_pd();
    for (int j = 0; j < M; ++j) {
        const float *a = px[0].mean + 3 * j, *b = px[1].mean + 3 * j, *c = px[2].mean + 3 * j,
                    *d = px[3].mean + 3 * j;
        // _mm256_set_pd takes the lanes from the highest down.
        const __m256d r = _mm256_set_pd(d[0], c[0], b[0], a[0]);
        const __m256d g = _mm256_set_pd(d[1], c[1], b[1], a[1]);
        const __m256d bl = _mm256_set_pd(d[2], c[2], b[2], a[2]);
        const __m256d w =
            _mm256_set_pd(px[3].count[j], px[2].count[j], px[1].count[j], px[0].count[j]);
        const __m256d y = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(l0, r), _mm256_mul_pd(l1, g)),
                                        _mm256_mul_pd(l2, bl));
        _mm256_store_pd(ys[j], y);
        _mm256_store_pd(ns[j], w);
        n = _mm256_add_pd(n, w);
        sum = _mm256_add_pd(sum, _mm256_mul_pd(w, y));
    }
    const __m256d mean = _mm256_div_pd(sum, n);
    __m256d ss = _mm256_setzero_pd();
    for (int j = 0; j < M; ++j) {
        const __m256d dev = _mm256_sub_pd(_mm256_load_pd(ys[j]), mean);
        ss = _mm256_add_pd(ss, _mm256_mul_pd(_mm256_mul_pd(_mm256_load_pd(ns[j]), dev), dev));
    }
    const __m256d se =
        _mm256_sqrt_pd(_mm256_div_pd(_mm256_div_pd(ss, _mm256_set1_pd(double(M - 1))), n));
    alignas(32) double meanOut[4], seOut[4];
    _mm256_store_pd(meanOut, mean);
    _mm256_store_pd(seOut, se);
    for (int i = 0; i < 4; ++i) out[i] = LumaSpread{meanOut[i], seOut[i], M};
}

}  // namespace

void lumaSpreads(const PixelBuffers* px, int n, const std::array<double, 3>& luma,
                 LumaSpread* out) {
    const bool wide = cpuHasAvx2();
    int i = 0;
    while (i < n) {
        const int M = px[i].M;
        if (wide && i + 4 <= n && M >= 2 && M <= kSpreadStackM && px[i + 1].M == M &&
            px[i + 2].M == M && px[i + 3].M == M && allBuffersValid(px[i]) &&
            allBuffersValid(px[i + 1]) && allBuffersValid(px[i + 2]) &&
            allBuffersValid(px[i + 3])) {
            lumaSpread4(px + i, luma, out + i);
            i += 4;
        } else {
            out[i] = lumaSpread(px[i], luma);
            ++i;
        }
    }
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
