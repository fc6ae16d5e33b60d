// Internal to filters/pixel/: the plain mean's pass on AVX2, shared by the mean's estimate
// (ranking.cpp) and its estimate-with-interval runs (confidence.cpp), which also keep the valid
// buffers widened to double for the interval's second pass.
#pragma once

#include <immintrin.h>

#include "mcstat/core/pixel_buffers.h"
#include "mcstat/filters/estimate.h"

namespace mcstat::detail {

/// What meanPassAvx2 leaves besides the estimates.
enum class MeanPassKeeps {
    Nothing,
    Valid,    ///< the valid buffers' indices (valid[k]), the sums and the counts of valid buffers
    Widened,  ///< the valid buffers' (R, G, B, count) as doubles, 4 per buffer in widened[k], and
              ///< the sums and counts
};

/// One buffer's R, G, B and count as four floats, read without touching memory past its three
/// means (the last buffer of the image ends its array).
__attribute__((target("avx2"))) inline __m128 bufferLanes(const float* m, float cnt) {
    const __m128 rg = _mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(m)));
    return _mm_insert_ps(_mm_insert_ps(rg, _mm_load_ss(m + 2), 0x20), _mm_set_ss(cnt), 0x30);
}

/// The plain mean's pass (ranking.cpp, meanPass) of K pixels of equal M on AVX2: the four sums of
/// a pixel (s0, s1, s2, w) are one register's lanes, each buffer adds (n m0, n m1, n m2, n) to
/// them: the same products (n times the widened mean), the same additions in the same order, so
/// the same bits, in a third of the instructions. The float tests are meanPass's: any of x - x not
/// zero (NaN or Inf among the means and the count) or a negative count excludes the buffer; a
/// zero count skips it. sums[k] = (w, s0, s1, s2), count[k] = pixel k's valid buffers. With
/// `means` (the interval's pass), the estimate's three divisions s_c / w are one register's
/// (correctly rounded in any width: the same bits), kept in means[k] = (s0 / w, s1 / w, s2 / w, 1)
/// where pixel k has a valid buffer; the estimate alone keeps the scalar divisions, whose latency
/// is shorter (the register's made the mean 5 % slower).
template <MeanPassKeeps kKeep, int K>
__attribute__((target("avx2"))) void meanPassAvx2(const PixelBuffers* px, PixelEstimate* out,
                                                  int* const* valid, double (*sums)[4], int* count,
                                                  double* const* widened,
                                                  __m256d* means = nullptr) {
    int excluded[K] = {}, Mv[K] = {};
    __m256d acc[K];
    for (int k = 0; k < K; ++k) acc[k] = _mm256_setzero_pd();
    const __m128 zero = _mm_setzero_ps();
    for (int j = 0; j < px[0].M; ++j)
        for (int k = 0; k < K; ++k) {
            const float cnt = px[k].count[j];
            const __m128 v = bufferLanes(px[k].mean + 3 * j, cnt);
            const int bad = _mm_movemask_ps(_mm_cmp_ps(_mm_sub_ps(v, v), zero, _CMP_NEQ_UQ));
            if (bad | (cnt < 0.f)) {
                ++excluded[k];
                continue;
            }
            if (cnt == 0.f) continue;
            const __m256d x = _mm256_cvtps_pd(v);  // (m0, m1, m2, n)
            const __m256d n = _mm256_permute4x64_pd(x, 0xff);
            acc[k] = _mm256_add_pd(acc[k], _mm256_blend_pd(_mm256_mul_pd(n, x), x, 0x8));
            if constexpr (kKeep == MeanPassKeeps::Valid) valid[k][Mv[k]] = j;
            if constexpr (kKeep == MeanPassKeeps::Widened)
                _mm256_store_pd(widened[k] + 4 * Mv[k], x);
            ++Mv[k];
        }
    for (int k = 0; k < K; ++k) {
        alignas(32) double s[4];
        _mm256_store_pd(s, acc[k]);
        if constexpr (kKeep != MeanPassKeeps::Nothing) {
            sums[k][0] = s[3];
            sums[k][1] = s[0];
            sums[k][2] = s[1];
            sums[k][3] = s[2];
            count[k] = Mv[k];
        }
        out[k] = PixelEstimate{};
        out[k].excluded = excluded[k];
        if (Mv[k] == 0) continue;
        if (means) {
            const __m256d mean = _mm256_div_pd(acc[k], _mm256_permute4x64_pd(acc[k], 0xff));
            means[k] = mean;
            alignas(16) float rgb[4];
            _mm_store_ps(rgb, _mm256_cvtpd_ps(mean));
            out[k].rgb = {rgb[0], rgb[1], rgb[2]};
        } else {
            out[k].rgb = {float(s[0] / s[3]), float(s[1] / s[3]), float(s[2] / s[3])};
        }
        out[k].kept = {Mv[k], Mv[k], Mv[k]};
    }
}

}  // namespace mcstat::detail
