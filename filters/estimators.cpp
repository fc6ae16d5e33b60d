// Median of means, Gini coefficient, G-MoN and G-MoN_b over one pixel's sub-buffers, and Jung's
// trimmed mean TMPE (thesis eq. 5.1, ../shared/papers/jung2016-thesis-robust-pixel-estimation.txt).
// Paper: ../shared/papers/buisine2021-gmon-median-of-means.txt (equations cited inline).
// The shared rules (valid buffers, weights, negatives, empty pixels) are in
// include/mcstat/estimators.h.
#include "mcstat/estimators.h"

#include <algorithm>
#include <cmath>
#include <limits>

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

int gmonTrim(double G, int M) {
    if (M < 2) return 0;
    // Section 4.3: c = floor(k - (1 - G) k), k = floor(M / 2).
    const int k = M / 2;
    int c = int(std::floor(double(k) - (1.0 - G) * double(k)));
    // Keep at least the median mean (odd M) or the two middle means (even M): c = k with even M
    // would leave M - 2c = 0 means in eq. 6.
    return std::clamp(c, 0, (M - 1) / 2);
}

int tmpeTrim(double alpha, int M) {
    if (M < 2 || !(alpha > 0.0)) return 0;
    // Jung eq. 5.1 sums ranks 1 + alpha*m .. m - alpha*m: alpha*m means are dropped per side. alpha
    // is meant to be i/m; floor(alpha*M + 1e-9) maps any alpha to an integer count, and the 1e-9
    // keeps alpha = i/M (rounded in binary) from becoming i - 1.
    const double c = std::floor(std::min(alpha, 1.0) * double(M) + 1e-9);
    return std::clamp(int(c), 0, (M - 1) / 2);
}

int collectValidBuffers(const PixelBuffers& px, std::vector<int>& order, int& excluded) {
    order.clear();
    excluded = 0;
    for (int j = 0; j < px.M; ++j) {
        const float n = px.count[j];
        const float* m = px.mean + 3 * j;
        if (!std::isfinite(n) || n < 0.f || !std::isfinite(m[0]) || !std::isfinite(m[1]) ||
            !std::isfinite(m[2])) {
            ++excluded;
            continue;
        }
        if (n == 0.f) continue;  // empty buffer (spp < M): no information, not an error
        order.push_back(j);
    }
    return int(order.size());
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

/// gmonTrim for G in [0, 1] (giniSorted's range): there k - (1 - G) k >= 0 (1 - G <= 1 and the
/// product rounds monotonically), so the conversion to int truncates exactly as floor would, and
/// the call to floor (not inlined without SSE4.1) is saved. Same value as gmonTrim.
int gmonTrimUnit(double G, int M) {
    if (M < 2) return 0;
    const int k = M / 2;
    const int c = int(double(k) - (1.0 - G) * double(k));
    return std::clamp(c, 0, (M - 1) / 2);
}

/// Which trimming policy an estimator applies once G is known.
enum class Policy { Mean, MoN, GMoN, GMoNb, TMPE };

int trimFor(Policy policy, double G, int Mv, const EstimatorParams& p) {
    const int cMax = (Mv - 1) / 2;  // the median (odd) or the two middle means (even)
    switch (policy) {
        case Policy::Mean:
            return 0;
        case Policy::MoN:
            return cMax;  // eq. 2
        case Policy::GMoN:
            return gmonTrimUnit(G, Mv);  // eq. 6
        case Policy::GMoNb:
            return G <= p.giniThreshold ? 0 : cMax;  // eq. 5
        case Policy::TMPE:
            return tmpeTrim(p.alpha, Mv);  // Jung eq. 5.1
    }
    return 0;
}

/// Shared body: every estimator here is "rank the valid means, trim c from each side, average the
/// rest with counts as weights", differing only in how c is chosen. This is the general version
/// (any M, vectors in the scratch); reduceSmall below is the fast path for M <= kSmallM and gives
/// the same bits.
void reduceGeneral(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                   EstimatorScratch& s, Policy policy) {
    out = PixelEstimate{};
    const int Mv = collectValid(px, s, out.excluded);
    if (Mv == 0) return;  // no sample: black, kept = 0
    const bool needGini = policy == Policy::GMoN || policy == Policy::GMoNb;
    s.key.resize(size_t(px.M));
    s.sorted.resize(size_t(Mv));

    if (policy == Policy::Mean) {
        weightedAverage(px, s, 0, Mv, 0, 3, out);
        out.kept = {Mv, Mv, Mv};
        return;
    }
    if (p.mode == EstimatorMode::Luminance) {
        for (int j : s.order) {
            const float* m = px.mean + 3 * j;
            s.key[j] = p.luma[0] * m[0] + p.luma[1] * m[1] + p.luma[2] * m[2];
        }
        sortByKey(s);
        double G = 0.0;
        if (needGini) {
            for (int r = 0; r < Mv; ++r) s.sorted[r] = s.key[s.order[r]];
            G = giniSorted(s.sorted.data(), size_t(Mv));
        }
        const int c = trimFor(policy, G, Mv, p);
        weightedAverage(px, s, c, Mv - c, 0, 3, out);
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
            G = giniSorted(s.sorted.data(), size_t(Mv));
        }
        const int c = trimFor(policy, G, Mv, p);
        weightedAverage(px, s, c, Mv - c, ch, ch + 1, out);
        out.gini[ch] = float(G);
        out.kept[ch] = Mv - 2 * c;
    }
}

