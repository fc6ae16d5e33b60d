// The ranked trimmed mean behind the rank estimators (ranking.h): ranking, the Gini coefficient
// (Buisine et al. 2021 eq. 4), the general path and the fast path for M <= 64, with the trim each
// estimator's TrimRule supplies. The shared rules (valid buffers, weights, negatives,
// empty pixels) are in include/mcstat/filters/pixel/pixel_estimate.h.
#include "mcstat/filters/pixel/ranking.h"

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "mcstat/core/color_space.h"
#include "mcstat/core/cpu_features.h"
#include "mcstat/filters/pixel/detail/rank_keys.h"
#include "mean_pass.h"

namespace mcstat {

double giniSorted(const double* v, size_t n) {
    if (n < 2) return 0.0;
    // Eq. 4 is G = 2 sum_j j x_j / (n sum_j x_j) - (n + 1) / n for ascending x_j, j = 1..n.
    // Over a common denominator: G = sum_j (2j - n - 1) x_j / (n sum_j x_j). That form has no
    // cancellation between two terms near 1, and all-equal inputs give exactly 0.
    // Gini is defined for non-negative values: shift by -min when the smallest is negative.
    const double shift = v[0] < 0.0 ? -v[0] : 0.0;
    double sum = 0.0, weighted = 0.0;
    const double nd = double(n);
    for (size_t j = 0; j < n; ++j) {
        const double x = v[j] + shift;
        sum += x;
        weighted += (2.0 * double(j + 1) - nd - 1.0) * x;
    }
    if (!(sum > 0.0) || !std::isfinite(sum)) return 0.0;  // all zero: perfect equality
    const double G = weighted / (nd * sum);
    return std::clamp(G, 0.0, 1.0);
}

double giniMagnitudes(const double* v, size_t n) {
    if (n < 2 || v[0] >= 0.0) return giniSorted(v, n);
    // A buffer's distance from zero, not its signed value, is what eq. 4 weighs: the means below
    // zero (ascending in magnitude from the last of them back to the first) merged with the others
    // (ascending from the first), then eq. 4 in giniSorted's form. Summed in order of magnitude,
    // as giniSorted sums.
    size_t neg = 0;
    while (neg < n && v[neg] < 0.0) ++neg;
    size_t a = neg, b = neg;  // next negative is v[a - 1], next other is v[b]
    double sum = 0.0, weighted = 0.0;
    const double nd = double(n);
    for (size_t j = 0; j < n; ++j) {
        double x;
        if (b < n && (a == 0 || v[b] <= -v[a - 1])) {
            x = v[b++];
        } else {
            x = -v[--a];
        }
        sum += x;
        weighted += (2.0 * double(j + 1) - nd - 1.0) * x;
    }
    if (!(sum > 0.0) || !std::isfinite(sum)) return 0.0;
    const double G = weighted / (nd * sum);
    return std::clamp(G, 0.0, 1.0);
}

namespace {

int collectValid(const PixelBuffers& px, EstimatorScratch& s, int& excluded) {
    return collectValidBuffers(px, s.order, excluded);
}

/// Sorts s.order ascending by s.key[j] (ties by buffer index, so results never depend on the sort).
void sortByKey(EstimatorScratch& s) {
    std::sort(s.order.begin(), s.order.end(), [&s](int a, int b) {
        return s.key[a] < s.key[b] || (s.key[a] == s.key[b] && a < b);
    });
}

/// Count-weighted mean of channels [c0, c1) over ranks [lo, hi) of s.order.
void weightedAverage(const PixelBuffers& px, const EstimatorScratch& s, int lo, int hi, int c0,
                     int c1, PixelEstimate& out) {
    double sum[3] = {0.0, 0.0, 0.0}, w = 0.0;
    for (int r = lo; r < hi; ++r) {
        const int j = s.order[r];
        const double n = px.count[j];
        w += n;
        for (int c = c0; c < c1; ++c) sum[c] += n * double(px.mean[3 * j + c]);
    }
    for (int c = c0; c < c1; ++c) out.rgb[c] = float(sum[c] / w);
}

/// The weights of a luminance-mode estimate that averaged ranks [lo, hi) of s.order with counts as
/// weights: w_j = n_j / sum n over those buffers, 0 for the others (EstimatorScratch::wantWeights).
void rankWeights(const PixelBuffers& px, EstimatorScratch& s, int lo, int hi) {
    s.bufferWeight.assign(size_t(px.M), 0.0);
    double w = 0.0;
    for (int r = lo; r < hi; ++r) w += double(px.count[s.order[r]]);
    if (!(w > 0.0)) return;
    for (int r = lo; r < hi; ++r)
        s.bufferWeight[size_t(s.order[r])] = double(px.count[s.order[r]]) / w;
}

/// The rule's c for M_v ranked means whose Gini coefficient is G (0 unless it uses G).
inline int trimFor(const TrimRule& rule, double G, int Mv) {
    return rule.trim != nullptr ? rule.trim(rule, G, Mv) : 0;
}

inline bool needsGini(const TrimRule& rule) { return rule.usesGini; }

/// G of the ranked keys under the rule's GiniInput.
inline double giniOf(const TrimRule& rule, const double* sorted, size_t n) {
    return rule.gini == GiniInput::Magnitudes ? giniMagnitudes(sorted, n) : giniSorted(sorted, n);
}

/// Shared body: every estimator here is "rank the valid means, trim c from each side, average the
/// rest with counts as weights", differing only in how c is chosen. This is the general version
/// (any M, vectors in the scratch); reduceSmall below is the fast path for M <= kSmallM and gives
/// the same bits.
void reduceGeneral(const PixelBuffers& px, const PixelParams& p, PixelEstimate& out,
                   EstimatorScratch& s, const TrimRule& policy) {
    out = PixelEstimate{};
    const int Mv = collectValid(px, s, out.excluded);
    if (Mv == 0) return;  // no sample: black, kept = 0
    const bool needGini = needsGini(policy);
    s.key.resize(size_t(px.M));
    s.sorted.resize(size_t(Mv));

    if (policy.trim == nullptr) {
        weightedAverage(px, s, 0, Mv, 0, 3, out);
        out.kept = {Mv, Mv, Mv};
        return;
    }
    if (p.mode == EstimatorMode::Luminance) {
        for (int j : s.order) {
            const float* m = px.mean + 3 * j;
            s.key[j] = luminance(p.luma, m);
        }
        sortByKey(s);
        double G = 0.0;
        if (needGini) {
            for (int r = 0; r < Mv; ++r) s.sorted[r] = s.key[s.order[r]];
            G = giniOf(policy, s.sorted.data(), size_t(Mv));
        }
        const int c = trimFor(policy, G, Mv);
        weightedAverage(px, s, c, Mv - c, 0, 3, out);
        if (s.wantWeights) rankWeights(px, s, c, Mv - c);
        out.gini.fill(float(G));
        out.kept.fill(Mv - 2 * c);
        return;
    }
    for (int ch = 0; ch < 3; ++ch) {
        for (int j : s.order) s.key[j] = px.mean[3 * j + ch];
        sortByKey(s);
        double G = 0.0;
        if (needGini) {
            for (int r = 0; r < Mv; ++r) s.sorted[r] = s.key[s.order[r]];
            G = giniOf(policy, s.sorted.data(), size_t(Mv));
        }
        const int c = trimFor(policy, G, Mv);
        weightedAverage(px, s, c, Mv - c, ch, ch + 1, out);
        out.gini[ch] = float(G);
        out.kept[ch] = Mv - 2 * c;
    }
}

// ---- fast path: the same arithmetic on small fixed arrays -------------------------------------
// Bit-identity with reduceGeneral (tests/filters/pixel/test_bit_identity.cpp) rests on three facts:
// the valid buffers are the same ones in the same index order; the ranking is the same total order
// (key ascending, ties by buffer index), so every sum below adds the same doubles in the same
// order; and every formula (luminance, Gini via giniSorted, trim, weighted average) is the same
// expression in double. Only where the numbers live and how many are handled at once changed:
// stack arrays instead of vectors, the luminance computed once per buffer (four at a time with
// AVX2), ranks counted by vector comparisons, and independent sums carried as vector lanes.

/// Whether the fast path uses its AVX2 functions (set once from the CPU; detail::setUseAvx2 lets
/// the bit-identity test run the portable versions too). Both give the same bits.
bool& useAvx2() {
    static bool on = cpuHasAvx2();
    return on;
}

/// Largest M the fast path takes (stack arrays); larger M goes to reduceGeneral.
constexpr int kSmallM = 64;

/// One pixel's valid buffers and their ranking, on the stack. The AVX2 ranking pads the keys with
/// +inf to a multiple of 8 (it reads blocks of 8).
struct SmallPixel {
    int n = 0;                ///< M_v
    int idx[kSmallM];         ///< buffer index of the i-th valid buffer (index order)
    double count[kSmallM];    ///< its count
    double key[kSmallM + 8];  ///< its key (luminance or one channel), then +inf padding
    int order[kSmallM];       ///< valid-buffer position by rank
    double sorted[kSmallM];   ///< key by rank
};

/// Which buffers loadBuffers found valid, excluded, or valid with a NaN key: bit j for buffer j.
struct BufferMasks {
    uint64_t take = 0, bad = 0, nanKey = 0;
    int nTake = 0, nBad = 0;  ///< the bits set in take and bad
};

/// collectValidBuffers' rules for buffer j, without branches: x - x is 0 for a finite float and NaN
/// for NaN/Inf, so `fin` is 0 exactly when the count and the three channels are finite. A buffer is
/// excluded when not finite or of negative count, skipped when its count is 0 (or -0). With `lum`
/// the key is the luminance, the same expression as in reduceGeneral (products and sums in double,
/// left to right).
inline void loadOne(const float* mean, const float* count, int j, bool lum, double l0, double l1,
                    double l2, SmallPixel& sp, BufferMasks& mk) {
    const float cnt = count[j];
    const float* m = mean + 3 * j;
    const float fin = ((cnt - cnt) + (m[0] - m[0])) + ((m[1] - m[1]) + (m[2] - m[2]));
    const uint64_t bad = (fin != 0.f) | (cnt < 0.f);  // NaN != 0
    const uint64_t take = (bad ^ 1) & (cnt != 0.f);
    mk.bad |= bad << j;
    mk.take |= take << j;
    sp.count[j] = cnt;
    sp.idx[j] = j;
    if (lum) {
        const double k = l0 * double(m[0]) + l1 * double(m[1]) + l2 * double(m[2]);
        mk.nanKey |= uint64_t(k != k) << j;
        sp.key[j] = k;
    }
}

/// loadOne for every buffer j < M (no compaction): the portable version.
BufferMasks loadScalar(const float* mean, const float* count, int M, bool lum, double l0, double l1,
                       double l2, SmallPixel& sp) {
    BufferMasks mk;
    for (int j = 0; j < M; ++j) loadOne(mean, count, j, lum, l0, l1, l2, sp, mk);
    mk.nanKey &= mk.take;
    mk.nTake = __builtin_popcountll(mk.take);
    mk.nBad = __builtin_popcountll(mk.bad);
    return mk;
}

/// loadScalar four buffers at a time: the same float tests (the comparisons of `fin` and of the
/// count, on four buffers at once) and the same luminance (mul and add in double, left to right,
/// correctly rounded in any width; no FMA in this target).
__attribute__((target("avx2,popcnt"))) BufferMasks loadAvx2(const float* mean, const float* count,
                                                            int M, bool lum, double l0, double l1,
                                                            double l2, SmallPixel& sp) {
    BufferMasks mk;
    const __m256d L0 = _mm256_set1_pd(l0), L1 = _mm256_set1_pd(l1), L2 = _mm256_set1_pd(l2);
    const __m128 zero = _mm_setzero_ps();
    int j = 0;
    for (; j + 4 <= M; j += 4) {
        const float* m = mean + 3 * j;
        const __m128 c = _mm_loadu_ps(count + j);
        // Deinterleave the 12 means of buffers j..j+3 (x = m[0..7], y = m[8..11] twice).
        const __m256 x = _mm256_loadu_ps(m);
        const __m128 c8 = _mm_loadu_ps(m + 8);
        const __m256 y = _mm256_set_m128(c8, c8);
        const __m256 rg = _mm256_blend_ps(
            _mm256_permutevar8x32_ps(x, _mm256_setr_epi32(0, 3, 6, 0, 1, 4, 7, 0)),
            _mm256_permutevar8x32_ps(y, _mm256_setr_epi32(0, 0, 0, 1, 0, 0, 0, 2)), 0x88);
        const __m128 b = _mm256_castps256_ps128(_mm256_blend_ps(
            _mm256_permutevar8x32_ps(x, _mm256_setr_epi32(2, 5, 0, 0, 0, 0, 0, 0)),
            _mm256_permutevar8x32_ps(y, _mm256_setr_epi32(0, 0, 0, 3, 0, 0, 0, 0)), 0x0c));
        const __m128 r = _mm256_castps256_ps128(rg), g = _mm256_extractf128_ps(rg, 1);
        const __m128 fin = _mm_add_ps(_mm_add_ps(_mm_sub_ps(c, c), _mm_sub_ps(r, r)),
                                      _mm_add_ps(_mm_sub_ps(g, g), _mm_sub_ps(b, b)));
        const __m128 bad =
            _mm_or_ps(_mm_cmp_ps(fin, zero, _CMP_NEQ_UQ), _mm_cmp_ps(c, zero, _CMP_LT_OQ));
        const __m128 take = _mm_andnot_ps(bad, _mm_cmp_ps(c, zero, _CMP_NEQ_UQ));
        mk.bad |= uint64_t(_mm_movemask_ps(bad)) << j;
        mk.take |= uint64_t(_mm_movemask_ps(take)) << j;
        _mm256_storeu_pd(sp.count + j, _mm256_cvtps_pd(c));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(sp.idx + j),
                         _mm_setr_epi32(j, j + 1, j + 2, j + 3));
        if (lum) {
            const __m256d k = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(L0, _mm256_cvtps_pd(r)),
                                                          _mm256_mul_pd(L1, _mm256_cvtps_pd(g))),
                                            _mm256_mul_pd(L2, _mm256_cvtps_pd(b)));
            mk.nanKey |= uint64_t(_mm256_movemask_pd(_mm256_cmp_pd(k, k, _CMP_UNORD_Q))) << j;
            _mm256_storeu_pd(sp.key + j, k);
        }
    }
    for (; j < M; ++j) loadOne(mean, count, j, lum, l0, l1, l2, sp, mk);
    mk.nanKey &= mk.take;
    // The processor's popcnt (every AVX2 processor has it): without -mpopcnt the builtin is a
    // call into libgcc, 1 % of a rank estimator's time.
    mk.nTake = int(_mm_popcnt_u64(mk.take));
    mk.nBad = int(_mm_popcnt_u64(mk.bad));
    return mk;
}

