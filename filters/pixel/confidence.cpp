// Confidence intervals per pixel (confidence.h); the statistics are core's
// (core/location_stats.h), shared with --compare's tests (analysis/two_sample.cpp).
#include "mcstat/filters/pixel/confidence.h"

#include <immintrin.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

#include "mcstat/core/cpu_features.h"
#include "mcstat/core/location_stats.h"
#include "mcstat/filters/pixel/detail/rank_keys.h"
#include "mcstat/filters/pixel/ranking.h"
#include "mean_pass.h"

namespace mcstat {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// No value: NaN. One value: anything is possible.
bool degenerate(int m, ValueInterval& out) {
    if (m <= 0) {
        out = {kNaN, kNaN, true};
        return true;
    }
    if (m == 1) {
        out = {-kInf, kInf, true};
        return true;
    }
    return false;
}

/// degenerate() for R, G and B at once.
bool degenerateAll(int m, ValueInterval out[3]) {
    ValueInterval d;
    if (!degenerate(m, d)) return false;
    out[0] = out[1] = out[2] = d;
    return true;
}

/// f(level, n) remembered: Boost's t inverse and the binomial sums take microseconds, and an image
/// asks for the same few (level, n) pixel after pixel. A few entries per thread, replaced in turn.
template <class F>
double remembered(double level, double n, F f) {
    struct Entry {
        double level = -1.0, n = -1.0, value = 0.0;
    };
    thread_local Entry cache[8];
    thread_local unsigned next = 0;
    for (const Entry& e : cache)
        if (e.level == level && e.n == n) return e.value;
    Entry& e = cache[next++ % 8];
    e = {level, n, f()};
    return e.value;
}

/// t_{1 - (1 - level) / 2, df}.
double twoSidedQuantile(double level, double df) {
    return remembered(level, df, [&] { return studentQuantile(0.5 + 0.5 * level, df); });
}

/// medianIntervalRank(m, level) remembered; as a double key, a negative n keeps its entries apart
/// from the quantile's.
int rememberedMedianRank(int m, double level) {
    return int(remembered(level, -double(m), [&] { return double(medianIntervalRank(m, level)); }));
}

/// estimate +- q sqrt(variance), q = twoSidedQuantile(level, df).
ValueInterval tIntervalWith(const LocationSummary& s, double q) {
    const double half = q * std::sqrt(s.variance);
    // variance 0 (all equal): zero width, not 0 * quantile's rounding.
    if (s.variance == 0.0) return {s.estimate, s.estimate, false};
    return {s.estimate - half, s.estimate + half, false};
}

/// estimate +- t_{1 - (1 - level) / 2, df} sqrt(variance).
ValueInterval tInterval(const LocationSummary& s, double level) {
    return tIntervalWith(s, twoSidedQuantile(level, s.df));
}

}  // namespace

ValueInterval meanInterval(const double* values, const double* counts, int m, double level) {
    ValueInterval out;
    if (degenerate(m, out)) return out;
    return tInterval(weightedMeanSummary(values, counts, m), level);
}

ValueInterval spreadInterval(double mean, double perSampleVariance, double samples, int buffers,
                             double level) {
    if (!std::isfinite(mean)) return {kNaN, kNaN, true};
    if (buffers < 2 || !(samples > 0.0) || !(perSampleVariance >= 0.0) ||
        !std::isfinite(perSampleVariance))
        return {-kInf, kInf, true};
    LocationSummary s;
    s.estimate = mean;
    s.variance = perSampleVariance / samples;
    s.df = double(buffers - 1);
    return tInterval(s, level);
}

ValueInterval expectedInterval(double mean, double s2, double pooledS2, double samples, int buffers,
                               double level) {
    const double own = std::isfinite(s2) && s2 >= 0.0 ? s2 : kNaN;
    const double pooled = std::isfinite(pooledS2) && pooledS2 >= 0.0 ? pooledS2 : kNaN;
    const double v = std::isnan(own) ? pooled : std::isnan(pooled) ? own : std::max(own, pooled);
    return spreadInterval(mean, v, samples, buffers, level);
}