// ---- fast path (issue 11): the same arithmetic on small fixed arrays ----------------------------
// Bit-identity with reduceGeneral (tests/estimators/test_bit_identity.cpp) rests on three facts:
// the valid buffers are the same ones in the same index order; the ranking is the same total order
// (key ascending, ties by buffer index), so every sum below adds the same doubles in the same
// order; and every formula (luminance, Gini via giniSorted, trim, weighted average) is the same
// expression in double. Only where the numbers live changed: stack arrays instead of vectors, and
// the luminance computed once per buffer.

/// Largest M the fast path takes (stack arrays); larger M goes to reduceGeneral.
constexpr int kSmallM = 64;

/// One pixel's valid buffers and their ranking, on the stack.
struct SmallPixel {
    int n = 0;               ///< M_v
    int idx[kSmallM];        ///< buffer index of the i-th valid buffer (index order)
    double count[kSmallM];   ///< its count
    double key[kSmallM];     ///< its key (luminance or one channel)
    int rank[kSmallM];       ///< its rank in (key, index) order
    int order[kSmallM];      ///< valid-buffer position by rank
    double sorted[kSmallM];  ///< key by rank
};

/// less[i] = #{j : key_j < key_i} for i < n; key holds n keys padded with +inf to a multiple of 8
/// (less of the padding is computed and ignored). Branch-free O(n^2) counting beats a comparison
/// sort at these sizes (no mispredicted branches) and vectorises: each key_j is compared with 8
/// key_i at once, the counts stay in registers. The AVX2 clone only compares, so the result does
/// not depend on the CPU.
__attribute__((target_clones("avx2", "default"))) void countLess(const double* key, int n,
                                                                 int padded, int* less) {
    for (int i0 = 0; i0 < padded; i0 += 8) {
        long long acc[8] = {};
        for (int j = 0; j < n; ++j) {
            const double kj = key[j];
            for (int t = 0; t < 8; ++t) acc[t] += kj < key[i0 + t];
        }
        for (int t = 0; t < 8; ++t) less[i0 + t] = int(acc[t]);
    }
}