// Exact ranks in the order "key ascending, ties by buffer index" (sortByKey's order): the rank of
// i is #{j < i : key_j <= key_i} + #{j > i : key_j < key_i}. Keys are never NaN (checked by the
// caller), so the ranks are a permutation of 0..n-1. Branch-free counting beats a comparison sort
// at these sizes (no mispredicted branches) and vectorises. Both versions only compare, so the
// ranks do not depend on the CPU.

/// The portable version of rankAvx2.
void rankScalar(const double* key, int n, int* rank) {
    for (int i = 0; i < n; ++i) {
        int r = 0;
        const double ki = key[i];
        for (int j = 0; j < i; ++j) r += key[j] <= ki;
        for (int j = i + 1; j < n; ++j) r += key[j] < ki;
        rank[i] = r;
    }
}

/// Ranks of 8 keys at a time: each key_j is broadcast and compared with 8 key_i in two registers,
/// the counts stay in registers (a true comparison is all ones, i.e. -1: subtracting counts it).
/// Below the block of 8 the test is <=, above it <, and inside it < or (== and lower index).
/// `key` is padded with +inf to a multiple of 8 (ranks of the padding are computed and ignored).
__attribute__((target("avx2"))) void rankAvx2(const double* key, int n, int* order,
                                              double* sorted) {
    const int padded = (n + 7) & ~7;
    for (int i0 = 0; i0 < padded; i0 += 8) {
        const __m256d a = _mm256_loadu_pd(key + i0), b = _mm256_loadu_pd(key + i0 + 4);
        __m256i ra = _mm256_setzero_si256(), rb = _mm256_setzero_si256();
        for (int j = 0; j < i0; ++j) {
            const __m256d kj = _mm256_broadcast_sd(key + j);
            ra = _mm256_sub_epi64(ra, _mm256_castpd_si256(_mm256_cmp_pd(kj, a, _CMP_LE_OQ)));
            rb = _mm256_sub_epi64(rb, _mm256_castpd_si256(_mm256_cmp_pd(kj, b, _CMP_LE_OQ)));
        }
        const __m256i ia = _mm256_setr_epi64x(i0, i0 + 1, i0 + 2, i0 + 3);
        const __m256i ib = _mm256_setr_epi64x(i0 + 4, i0 + 5, i0 + 6, i0 + 7);
        const int mid = std::min(i0 + 8, n);
        for (int j = i0; j < mid; ++j) {
            const __m256d kj = _mm256_broadcast_sd(key + j);
            const __m256i jv = _mm256_set1_epi64x(j);
            const __m256i la = _mm256_or_si256(
                _mm256_castpd_si256(_mm256_cmp_pd(kj, a, _CMP_LT_OQ)),
                _mm256_and_si256(_mm256_castpd_si256(_mm256_cmp_pd(kj, a, _CMP_EQ_OQ)),
                                 _mm256_cmpgt_epi64(ia, jv)));
            const __m256i lb = _mm256_or_si256(
                _mm256_castpd_si256(_mm256_cmp_pd(kj, b, _CMP_LT_OQ)),
                _mm256_and_si256(_mm256_castpd_si256(_mm256_cmp_pd(kj, b, _CMP_EQ_OQ)),
                                 _mm256_cmpgt_epi64(ib, jv)));
            ra = _mm256_sub_epi64(ra, la);
            rb = _mm256_sub_epi64(rb, lb);
        }
        for (int j = mid; j < n; ++j) {
            const __m256d kj = _mm256_broadcast_sd(key + j);
            ra = _mm256_sub_epi64(ra, _mm256_castpd_si256(_mm256_cmp_pd(kj, a, _CMP_LT_OQ)));
            rb = _mm256_sub_epi64(rb, _mm256_castpd_si256(_mm256_cmp_pd(kj, b, _CMP_LT_OQ)));
        }
        // Scatter straight from the registers: the ranks never go through memory (a scalar load
        // of a rank just stored as a vector waited for the store).
        const __m128i q[4] = {_mm256_castsi256_si128(ra), _mm256_extracti128_si256(ra, 1),
                              _mm256_castsi256_si128(rb), _mm256_extracti128_si256(rb, 1)};
        long long r[8];
        for (int h = 0; h < 4; ++h) {
            r[2 * h] = _mm_cvtsi128_si64(q[h]);
            r[2 * h + 1] = _mm_extract_epi64(q[h], 1);
        }
        for (int t = 0; t < 8 && i0 + t < n; ++t) {
            order[r[t]] = i0 + t;
            sorted[r[t]] = key[i0 + t];
        }
    }
}