ValueInterval medianInterval(double* values, int m, double level) {
    ValueInterval out;
    if (degenerate(m, out)) return out;
    std::sort(values, values + m);
    const int k = rememberedMedianRank(m, level);
    if (k == 0) return {values[0], values[m - 1], true};  // the range: coverage 1 - 2^(1-m)
    return {values[k - 1], values[m - k], false};
}

ValueInterval yuenInterval(double* values, int m, int g, double level) {
    ValueInterval out;
    if (degenerate(m, out)) return out;
    std::sort(values, values + m);
    const LocationSummary s = yuenSummary(values, m, g);
    if (s.df < 1.0) return medianInterval(values, m, level);
    return tInterval(s, level);
}

// ---- R, G and B of one pixel at once ------------------------------------------------------------

namespace {

/// Largest m the sorting network takes (its lanes live on the stack); above it, the per-channel
/// functions.
constexpr int kNetworkMax = 64;

/// Batcher's odd-even merge sort for the power of two N >= n, keeping the comparators whose two
/// ends are below n, in order; `emit(i, j)` gets each comparator (i < j). Why pruning is exact:
/// pad the n values with +inf at positions n..N-1; a comparator (i, j) with j >= n leaves a
/// finite v_i where it is (min(v_i, +inf) = v_i) and one between two paddings swaps equal values,
/// so the padding never moves and those comparators are no-ops.
template <class Emit>
constexpr void batcherNetwork(int n, Emit&& emit) {
    int N = 1;
    while (N < n) N <<= 1;
    for (int p = 1; p < N; p <<= 1)
        for (int k = p; k >= 1; k >>= 1)
            for (int j = k % p; j + k < N; j += 2 * k)
                for (int i = 0; i < std::min(k, N - j - k); ++i)
                    if ((i + j) / (2 * p) == (i + j + k) / (2 * p) && i + j + k < n)
                        emit(i + j, i + j + k);
}

/// The comparators of batcherNetwork(m), as byte offsets of four-float lanes, built once per m.
const std::vector<std::pair<uint16_t, uint16_t>>& sortingNetwork(int m) {
    static const std::array<std::vector<std::pair<uint16_t, uint16_t>>, kNetworkMax + 1> nets = [] {
        std::array<std::vector<std::pair<uint16_t, uint16_t>>, kNetworkMax + 1> all;
        for (int n = 2; n <= kNetworkMax; ++n)
            batcherNetwork(n, [&](int i, int j) {
                all[size_t(n)].emplace_back(uint16_t(16 * i), uint16_t(16 * j));
            });
        return all;
    }();
    return nets[size_t(m)];
}

/// Buffer j's R, G, B as lanes 0-2. Lane 3 is the next buffer's R (sorted along, never read),
/// except for the pixel's last buffer, whose 16 bytes could end past the data: 8 + 4 bytes there.
inline __m128 loadLane(const PixelBuffers& px, int j) {
    const float* p = px.mean + 3 * size_t(j);
    if (j + 1 < px.M) return _mm_loadu_ps(p);
    return _mm_movelh_ps(_mm_castpd_ps(_mm_load_sd(reinterpret_cast<const double*>(p))),
                         _mm_load_ss(p + 2));
}

/// Up to this m the network is unrolled at compile time: the lanes stay in registers (a loop over
/// the comparator list loads and stores both lanes of every comparator, three times the work).
constexpr int kUnrolledMax = 32;

template <int M>
struct UnrolledNetwork {
    static constexpr int size() {
        int c = 0;
        batcherNetwork(M, [&](int, int) { ++c; });
        return c;
    }
    static constexpr std::array<std::array<uint8_t, 2>, size_t(size())> pairs() {
        std::array<std::array<uint8_t, 2>, size_t(size())> out{};
        int c = 0;
        batcherNetwork(M, [&](int i, int j) {
            out[size_t(c)][0] = uint8_t(i);
            out[size_t(c)][1] = uint8_t(j);
            ++c;
        });
        return out;
    }
    static constexpr auto kPairs = pairs();
    template <size_t... I>
    static void run(__m128* v, std::index_sequence<I...>) {
        (compareExchange(v[kPairs[I][0]], v[kPairs[I][1]]), ...);
    }
    static void compareExchange(__m128& a, __m128& b) {
        const __m128 lo = _mm_min_ps(a, b);
        b = _mm_max_ps(a, b);
        a = lo;
    }
    static void sort(const PixelBuffers& px, const int* valid, float (*lanes)[4]) {
        __m128 v[M];
        for (int i = 0; i < M; ++i) v[i] = loadLane(px, valid[i]);
        run(v, std::make_index_sequence<size_t(size())>{});
        for (int i = 0; i < M; ++i) _mm_store_ps(lanes[i], v[i]);
    }
};

template <int... M>
void sortUnrolled(int m, const PixelBuffers& px, const int* valid, float (*lanes)[4],
                  std::integer_sequence<int, M...>) {
    using Fn = void (*)(const PixelBuffers&, const int*, float(*)[4]);
    static constexpr Fn fns[] = {&UnrolledNetwork<M + 2>::sort...};
    fns[m - 2](px, valid, lanes);
}

/// UnrolledNetwork<M> on two pixels at once: pixel a's lanes in the low half of eight-float AVX
/// registers, pixel b's in the high half, the same comparators (min and max per lane, so each half
/// gets the four-float network's values).
// The sanitizers' checks are left out of these functions: they hold no memory access of their own
// but the loads loadLane makes (checked on the four-float path, which reads the same bytes), and
// instrumenting 31 unrolled networks of up to 191 comparators tripled the file's compile time
// under ASan + UBSan (12 s to 37 s).
#define MCSTAT_NETWORK2 __attribute__((target("avx"), no_sanitize("address", "undefined")))

template <int M>
struct UnrolledNetwork2 {
    MCSTAT_NETWORK2 static void compareExchange(__m256& a, __m256& b) {
        const __m256 lo = _mm256_min_ps(a, b);
        b = _mm256_max_ps(a, b);
        a = lo;
    }
    template <size_t... I>
    MCSTAT_NETWORK2 static void run(__m256* v, std::index_sequence<I...>) {
        constexpr auto& pairs = UnrolledNetwork<M>::kPairs;
        (compareExchange(v[pairs[I][0]], v[pairs[I][1]]), ...);
    }
    /// Every buffer of a and b (both of M buffers, all valid) sorted into la and lb.
    MCSTAT_NETWORK2 static void sort(const PixelBuffers& a, const PixelBuffers& b, float (*la)[4],
                                     float (*lb)[4]) {
        __m256 v[M];
        for (int i = 0; i < M; ++i) v[i] = _mm256_set_m128(loadLane(b, i), loadLane(a, i));
        run(v, std::make_index_sequence<size_t(UnrolledNetwork<M>::size())>{});
        for (int i = 0; i < M; ++i) {
            _mm_store_ps(la[i], _mm256_castps256_ps128(v[i]));
            _mm_store_ps(lb[i], _mm256_extractf128_ps(v[i], 1));
        }
    }
};

#undef MCSTAT_NETWORK2

template <int... M>
void sortUnrolled2(int m, const PixelBuffers& a, const PixelBuffers& b, float (*la)[4],
                   float (*lb)[4], std::integer_sequence<int, M...>) {
    using Fn = void (*)(const PixelBuffers&, const PixelBuffers&, float(*)[4], float(*)[4]);
    static constexpr Fn fns[] = {&UnrolledNetwork2<M + 2>::sort...};
    fns[m - 2](a, b, la, lb);
}

/// The valid buffers' R, G, B (and a zero) as four-float lanes, sorted lane by lane: lane c of
/// v[r] is the r-th smallest of channel c. Values are the buffers' floats (the per-channel path
/// sorts the same values widened to double, which orders them the same way).
struct SortedLanes {
    alignas(16) float v[kNetworkMax][4];
    void load(const PixelBuffers& px, const int* valid, int m) {
        if (m >= 2 && m <= kUnrolledMax)
            return sortUnrolled(m, px, valid, v,
                                std::make_integer_sequence<int, kUnrolledMax - 1>{});
        for (int i = 0; i < m; ++i) _mm_store_ps(v[i], loadLane(px, valid[i]));
        char* base = reinterpret_cast<char*>(v);
        for (const auto& [a, b] : sortingNetwork(m)) {
            float* pa = reinterpret_cast<float*>(base + a);
            float* pb = reinterpret_cast<float*>(base + b);
            const __m128 x = _mm_load_ps(pa), y = _mm_load_ps(pb);
            _mm_store_ps(pa, _mm_min_ps(x, y));
            _mm_store_ps(pb, _mm_max_ps(x, y));
        }
    }
    double at(int rank, int c) const { return double(v[rank][c]); }
};

/// The median's interval of each channel from a pixel's sorted lanes: ranks k - 1 and m - k (all
/// of them when k is 0: rememberedMedianRank).
void medianFromLanes(const float (*lanes)[4], int m, int k, ValueInterval out[3]) {
    for (int c = 0; c < 3; ++c)
        out[c] = k == 0 ? ValueInterval{double(lanes[0][c]), double(lanes[m - 1][c]), true}
                        : ValueInterval{double(lanes[k - 1][c]), double(lanes[m - k][c]), false};
}

/// Yuen's interval of each channel from its trimmed sum and the winsorised values' sum of squared
/// deviations (h the values kept inside the trim).
void yuenFromSums(int h, const double sum[3], const double ss[3], double level,
                  ValueInterval out[3]) {
    const double q = twoSidedQuantile(level, double(h - 1));
    for (int c = 0; c < 3; ++c) {
        LocationSummary ls;
        ls.estimate = sum[c] / h;
        ls.variance = ss[c] / (double(h) * (h - 1));
        ls.df = h - 1;
        out[c] = tIntervalWith(ls, q);
    }
}

/// Yuen's interval of each channel from a pixel's sorted lanes (m <= kNetworkMax, h = m - 2 g at
/// least 2): yuenSummary's sums, the three channels side by side (for each channel the same
/// additions in the same order): the winsorised values once, as doubles; the trimmed sum and the
/// winsorised sum are independent chains, so they share a loop.
void yuenFromLanes(const float (*lanes)[4], int m, int g, double level, ValueInterval out[3]) {
    const int h = m - 2 * g;
    double w[3][kNetworkMax];
    for (int j = 0; j < m; ++j) {
        const int r = std::clamp(j, g, m - g - 1);
        for (int c = 0; c < 3; ++c) w[c][j] = double(lanes[r][c]);
    }
    double sum[3] = {0.0, 0.0, 0.0}, wsum[3] = {0.0, 0.0, 0.0};
    for (int j = 0; j < g; ++j)
        for (int c = 0; c < 3; ++c) wsum[c] += w[c][j];
    for (int j = g; j < m - g; ++j)
        for (int c = 0; c < 3; ++c) {
            sum[c] += w[c][j];  // inside the trim the winsorised value is the value
            wsum[c] += w[c][j];
        }
    for (int j = m - g; j < m; ++j)
        for (int c = 0; c < 3; ++c) wsum[c] += w[c][j];
    double wmean[3], ss[3] = {0.0, 0.0, 0.0};
    for (int c = 0; c < 3; ++c) wmean[c] = wsum[c] / m;
    for (int j = 0; j < m; ++j)
        for (int c = 0; c < 3; ++c) {
            const double dv = w[c][j] - wmean[c];
            ss[c] += dv * dv;
        }
    yuenFromSums(h, sum, ss, level, out);
}

/// A sorted lane's four floats widened to doubles.
__attribute__((target("avx"))) inline __m256d widenedLane(const float (*lanes)[4], int r) {
    return _mm256_cvtps_pd(_mm_load_ps(lanes[r]));
}

/// tIntervalWith of R, G and B at once, their estimates and variances the first three lanes of AVX
/// registers (the fourth is never read): half = q sqrt(variance), [x - half, x + half], variance 0:
/// [x, x]. Correctly rounded in any width, so the portable code's bits. Always inlined: a call
/// that takes AVX registers leaves their upper halves set for the portable caller (see
/// meanRunAvx2's _mm256_zeroupper).
[[gnu::always_inline]] __attribute__((target("avx"))) inline void tIntervalsAvx(
    __m256d estimate, __m256d variance, double q, ValueInterval out[3]) {
    const __m256d half = _mm256_mul_pd(_mm256_set1_pd(q), _mm256_sqrt_pd(variance));
    const __m256d zero = _mm256_cmp_pd(variance, _mm256_setzero_pd(), _CMP_EQ_OQ);
    alignas(32) double lo[4], hi[4];
    _mm256_store_pd(lo, _mm256_blendv_pd(_mm256_sub_pd(estimate, half), estimate, zero));
    _mm256_store_pd(hi, _mm256_blendv_pd(_mm256_add_pd(estimate, half), estimate, zero));
    for (int c = 0; c < 3; ++c) out[c] = {lo[c], hi[c], false};
}

/// yuenFromSums of a pixel whose R, G, B sums are the first three lanes of AVX registers (`sum`
/// the trimmed sum, `ss` the winsorised squared deviations): each lane's operations are the
/// portable code's (the estimate sum / h, the variance ss / (h (h - 1)), then tIntervalWith's),
/// so the same bits, with a third of the divisions and square roots.
[[gnu::always_inline]] __attribute__((target("avx"))) inline void yuenEndsAvx(
    int h, double q, __m256d sum, __m256d ss, ValueInterval out[3]) {
    tIntervalsAvx(_mm256_div_pd(sum, _mm256_set1_pd(double(h))),
                  _mm256_div_pd(ss, _mm256_set1_pd(double(h) * (h - 1))), q, out);
}

/// yuenFromLanes on two pixels of equal m and g at once, each pixel's R, G, B (and a lane never
/// read) the four lanes of AVX double registers: for each channel the same operations in the same
/// order (additions, one division, subtractions, products; no FMA), so the same bits. The two
/// pixels' chains of dependent additions are independent and overlap.
__attribute__((target("avx"))) void yuenFromLanes2(const float (*la)[4], const float (*lb)[4],
                                                   int m, int g, double level, ValueInterval oa[3],
                                                   ValueInterval ob[3]) {
    const int h = m - 2 * g;
    __m256d sa = _mm256_setzero_pd(), sb = sa, wa = sa, wb = sa;
    const __m256d loA = widenedLane(la, g), loB = widenedLane(lb, g);
    const __m256d hiA = widenedLane(la, m - g - 1), hiB = widenedLane(lb, m - g - 1);
    for (int j = 0; j < g; ++j) wa = _mm256_add_pd(wa, loA), wb = _mm256_add_pd(wb, loB);
    for (int j = g; j < m - g; ++j) {
        const __m256d xa = widenedLane(la, j), xb = widenedLane(lb, j);
        sa = _mm256_add_pd(sa, xa), wa = _mm256_add_pd(wa, xa);
        sb = _mm256_add_pd(sb, xb), wb = _mm256_add_pd(wb, xb);
    }
    for (int j = m - g; j < m; ++j) wa = _mm256_add_pd(wa, hiA), wb = _mm256_add_pd(wb, hiB);
    const __m256d n = _mm256_set1_pd(double(m));
    const __m256d meanA = _mm256_div_pd(wa, n), meanB = _mm256_div_pd(wb, n);
    __m256d qa = _mm256_setzero_pd(), qb = qa;
    for (int j = 0; j < m; ++j) {
        const int r = std::clamp(j, g, m - g - 1);
        const __m256d da = _mm256_sub_pd(widenedLane(la, r), meanA),
                      db = _mm256_sub_pd(widenedLane(lb, r), meanB);
        qa = _mm256_add_pd(qa, _mm256_mul_pd(da, da));
        qb = _mm256_add_pd(qb, _mm256_mul_pd(db, db));
    }
    const double q = twoSidedQuantile(level, double(h - 1));
    yuenEndsAvx(h, q, sa, qa, oa);
    yuenEndsAvx(h, q, sb, qb, ob);
}

/// One channel's values of the valid buffers, widened to double (the per-channel path's input).
void gatherChannel(const PixelBuffers& px, const int* valid, int m, int c, double* out) {
    for (int i = 0; i < m; ++i) out[i] = double(px.mean[3 * size_t(valid[i]) + size_t(c)]);
}

}  // namespace