/// Ranks sp.key in the order "key ascending, ties by buffer index" (sortByKey's order) and fills
/// sp.order / sp.sorted. Keys are never NaN here (checked by the caller), so the ranks are a
/// permutation of 0..n-1.
void rankSmall(SmallPixel& sp) {
    const int n = sp.n;
    const int padded = (n + 7) & ~7;
    for (int i = n; i < padded; ++i) sp.key[i] = std::numeric_limits<double>::infinity();
    countLess(sp.key, n, padded, sp.rank);
    // Without ties the "less" counts are the ranks and sum to n(n-1)/2; a tie gives the later
    // members of a group of equal keys too small a count, so the sum is smaller. Then add
    // #{j < i : key_j == key_i}: equal keys rank by index.
    long long sum = 0;
    for (int i = 0; i < n; ++i) sum += sp.rank[i];
    if (sum != (long long)n * (n - 1) / 2)
        for (int i = 1; i < n; ++i)
            for (int j = 0; j < i; ++j) sp.rank[i] += sp.key[j] == sp.key[i];
    for (int i = 0; i < n; ++i) {
        sp.order[sp.rank[i]] = i;
        sp.sorted[sp.rank[i]] = sp.key[i];
    }
}

// The channel loops below have a compile-time length NC (3 in luminance mode, 1 per channel) so
// that the accumulators live in registers: with a run-time range they went through the stack and
// every addition waited for a store-to-load forward.

/// weightedAverage over ranks [lo, hi) of sp.order, channels [c0, c0 + NC): the same sums in the
/// same order.
template <int NC>
void weightedAverageSmall(const PixelBuffers& px, const SmallPixel& sp, int lo, int hi, int c0,
                          PixelEstimate& out) {
    double sum[NC] = {}, w = 0.0;
    for (int r = lo; r < hi; ++r) {
        const int i = sp.order[r];
        const double n = sp.count[i];
        const float* m = px.mean + 3 * sp.idx[i] + c0;
        w += n;
        for (int c = 0; c < NC; ++c) sum[c] += n * double(m[c]);
    }
    for (int c = 0; c < NC; ++c) out.rgb[size_t(c0 + c)] = float(sum[c] / w);
}

/// giniSorted(sp.sorted, n) (same expression, same order) fused with the untrimmed weighted
/// average of channels [c0, c0 + NC) (weightedAverageSmall over all ranks). The two are
/// independent chains of additions, so running them in one loop overlaps their latencies; the
/// average is used when the trim turns out to be 0 (smooth pixels: G small), else recomputed.
template <int NC>
double giniWithFullAverage(const PixelBuffers& px, const SmallPixel& sp, int c0, float* rgb) {
    const int n = sp.n;
    const double* v = sp.sorted;
    const double shift = v[0] < 0.0 ? -v[0] : 0.0;
    double sum = 0.0, weighted = 0.0;
    double avg[NC] = {}, w = 0.0;
    const double nd = double(n);
    for (int j = 0; j < n; ++j) {
        const double x = v[j] + shift;
        sum += x;
        weighted += (2.0 * double(j + 1) - nd - 1.0) * x;
        const int i = sp.order[j];
        const double cnt = sp.count[i];
        const float* m = px.mean + 3 * sp.idx[i] + c0;
        w += cnt;
        for (int c = 0; c < NC; ++c) avg[c] += cnt * double(m[c]);
    }
    for (int c = 0; c < NC; ++c) rgb[c] = float(avg[c] / w);
    if (n < 2) return 0.0;
    if (!(sum > 0.0) || !std::isfinite(sum)) return 0.0;  // all zero: perfect equality
    const double G = weighted / (nd * sum);
    return std::clamp(G, 0.0, 1.0);
}

/// One pixel (luminance, NC = 3) or one channel (NC = 1): G if the policy needs it, the trim, the
/// average.
template <int NC>
void rankedReduce(const PixelBuffers& px, const EstimatorParams& p, SmallPixel& sp, Policy policy,
                  int c0, PixelEstimate& out, double& G, int& c) {
    const int Mv = sp.n;
    rankSmall(sp);
    if (policy == Policy::GMoN || policy == Policy::GMoNb) {
        float full[NC];
        G = giniWithFullAverage<NC>(px, sp, c0, full);
        c = trimFor(policy, G, Mv, p);
        if (c == 0) {
            for (int ch = 0; ch < NC; ++ch) out.rgb[size_t(c0 + ch)] = full[ch];
            return;
        }
    } else {
        G = 0.0;
        c = trimFor(policy, G, Mv, p);
    }
    weightedAverageSmall<NC>(px, sp, c, Mv - c, c0, out);
}