/// rankAvx2 on the keys rounded to float, eight lanes per register, when that is exact: rounding
/// to nearest is monotone, so float(k_j) < float(k_i) implies k_j < k_i, and when the n rounded
/// keys are distinct their "less" counts are the ranks of the doubles (a permutation of 0..n-1,
/// summing to n(n-1)/2). Equal rounded keys give equal counts, a smaller sum, and false: the
/// caller then ranks the doubles. One comparison per key pair and per 8 lanes instead of 4, no
/// tie test. `key` is padded with +inf to a multiple of 8.
__attribute__((target("avx2"))) bool rankFloatAvx2(const double* key, int n, int* order,
                                                   double* sorted) {
    const int padded = (n + 7) & ~7;
    alignas(32) float kf[kSmallM];
    for (int i = 0; i < padded; i += 8) {
        const __m128 lo = _mm256_cvtpd_ps(_mm256_loadu_pd(key + i));
        const __m128 hi = _mm256_cvtpd_ps(_mm256_loadu_pd(key + i + 4));
        _mm256_store_ps(kf + i, _mm256_set_m128(hi, lo));
    }
    alignas(32) int rank[kSmallM];
    __m256i total = _mm256_setzero_si256();
    for (int i0 = 0; i0 < padded; i0 += 8) {
        const __m256 a = _mm256_load_ps(kf + i0);
        __m256i r = _mm256_setzero_si256();
        for (int j = 0; j < n; ++j)
            r = _mm256_sub_epi32(
                r, _mm256_castps_si256(_mm256_cmp_ps(_mm256_broadcast_ss(kf + j), a, _CMP_LT_OQ)));
        _mm256_store_si256(reinterpret_cast<__m256i*>(rank + i0), r);
        total = _mm256_add_epi32(total, r);
    }
    // The padding (+inf, or its rounding) counts the n finite keys below it: n per padded lane.
    alignas(32) int lanes[8];
    _mm256_store_si256(reinterpret_cast<__m256i*>(lanes), total);
    long long sum = 0;
    for (int t = 0; t < 8; ++t) sum += lanes[t];
    if (sum - (long long)(padded - n) * n != (long long)n * (n - 1) / 2) return false;
    for (int i = 0; i < n; ++i) {
        order[rank[i]] = i;
        sorted[rank[i]] = key[i];
    }
    return true;
}