void meanIntervals(const PixelBuffers& px, const int* valid, int m, double level,
                   ValueInterval out[3]) {
    // weightedMeanSummary's two passes, the three channels side by side: for each channel the
    // same additions in the same order.
    double n = 0.0, sum[3] = {0.0, 0.0, 0.0};
    for (int j = 0; j < m; ++j) {
        const double w = px.count[valid[j]];
        const float* v = px.mean + 3 * size_t(valid[j]);
        n += w;
        for (int c = 0; c < 3; ++c) sum[c] += w * double(v[c]);
    }
    meanIntervalsFromSums(px, valid, m, n, sum, level, out);
}

namespace {

/// A pixel's mean interval from its means and its sums of squares in the lanes of AVX registers
/// (R, G, B and a lane never read): the variance ss / df / n, then tIntervalsAvx. Each lane's
/// operations are the portable code's, in the same order, correctly rounded in any width, no FMA:
/// the same bits, with a third of the divisions and square roots.
__attribute__((target("avx2"))) void meanIntervalEndsAvx2(int m, double n, __m256d mean, __m256d ss,
                                                          double level, ValueInterval* out) {
    if (degenerateAll(m, out)) return;
    const double df = m - 1;
    const double q = twoSidedQuantile(level, df);
    tIntervalsAvx(mean, _mm256_div_pd(_mm256_div_pd(ss, _mm256_set1_pd(df)), _mm256_set1_pd(n)), q,
                  out);
}

/// meanIntervalsFromSums on AVX2: a pixel's R, G, B (and a lane that stays 0) in the lanes of one
/// register through every step, the means, the sums of squares (w dv) dv, and the ends
/// (meanIntervalEndsAvx2). The same bits.
__attribute__((target("avx2"))) void meanIntervalsFromSumsAvx2(const PixelBuffers& px,
                                                               const int* valid, int m, double n,
                                                               const double sum[3], double level,
                                                               ValueInterval out[3]) {
    const __m256d mean =
        _mm256_div_pd(_mm256_setr_pd(sum[0], sum[1], sum[2], 0.0), _mm256_set1_pd(n));
    __m256d ss = _mm256_setzero_pd();
    for (int j = 0; j < m; ++j) {
        // (R, G, B, 0): a zero count in the fourth lane, which is never read.
        const __m256d x = _mm256_cvtps_pd(detail::bufferLanes(px.mean + 3 * size_t(valid[j]), 0.f));
        const __m256d dv = _mm256_sub_pd(x, mean);
        const __m256d w = _mm256_set1_pd(double(px.count[valid[j]]));
        ss = _mm256_add_pd(ss, _mm256_mul_pd(_mm256_mul_pd(w, dv), dv));
    }
    meanIntervalEndsAvx2(m, n, mean, ss, level, out);
}

/// The plain mean's estimate and interval of K pixels of equal M (at most kWidenedMax) on AVX2,
/// side by side so that the pixels' chains of dependent additions overlap: meanPassAvx2 keeps
/// each valid buffer widened to double, so the interval's second pass reads them from the stack
/// with no index; then as meanIntervalsFromSumsAvx2. The same bits as plainMeanPass and
/// meanIntervalsFromSums.
constexpr int kWidenedMax = 64;
template <int K>
__attribute__((target("avx2"))) void meanRunAvx2(const PixelBuffers* px, double level,
                                                 PixelEstimate* e, ValueInterval* out) {
    alignas(32) double widened[K][4 * kWidenedMax];
    double* keep[K];
    for (int k = 0; k < K; ++k) keep[k] = widened[k];
    double sums[K][4];
    int m[K];
    __m256d mean[K], ss[K];
    for (int k = 0; k < K; ++k) mean[k] = ss[k] = _mm256_setzero_pd();
    // The estimate's divisions are the interval's means (lanes s_c / w: the portable code's).
    detail::meanPassAvx2<detail::MeanPassKeeps::Widened, K>(px, e, nullptr, sums, m, keep, mean);
    int most = 0;
    for (int k = 0; k < K; ++k) most = std::max(most, m[k]);
    most = std::min(most, kWidenedMax);  // m[k] <= px[k].M <= kWidenedMax: tells the compiler
    for (int j = 0; j < most; ++j)
        for (int k = 0; k < K; ++k) {
            if (j >= m[k]) continue;
            // (m0, m1, m2, n): the fourth lane's sums are never read.
            const __m256d x = _mm256_load_pd(widened[k] + 4 * j);
            const __m256d dv = _mm256_sub_pd(x, mean[k]);
            const __m256d w = _mm256_permute4x64_pd(x, 0xff);
            ss[k] = _mm256_add_pd(ss[k], _mm256_mul_pd(_mm256_mul_pd(w, dv), dv));
        }
    for (int k = 0; k < K; ++k)
        meanIntervalEndsAvx2(m[k], sums[k][0], mean[k], ss[k], level, out + 3 * k);
    // meanIntervalEndsAvx2 takes AVX registers, so the compiler neither clears their upper halves
    // when it returns nor here, where it became the tail call: cleared before the portable
    // caller's SSE code, each instruction of which otherwise waited on them (the mean's :ci took
    // 174 ms against 99 ms with this line, the estimate alone 54 ms).
    _mm256_zeroupper();
}

}  // namespace

