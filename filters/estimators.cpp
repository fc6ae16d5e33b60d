// Median of means, Gini coefficient, G-MoN and G-MoN_b over one pixel's sub-buffers, and Jung's
// trimmed mean TMPE (thesis eq. 5.1, ../shared/papers/jung2016-thesis-robust-pixel-estimation.txt).
// Paper: ../shared/papers/buisine2021-gmon-median-of-means.txt (equations cited inline).
// The shared rules (valid buffers, weights, negatives, empty pixels) are in
// include/mcstat/estimators.h.
#include "mcstat/estimators.h"

#include <algorithm>
#include <cmath>

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
            return gmonTrim(G, Mv);  // eq. 6
        case Policy::GMoNb:
            return G <= p.giniThreshold ? 0 : cMax;  // eq. 5
        case Policy::TMPE:
            return tmpeTrim(p.alpha, Mv);  // Jung eq. 5.1
    }
    return 0;
}

/// Shared body: every estimator here is "rank the valid means, trim c from each side, average the
/// rest with counts as weights", differing only in how c is chosen.
void reduce(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
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