/// Ranks sp.key (padded here with +inf for rankAvx2) and fills sp.order / sp.sorted.
void rankSmall(SmallPixel& sp) {
    const int n = sp.n;
    if (useAvx2() && n >= 8) {
        for (int i = n; i < ((n + 7) & ~7); ++i)
            sp.key[i] = std::numeric_limits<double>::infinity();
        if (!rankFloatAvx2(sp.key, n, sp.order, sp.sorted))
            rankAvx2(sp.key, n, sp.order, sp.sorted);
        return;
    }
    int rank[kSmallM];
    rankScalar(sp.key, n, rank);
    for (int i = 0; i < n; ++i) {
        sp.order[rank[i]] = i;
        sp.sorted[rank[i]] = sp.key[i];
    }
}

// The channel loops below have a compile-time length NC (3 in luminance mode, 1 per channel).
// The NC channel sums and the weight sum are lanes of 128-bit vectors (GCC vector extension, SSE2
// registers): lane c adds n * mean_c, lane NC adds n * 1.0 = n exactly, each lane in rank order as
// before, so every sum is the same chain of the same double additions; (NC + 2) / 2 vector
// additions per rank instead of NC + 1 dependent scalar ones.
typedef double Lanes2 __attribute__((vector_size(16)));

/// sum_r n_r {m_r[0], .., m_r[NC-1], 1}: the channel sums, then the weight.
template <int NC>
struct WeightedSums {
    Lanes2 v[(NC + 2) / 2] = {};
    /// Adds n * {m[0], .., m[NC-1], 1} (one buffer, channel c0 first).
    void add(double n, const float* m) {
        if constexpr (NC == 1) {
            v[0] += n * Lanes2{double(m[0]), 1.0};
        } else {
            v[0] += n * Lanes2{double(m[0]), double(m[1])};
            v[1] += n * Lanes2{double(m[2]), 1.0};
        }
    }
    double lane(int c) const { return v[c / 2][c % 2]; }
    /// The average of channel c: its sum over the weight.
    float average(int c) const { return float(lane(c) / lane(NC)); }
};