void meanIntervalsFromSums(const PixelBuffers& px, const int* valid, int m, double n,
                           const double sum[3], double level, ValueInterval out[3]) {
    if (detail::usesAvx2()) return meanIntervalsFromSumsAvx2(px, valid, m, n, sum, level, out);
    if (degenerateAll(m, out)) return;
    double est[3], ss[3] = {0.0, 0.0, 0.0};
    for (int c = 0; c < 3; ++c) est[c] = sum[c] / n;
    for (int j = 0; j < m; ++j) {
        const double w = px.count[valid[j]];
        const float* v = px.mean + 3 * size_t(valid[j]);
        for (int c = 0; c < 3; ++c) {
            const double dv = double(v[c]) - est[c];
            ss[c] += w * dv * dv;
        }
    }
    const double q = twoSidedQuantile(level, double(m - 1));
    for (int c = 0; c < 3; ++c) {
        LocationSummary s;
        s.estimate = est[c];
        s.df = m - 1;
        s.variance = ss[c] / s.df / n;
        out[c] = tIntervalWith(s, q);
    }
}

void meanEstimatesWithIntervals(const PixelBuffers* px, int n, double level, PixelEstimate* e,
                                ValueInterval* out) {
    const bool avx2 = detail::usesAvx2();
    std::vector<int> valid;
    int asked = kPrefetchPixels;  // pixels whose buffers were asked for
    for (int i = 0; i < n;) {
        ValueInterval* rgb = out + 3 * size_t(i);
        // The buffers a few pixels on, while these are summed (pixel_buffers.h).
        for (; asked < std::min(n, i + kPrefetchPixels + 4); ++asked) prefetchBuffers(px[asked]);
        if (avx2 && px[i].M <= kWidenedMax) {
            if (i + 3 < n && px[i].M == px[i + 1].M && px[i].M == px[i + 2].M &&
                px[i].M == px[i + 3].M) {
                meanRunAvx2<4>(px + i, level, e + i, rgb);
                i += 4;
            } else if (i + 1 < n && px[i].M == px[i + 1].M) {
                meanRunAvx2<2>(px + i, level, e + i, rgb);
                i += 2;
            } else {
                meanRunAvx2<1>(px + i, level, e + i, rgb);
                ++i;
            }
            continue;
        }
        double w, sum[3];
        const int m = plainMeanPass(px[i], e[i], valid, w, sum);
        meanIntervalsFromSums(px[i], valid.data(), m, w, sum, level, rgb);
        ++i;
    }
}

