// The removed light's per-pixel scale and its neighbourhood significance (removed_light.h).
#include "mcstat/filters/removed_light.h"

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "mcstat/core/color_space.h"
#include "mcstat/core/cpu_features.h"
#include "mcstat/core/parallel.h"

namespace mcstat {

namespace {

/// Largest M of lumaSpread's stack arrays, and of the four-pixel path.
constexpr int kSpreadStackM = 64;

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
            ys[j] = luminance(luma, px.mean + 3 * j);
            n += ns[j];
            sum += ns[j] * ys[j];
        }
        out.valid = px.M;
    } else {
        for (int j = 0; j < px.M; ++j) {
            const bool valid = isValidBuffer(px, j);
            ns[j] = valid ? double(px.count[j]) : 0.0;
            if (!valid) continue;
            ys[j] = luminance(luma, px.mean + 3 * j);
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

/// lumaSpread8FromKeys on AVX2: lumaSpread4's sums over the given luminances and counts, for two
/// groups of four pixels (lanes 0-3 and 4-7 of key[8 j + i]) side by side, so that the two
/// groups' chains of dependent additions overlap (the sums of one group alone wait on the
/// adder's latency). Each lane's operations are lumaSpread4's, in its order.
__attribute__((target("avx2"))) void spread8FromKeysAvx2(const double* key, const double* count,
                                                         int M, LumaSpread* out) {
    __m256d nA = _mm256_setzero_pd(), sumA = nA, nB = nA, sumB = nA;
    for (int j = 0; j < M; ++j) {
        const __m256d wA = _mm256_loadu_pd(count + 8 * j), wB = _mm256_loadu_pd(count + 8 * j + 4);
        nA = _mm256_add_pd(nA, wA);
        nB = _mm256_add_pd(nB, wB);
        sumA = _mm256_add_pd(sumA, _mm256_mul_pd(wA, _mm256_loadu_pd(key + 8 * j)));
        sumB = _mm256_add_pd(sumB, _mm256_mul_pd(wB, _mm256_loadu_pd(key + 8 * j + 4)));
    }
    const __m256d meanA = _mm256_div_pd(sumA, nA), meanB = _mm256_div_pd(sumB, nB);
    __m256d ssA = _mm256_setzero_pd(), ssB = ssA;
    for (int j = 0; j < M; ++j) {
        const __m256d devA = _mm256_sub_pd(_mm256_loadu_pd(key + 8 * j), meanA);
        const __m256d devB = _mm256_sub_pd(_mm256_loadu_pd(key + 8 * j + 4), meanB);
        ssA = _mm256_add_pd(
            ssA, _mm256_mul_pd(_mm256_mul_pd(_mm256_loadu_pd(count + 8 * j), devA), devA));
        ssB = _mm256_add_pd(
            ssB, _mm256_mul_pd(_mm256_mul_pd(_mm256_loadu_pd(count + 8 * j + 4), devB), devB));
    }
    const __m256d df = _mm256_set1_pd(double(M - 1));
    const __m256d seA = _mm256_sqrt_pd(_mm256_div_pd(_mm256_div_pd(ssA, df), nA));
    const __m256d seB = _mm256_sqrt_pd(_mm256_div_pd(_mm256_div_pd(ssB, df), nB));
    alignas(32) double mean[8], se[8];
    _mm256_store_pd(mean, meanA);
    _mm256_store_pd(mean + 4, meanB);
    _mm256_store_pd(se, seA);
    _mm256_store_pd(se + 4, seB);
    for (int i = 0; i < 8; ++i) out[i] = LumaSpread{mean[i], se[i], M};
}

/// Four pixels' lumaSpread, one per lane: px[0..3] share M in [2, kSpreadStackM]. Each lane
/// computes lumaSpread's all-valid path: Y_j = (l0 R + l1 G) + l2 B, n += n_j, sum += n_j Y_j,
/// mean = sum / n, ss += (n_j dev) dev, se = sqrt(ss / (M - 1) / n), the same roundings in the same
/// order (no "fma" target: nothing is contracted). allBuffersValid is tested on the way (a mean
/// or count not finite, or a count not above 0): returns the mask of the pixels that have an
/// invalid buffer, whose out[i] the caller must compute by lumaSpread.
__attribute__((target("avx2"))) int lumaSpread4(const PixelBuffers* px,
                                                const std::array<double, 3>& luma,
                                                LumaSpread* out) {
    const int M = px[0].M;
    alignas(32) double ys[kSpreadStackM][4], ns[kSpreadStackM][4];
    const __m256d l0 = _mm256_set1_pd(luma[0]), l1 = _mm256_set1_pd(luma[1]),
                  l2 = _mm256_set1_pd(luma[2]);
    const __m256d zero = _mm256_setzero_pd();
    __m256d n = zero, sum = zero, bad = zero;
    for (int j = 0; j < M; ++j) {
        const float *a = px[0].mean + 3 * j, *b = px[1].mean + 3 * j, *c = px[2].mean + 3 * j,
                    *d = px[3].mean + 3 * j;
        // _mm256_set_pd takes the lanes from the highest down.
        const __m256d r = _mm256_set_pd(d[0], c[0], b[0], a[0]);
        const __m256d g = _mm256_set_pd(d[1], c[1], b[1], a[1]);
        const __m256d bl = _mm256_set_pd(d[2], c[2], b[2], a[2]);
        const __m256d w =
            _mm256_set_pd(px[3].count[j], px[2].count[j], px[1].count[j], px[0].count[j]);
        // x - x is NaN for an infinite or NaN x, 0 otherwise.
        const __m256d t = _mm256_add_pd(_mm256_add_pd(_mm256_sub_pd(r, r), _mm256_sub_pd(g, g)),
                                        _mm256_add_pd(_mm256_sub_pd(bl, bl), _mm256_sub_pd(w, w)));
        bad = _mm256_or_pd(bad, _mm256_or_pd(_mm256_cmp_pd(t, zero, _CMP_NEQ_UQ),
                                             _mm256_cmp_pd(w, zero, _CMP_NGT_UQ)));
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
    return _mm256_movemask_pd(bad);
}

}  // namespace

void lumaSpread8FromKeys(const double* key, const double* count, int M, LumaSpread out[8]) {
    if (cpuHasAvx2()) return spread8FromKeysAvx2(key, count, M, out);
    // lumaSpread's all-valid path per pixel, over its lane of the arrays.
    for (int i = 0; i < 8; ++i) {
        double n = 0.0, sum = 0.0;
        for (int j = 0; j < M; ++j) {
            n += count[8 * j + i];
            sum += count[8 * j + i] * key[8 * j + i];
        }
        const double mean = sum / n;
        double ss = 0.0;
        for (int j = 0; j < M; ++j) {
            const double dev = key[8 * j + i] - mean;
            ss += count[8 * j + i] * dev * dev;
        }
        out[i] = LumaSpread{mean, std::sqrt(ss / double(M - 1) / n), M};
    }
}

void lumaSpreads(const PixelBuffers* px, int n, const std::array<double, 3>& luma,
                 LumaSpread* out) {
    const bool wide = cpuHasAvx2();
    int i = 0;
    while (i < n) {
        const int M = px[i].M;
        if (wide && i + 4 <= n && M >= 2 && M <= kSpreadStackM && px[i + 1].M == M &&
            px[i + 2].M == M && px[i + 3].M == M) {
            const int invalid = lumaSpread4(px + i, luma, out + i);
            for (int k = 0; k < 4; ++k)
                if (invalid & (1 << k)) out[i + k] = lumaSpread(px[i + k], luma);
            i += 4;
        } else {
            out[i] = lumaSpread(px[i], luma);
            ++i;
        }
    }
}

void localRemovedZ(const float* d, const float* se, int width, int height, int radius, float* out,
                   int nthreads) {
    localRemovedZ(d, se, 1, width, height, radius, out, 1, nthreads);
}

void localRemovedZ(const float* d, const float* se, size_t stride, int width, int height,
                   int radius, float* out, size_t outStride, int nthreads) {
    // Separable box sums in double, each window summed directly in index order (rows, then
    // columns): exact zeros stay zero, which running or summed-area tables would not guarantee. A
    // non-finite d or se adds 0.0 to both sums, which leaves a sum that started at +0 as it was.
    // The sums run offset by offset over whole rows (each output's terms in the same order, the
    // loops over x contiguous, so the compiler vectorises them). Bands of kBand output rows: each
    // band sums the rows it reads (its own and `radius` more on either side) into its own arrays,
    // which stay in cache and are reused for the next band; halo rows are summed again by the
    // neighbouring band, with the same sums, so every output is the same whatever the bands and
    // threads.
    constexpr int kBand = 32;
    const size_t w = size_t(width);
    const int bands = (height + kBand - 1) / kBand;
    parallelFor(0, bands, 1, nthreads, [&](int64_t b0, int64_t b1) {
        std::vector<double> rd, rv, cd(w), cv(w), a(w), b(w);
        for (int band = int(b0); band < int(b1); ++band) {
            const int y0 = band * kBand, y1 = std::min(height, y0 + kBand);
            const int r0 = std::max(0, y0 - radius), r1 = std::min(height, y1 + radius);
            rd.assign(size_t(r1 - r0) * w, 0.0);
            rv.assign(size_t(r1 - r0) * w, 0.0);
            for (int y = r0; y < r1; ++y) {
                for (size_t x = 0; x < w; ++x) {
                    const size_t p = (size_t(y) * w + x) * stride;
                    const bool ok = std::isfinite(d[p]) && std::isfinite(se[p]);
                    cd[x] = ok ? double(d[p]) : 0.0;
                    cv[x] = ok ? double(se[p]) * double(se[p]) : 0.0;
                }
                double* rdRow = rd.data() + size_t(y - r0) * w;
                double* rvRow = rv.data() + size_t(y - r0) * w;
                for (int o = -radius; o <= radius; ++o) {
                    // x + o inside the row: x in [max(0, -o), min(width, width - o)).
                    const int xb = std::max(0, -o), xe = std::min(width, width - o);
                    for (int x = xb; x < xe; ++x) {
                        rdRow[x] += cd[size_t(x + o)];
                        rvRow[x] += cv[size_t(x + o)];
                    }
                }
            }
            for (int y = y0; y < y1; ++y) {
                std::fill(a.begin(), a.end(), 0.0);
                std::fill(b.begin(), b.end(), 0.0);
                for (int j = std::max(0, y - radius); j < std::min(height, y + radius + 1); ++j) {
                    const double* rdRow = rd.data() + size_t(j - r0) * w;
                    const double* rvRow = rv.data() + size_t(j - r0) * w;
                    for (size_t x = 0; x < w; ++x) {
                        a[x] += rdRow[x];
                        b[x] += rvRow[x];
                    }
                }
                for (size_t x = 0; x < w; ++x)
                    out[(size_t(y) * w + x) * outStride] = float(removedZ(a[x], std::sqrt(b[x])));
            }
        }
    });
}

}  // namespace mcstat