/// weightedAverage over ranks [lo, hi) of sp.order, channels [c0, c0 + NC): the same sums in the
/// same order.
template <int NC>
void weightedAverageSmall(const PixelBuffers& px, const SmallPixel& sp, int lo, int hi, int c0,
                          PixelEstimate& out) {
    WeightedSums<NC> acc;
    for (int r = lo; r < hi; ++r) {
        const int i = sp.order[r];
        acc.add(sp.count[i], px.mean + 3 * sp.idx[i] + c0);
    }
    for (int c = 0; c < NC; ++c) out.rgb[size_t(c0 + c)] = acc.average(c);
}

/// giniSorted(sp.sorted, n) (same expression, same order) fused with the untrimmed weighted
/// average of channels [c0, c0 + NC) (weightedAverageSmall over all ranks). The two are
/// independent chains of additions, so running them in one loop overlaps their latencies; the
/// average is used when the trim turns out to be 0 (smooth pixels: G small), else recomputed.
/// Eq. 4's weight 2 (j + 1) - n - 1 is a small integer, so stepping it by 2.0 is exact (the same
/// doubles as before); sum and weighted sum are the lanes {1 * x, weight * x} of one vector.
/// With GiniInput::Magnitudes and a negative key, G is giniMagnitudes' (the average is the same).
template <int NC>
double giniWithFullAverage(const PixelBuffers& px, const SmallPixel& sp, int c0, float* rgb,
                           GiniInput input) {
    const int n = sp.n;
    const double* v = sp.sorted;
    const double shift = v[0] < 0.0 ? -v[0] : 0.0;
    Lanes2 gs = {};  // {sum, weighted}
    WeightedSums<NC> avg;
    const double nd = double(n);
    Lanes2 weight = {1.0, 1.0 - nd};  // {1, 2 (j + 1) - n - 1}: small integers, exact
    for (int j = 0; j < n; ++j) {
        const double x = v[j] + shift;
        gs += weight * x;
        weight += Lanes2{0.0, 2.0};
        const int i = sp.order[j];
        avg.add(sp.count[i], px.mean + 3 * sp.idx[i] + c0);
    }
    for (int c = 0; c < NC; ++c) rgb[c] = avg.average(c);
    const double sum = gs[0], weighted = gs[1];
    if (n < 2) return 0.0;
    if (input == GiniInput::Magnitudes && v[0] < 0.0) return giniMagnitudes(v, size_t(n));
    if (!(sum > 0.0) || !std::isfinite(sum)) return 0.0;  // all zero: perfect equality
    const double G = weighted / (nd * sum);
    return std::clamp(G, 0.0, 1.0);
}