/// The fast path of reduceGeneral for px.M <= kSmallM and every policy but Mean (meanOnePass).
/// Returns false (nothing written) when a key
/// is NaN (only possible with non-finite luminance weights): the general path then decides.
bool reduceSmall(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                 Policy policy) {
    SmallPixel sp;
    int excluded = 0, n = 0;
    const bool lum = p.mode == EstimatorMode::Luminance;
    const double l0 = p.luma[0], l1 = p.luma[1], l2 = p.luma[2];
    bool nanKey = false;
    // collectValidBuffers' rules without branches: x - x is 0 for a finite float and NaN for
    // NaN/Inf, so `fin` is 0 exactly when the count and the three channels are finite. A buffer is
    // excluded when not finite or of negative count, skipped when its count is 0 (or -0).
    for (int j = 0; j < px.M; ++j) {
        const float cnt = px.count[j];
        const float* m = px.mean + 3 * j;
        const float fin = ((cnt - cnt) + (m[0] - m[0])) + ((m[1] - m[1]) + (m[2] - m[2]));
        const bool bad = (fin != 0.f) | (cnt < 0.f);  // NaN != 0; no short-circuit branches
        const bool take = !bad & (cnt != 0.f);
        excluded += bad;
        sp.idx[n] = j;
        sp.count[n] = cnt;
        if (lum) {
            const double k = l0 * m[0] + l1 * m[1] + l2 * m[2];
            nanKey |= take & (k != k);
            sp.key[n] = k;
        }
        n += take;
    }
    sp.n = n;
    if (nanKey) return false;
    out = PixelEstimate{};
    out.excluded = excluded;
    const int Mv = n;
    if (Mv == 0) return true;  // no sample: black, kept = 0

    double G;
    int c;
    if (lum) {
        rankedReduce<3>(px, p, sp, policy, 0, out, G, c);
        out.gini.fill(float(G));
        out.kept.fill(Mv - 2 * c);
        return true;
    }
    for (int ch = 0; ch < 3; ++ch) {
        for (int i = 0; i < Mv; ++i) sp.key[i] = px.mean[3 * sp.idx[i] + ch];
        rankedReduce<1>(px, p, sp, policy, ch, out, G, c);
        out.gini[ch] = float(G);
        out.kept[ch] = Mv - 2 * c;
    }
    return true;
}

/// The plain mean in one pass for any M: the valid buffers in index order, summed as they are
/// found (collectValidBuffers + weightedAverage over ranks [0, M_v) in index order: the same sums
/// in the same order), no keys, no arrays.
void meanOnePass(const PixelBuffers& px, PixelEstimate& out) {
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
        ++Mv;
    }
    out = PixelEstimate{};
    out.excluded = excluded;
    if (Mv == 0) return;
    out.rgb = {float(s0 / w), float(s1 / w), float(s2 / w)};
    out.kept = {Mv, Mv, Mv};
}

void reduce(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
            EstimatorScratch& s, Policy policy) {
    if (policy == Policy::Mean) return meanOnePass(px, out);
    if (px.M <= kSmallM && reduceSmall(px, p, out, policy)) return;
    reduceGeneral(px, p, out, s, policy);
}

}  // namespace

void estimateMean(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                  EstimatorScratch& s) {
    reduce(px, p, out, s, Policy::Mean);
}
void estimateMoN(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                 EstimatorScratch& s) {
    reduce(px, p, out, s, Policy::MoN);
}
void estimateGMoN(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                  EstimatorScratch& s) {
    reduce(px, p, out, s, Policy::GMoN);
}
void estimateGMoNb(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                   EstimatorScratch& s) {
    reduce(px, p, out, s, Policy::GMoNb);
}
void estimateTMPE(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                  EstimatorScratch& s) {
    reduce(px, p, out, s, Policy::TMPE);
}

}  // namespace mcstat