void medianIntervals(const PixelBuffers& px, const int* valid, int m, double level,
                     ValueInterval out[3]) {
    if (degenerateAll(m, out)) return;
    if (m > kNetworkMax) {
        std::vector<double> values(static_cast<size_t>(m));
        for (int c = 0; c < 3; ++c) {
            gatherChannel(px, valid, m, c, values.data());
            out[c] = medianInterval(values.data(), m, level);
        }
        return;
    }
    const int k = rememberedMedianRank(m, level);
    SortedLanes s;
    s.load(px, valid, m);
    medianFromLanes(s.v, m, k, out);
}

void medianIntervalsRun(const PixelBuffers* px, int n, double level, ValueInterval* out) {
    const bool avx = cpuHasAvx();
    std::vector<int> all;  // 0, 1, ..., M - 1: every buffer valid
    int i = 0;
    while (i < n) {
        const int m = px[i].M;
        if (avx && i + 1 < n && px[i + 1].M == m && m >= 2 && m <= kUnrolledMax) {
            alignas(16) float la[kUnrolledMax][4], lb[kUnrolledMax][4];
            sortUnrolled2(m, px[i], px[i + 1], la, lb,
                          std::make_integer_sequence<int, kUnrolledMax - 1>{});
            const int k = rememberedMedianRank(m, level);
            medianFromLanes(la, m, k, out + 3 * i);
            medianFromLanes(lb, m, k, out + 3 * (i + 1));
            i += 2;
            continue;
        }
        for (int j = int(all.size()); j < m; ++j) all.push_back(j);
        medianIntervals(px[i], all.data(), m, level, out + 3 * i);
        ++i;
    }
}