/// One pixel (luminance, NC = 3) or one channel (NC = 1): G if the policy needs it, the trim, the
/// average.
template <int NC>
void rankedReduce(const PixelBuffers& px, SmallPixel& sp, const TrimRule& policy, int c0,
                  PixelEstimate& out, double& G, int& c) {
    const int Mv = sp.n;
    rankSmall(sp);
    if (needsGini(policy)) {
        float full[NC];
        G = giniWithFullAverage<NC>(px, sp, c0, full, policy.gini);
        c = trimFor(policy, G, Mv);
        if (c == 0) {
            for (int ch = 0; ch < NC; ++ch) out.rgb[size_t(c0 + ch)] = full[ch];
            return;
        }
    } else {
        G = 0.0;
        c = trimFor(policy, G, Mv);
    }
    weightedAverageSmall<NC>(px, sp, c, Mv - c, c0, out);
}

/// Leaves a pixel's buffer luminances and counts, every buffer valid, where the caller asked
/// (EstimatorScratch::LumaKeys) if they were computed with the coefficients it gave. Out of line:
/// reduceSmall's registers stay its own when nobody asks.
__attribute__((noinline)) void leaveLumaKeys(const SmallPixel& sp, int M,
                                             const std::array<double, 3>& luma,
                                             EstimatorScratch::LumaKeys& k) {
    if (k.luma != luma) return;
    for (int j = 0; j < M; ++j) {
        k.key[j * k.stride] = sp.key[j];
        k.count[j * k.stride] = sp.count[j];
    }
    k.given = true;
}

/// The fast path of reduceGeneral for px.M <= kSmallM and every policy but Mean (meanOnePass).
/// Returns false (nothing written) when a key
/// is NaN (only possible with non-finite luminance weights): the general path then decides.
bool reduceSmall(const PixelBuffers& px, const PixelParams& p, PixelEstimate& out,
                 EstimatorScratch& s, const TrimRule& policy) {
    SmallPixel sp;
    const bool lum = p.mode == EstimatorMode::Luminance;
    const int M = px.M;
    // Below 8 buffers the portable code is faster (no call through the dispatch, no padding).
    const bool avx2 = useAvx2() && M >= 8;
    const double l0 = p.luma[0], l1 = p.luma[1], l2 = p.luma[2];
    const BufferMasks mk = avx2 ? loadAvx2(px.mean, px.count, M, lum, l0, l1, l2, sp)
                                : loadScalar(px.mean, px.count, M, lum, l0, l1, l2, sp);
    if (mk.nanKey) return false;
    const int excluded = mk.nBad;
    const int n = mk.nTake;
    if (s.lumaKeys.key && n == M && lum) leaveLumaKeys(sp, M, p.luma, s.lumaKeys);
    if (n != M) {
        // Some buffers left out (rare): keep the valid ones in index order, in place (i <= j).
        int i = 0;
        for (uint64_t t = mk.take; t; t &= t - 1, ++i) {
            const int j = __builtin_ctzll(t);
            sp.idx[i] = j;
            sp.count[i] = sp.count[j];
            if (lum) sp.key[i] = sp.key[j];
        }
    }
    sp.n = n;
    out = PixelEstimate{};
    out.excluded = excluded;
    const int Mv = n;
    if (Mv == 0) return true;  // no sample: black, kept = 0

    double G;
    int c;
    if (lum) {
        rankedReduce<3>(px, sp, policy, 0, out, G, c);
        out.gini.fill(float(G));
        out.kept.fill(Mv - 2 * c);
        return true;
    }
    for (int ch = 0; ch < 3; ++ch) {
        for (int i = 0; i < Mv; ++i) sp.key[i] = px.mean[3 * sp.idx[i] + ch];
        rankedReduce<1>(px, sp, policy, ch, out, G, c);
        out.gini[ch] = float(G);
        out.kept[ch] = Mv - 2 * c;
    }
    return true;
}

/// The plain mean in one pass for any M: the valid buffers in index order, summed as they are
/// found (collectValidBuffers + weightedAverage over ranks [0, M_v) in index order: the same sums
/// in the same order), no keys, no arrays. With `valid` non-null it also records the valid
/// buffers' indices (room for px.M) and the sums (plainMeanPass).
template <bool kRecord>
int meanPass(const PixelBuffers& px, PixelEstimate& out, int* valid, double* sums) {
    int excluded = 0, Mv = 0;
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, w = 0.0;
    for (int j = 0; j < px.M; ++j) {
        const float cnt = px.count[j];
        const float* m = px.mean + 3 * j;
        const float fin = ((cnt - cnt) + (m[0] - m[0])) + ((m[1] - m[1]) + (m[2] - m[2]));
        if ((fin != 0.f) | (cnt < 0.f)) {  // NaN/Inf or negative count: excluded
            ++excluded;
            continue;
        }
        if (cnt == 0.f) continue;  // empty buffer
        const double n = cnt;
        w += n;
        s0 += n * double(m[0]);
        s1 += n * double(m[1]);
        s2 += n * double(m[2]);
        if constexpr (kRecord) valid[Mv] = j;
        ++Mv;
    }
    if constexpr (kRecord) {
        sums[0] = w;
        sums[1] = s0;
        sums[2] = s1;
        sums[3] = s2;
    }
    out = PixelEstimate{};
    out.excluded = excluded;
    if (Mv == 0) return 0;
    out.rgb = {float(s0 / w), float(s1 / w), float(s2 / w)};
    out.kept = {Mv, Mv, Mv};
    return Mv;
}