void yuenIntervals(const PixelBuffers& px, const int* valid, int m, int g, double level,
                   ValueInterval out[3]) {
    if (degenerateAll(m, out)) return;
    g = std::clamp(g, 0, (m - 1) / 2);
    const int h = m - 2 * g;
    if (m > kNetworkMax || h < 2) {  // h < 2: the median's interval (yuenInterval)
        std::vector<double> values(static_cast<size_t>(m));
        for (int c = 0; c < 3; ++c) {
            gatherChannel(px, valid, m, c, values.data());
            out[c] = yuenInterval(values.data(), m, g, level);
        }
        return;
    }
    SortedLanes s;
    s.load(px, valid, m);
    yuenFromLanes(s.v, m, g, level, out);
}

void yuenIntervalsRun(const PixelBuffers* px, int n, const std::function<int(int)>& trim,
                      double level, ValueInterval* out) {
    const bool avx = cpuHasAvx();
    std::vector<int> all;             // 0, 1, ..., M - 1: every buffer valid
    int i = 0, trimmedM = -1, g = 0;  // the trim g of the last m asked (a run's M rarely changes)
    while (i < n) {
        const int m = px[i].M;
        if (m != trimmedM) {
            g = m >= 2 ? std::clamp(trim(m), 0, (m - 1) / 2) : 0;
            trimmedM = m;
        }
        if (avx && i + 1 < n && px[i + 1].M == m && m >= 2 && m <= kUnrolledMax && m - 2 * g >= 2) {
            alignas(16) float la[kUnrolledMax][4], lb[kUnrolledMax][4];
            sortUnrolled2(m, px[i], px[i + 1], la, lb,
                          std::make_integer_sequence<int, kUnrolledMax - 1>{});
            yuenFromLanes2(la, lb, m, g, level, out + 3 * i, out + 3 * (i + 1));
            i += 2;
            continue;
        }
        for (int j = int(all.size()); j < m; ++j) all.push_back(j);
        yuenIntervals(px[i], all.data(), m, g, level, out + 3 * i);
        ++i;
    }
}

}  // namespace mcstat