/// meanPass, or detail::meanPassAvx2 (the same bits) where the processor allows.
template <bool kRecord>
int meanPasses(const PixelBuffers& px, PixelEstimate& out, int* valid, double* sums) {
    if (!useAvx2()) return meanPass<kRecord>(px, out, valid, sums);
    using detail::MeanPassKeeps;
    constexpr MeanPassKeeps keep = kRecord ? MeanPassKeeps::Valid : MeanPassKeeps::Nothing;
    double s[1][4];
    int m = 0;
    detail::meanPassAvx2<keep, 1>(&px, &out, &valid, s, &m, nullptr);
    if constexpr (kRecord) std::copy(s[0], s[0] + 4, sums);
    return m;
}

void meanOnePass(const PixelBuffers& px, PixelEstimate& out) {
    meanPasses<false>(px, out, nullptr, nullptr);
}

void reduce(const PixelBuffers& px, const PixelParams& p, PixelEstimate& out, EstimatorScratch& s,
            const TrimRule& policy) {
    if (s.wantWeights) {
        // Weights wanted (AOVs): the general path, which keeps its ranking in s.order. It gives
        // the fast path's bits (tests/filters/pixel/test_bit_identity.cpp), so the beauty does not
        // change with AOVs present; the AOVs cost one weighted sum each, not a ranking.
        s.bufferWeight.clear();
        if (policy.trim == nullptr) {
            meanOnePass(px, out);
            if (out.kept[0] == 0) {
                s.bufferWeight.assign(size_t(px.M), 0.0);
                return;
            }
            int excluded = 0;
            const int Mv = collectValidBuffers(px, s.order, excluded);
            rankWeights(px, s, 0, Mv);
            return;
        }
        reduceGeneral(px, p, out, s, policy);
        if (p.mode == EstimatorMode::Luminance && s.bufferWeight.empty())
            s.bufferWeight.assign(size_t(px.M), 0.0);  // no valid buffer: black, no weight
        if (p.mode != EstimatorMode::Luminance) s.bufferWeight.clear();
        return;
    }
    if (policy.trim == nullptr) return meanOnePass(px, out);
    if (px.M <= kSmallM && reduceSmall(px, p, out, s, policy)) return;
    reduceGeneral(px, p, out, s, policy);
}

}  // namespace

int plainMeanPass(const PixelBuffers& px, PixelEstimate& out, std::vector<int>& valid, double& n,
                  double sum[3]) {
    valid.resize(size_t(px.M));
    double sums[4];
    const int m = meanPasses<true>(px, out, valid.data(), sums);
    valid.resize(size_t(m));
    n = sums[0];
    sum[0] = sums[1];
    sum[1] = sums[2];
    sum[2] = sums[3];
    return m;
}

namespace detail {
void rankKeys(double* key, int n, int* order) {
    if (useAvx2()) {
        double sorted[kSmallM];
        for (int i = n; i < ((n + 7) & ~7); ++i) key[i] = std::numeric_limits<double>::infinity();
        if (!rankFloatAvx2(key, n, order, sorted)) rankAvx2(key, n, order, sorted);
        return;
    }
    int rank[kSmallM];
    rankScalar(key, n, rank);
    for (int i = 0; i < n; ++i) order[rank[i]] = i;
}

bool setUseAvx2(bool on) {
    const bool before = useAvx2();
    useAvx2() = on && cpuHasAvx2();
    return before;
}

bool usesAvx2() { return useAvx2(); }
}  // namespace detail

void rankedTrimmedMean(const PixelBuffers& px, const PixelParams& p, const TrimRule& rule,
                       PixelEstimate& out, EstimatorScratch& s) {
    reduce(px, p, out, s, rule);
}

}  // namespace mcstat
