// The straightforward implementation, kept as the oracle for bit-identity tests: the bodies of the
// rank estimators (now filters/pixel/ranking.cpp) and of myriad and meridian (now
// filters/pixel/myriad.cpp) copied verbatim (only the namespace changed) before they were
// rewritten for speed. See reference_estimators.h.
#include "reference_estimators.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

namespace mcstat::reference {

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
    std::vector<double> a(v, v + n);
    for (double& x : a) x = std::fabs(x);
    std::sort(a.begin(), a.end());
    return giniSorted(a.data(), n);
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
    return reference::collectValidBuffers(px, s.order, excluded);
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
            G = p.giniMagnitudes ? giniMagnitudes(s.sorted.data(), size_t(Mv))
                                 : giniSorted(s.sorted.data(), size_t(Mv));
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
            G = p.giniMagnitudes ? giniMagnitudes(s.sorted.data(), size_t(Mv))
                                 : giniSorted(s.sorted.data(), size_t(Mv));
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

namespace {  // jung

/// log1p(t^2) for t = |d| / scale >= 0, without overflow: for huge t it is 2 log t.
double logSquareTerm(double d, double scale) {
    const double ad = std::fabs(d);
    const double t = ad / scale;
    if (t < 1e150) return std::log1p(t * t);
    return 2.0 * (std::log(ad) - std::log(scale));
}

/// log1p(t) for t = |d| / scale, without overflow.
double logAbsTerm(double d, double scale) {
    const double ad = std::fabs(d);
    const double t = ad / scale;
    if (t < 1e300) return std::log1p(t);
    return std::log(ad) - std::log(scale);
}

/// a is better than b (smaller cost; within a relative 1e-12 it is a tie, which the caller breaks).
bool clearlyLess(double a, double b) {
    return a < b - 1e-12 * std::max(std::fabs(a), std::fabs(b));
}

/// Usable scale: a scale that underflowed to 0 becomes the smallest normal double (the selection
/// limit), an infinite one the largest (the mean limit).
double saneScale(double scale) {
    if (!(scale > 0.0)) return std::numeric_limits<double>::min();
    if (!std::isfinite(scale)) return std::numeric_limits<double>::max();
    return scale;
}

/// Majorise-minimise (fixed-point) iteration for eq. 4.7 from `beta`: log is concave, so
/// log(g^2 + d^2) <= log(a) + (g^2 + d^2 - a) / a, and minimising that quadratic bound gives the
/// weighted mean with weights w_j k_j, k_j = 1 / (1 + (d_j / g)^2); that step never increases the
/// cost. Its convergence is linear, so once the steps are small (< 0.01 gamma) and the cost is
/// convex there (f'' > 0), Newton steps finish quadratically; a Newton step longer than 8 MM steps
/// or leaving [x_0, x_{K-1}] is replaced by the MM step.
double myriadDescend(const double* x, const double* w, int K, double gamma, double beta) {
    const double lo = x[0], hi = x[K - 1];
    for (int it = 0; it < 2000; ++it) {
        double grad = 0.0, mm = 0.0, curv = 0.0;  // sums of w k t, w k, w (1 - t^2) k^2
        for (int j = 0; j < K; ++j) {
            const double t = (x[j] - beta) / gamma;
            const double k = 1.0 / (1.0 + t * t);  // t = inf gives 0: a far sample has no pull
            grad += w[j] * k * t;
            mm += w[j] * k;
            curv += w[j] * (1.0 - t * t) * k * k;
        }
        if (!(mm > 0.0)) break;
        // Step forms (beta + weighted mean of the offsets): exact at the fixed point.
        const double stepMM = gamma * (grad / mm);
        double step = stepMM;
        if (std::fabs(stepMM) < 0.01 * gamma && curv > 0.0) {
            const double stepNewton = gamma * (grad / curv);
            if (std::fabs(stepNewton) <= 8.0 * std::fabs(stepMM) && beta + stepNewton >= lo &&
                beta + stepNewton <= hi)
                step = stepNewton;
        }
        const double next = std::clamp(beta + step, lo, hi);
        const double moved = std::fabs(next - beta);
        beta = next;
        if (moved <= 1e-10 * gamma ||
            moved <= 2.0 * std::numeric_limits<double>::epsilon() * std::fabs(beta))
            break;
    }
    return beta;
}

/// Sorts the valid buffers by key (ties by buffer index) and merges equal keys:
/// s.sorted = distinct values ascending, s.weight = their summed counts. Returns the distinct
/// count.
int distinctValues(const PixelBuffers& px, EstimatorScratch& s) {
    std::sort(s.order.begin(), s.order.end(), [&s](int a, int b) {
        return s.key[a] < s.key[b] || (s.key[a] == s.key[b] && a < b);
    });
    s.sorted.clear();
    s.weight.clear();
    for (int j : s.order) {
        const double n = px.count[j];
        if (!s.sorted.empty() && s.sorted.back() == s.key[j]) {
            s.weight.back() += n;
        } else {
            s.sorted.push_back(s.key[j]);
            s.weight.push_back(n);
        }
    }
    return int(s.sorted.size());
}

/// The range of the valid buffers' keys within Hampel's fence |x - med| <= 3 x 1.4826 x MAD.
double hampelRange(const EstimatorScratch& s) {
    std::vector<double> x;
    for (int j : s.order) x.push_back(s.key[j]);
    std::sort(x.begin(), x.end());
    const size_t n = x.size();
    if (n < 2) return 0.0;
    auto median = [](const std::vector<double>& v) {
        const size_t m = v.size();
        return m % 2 == 1 ? v[m / 2] : 0.5 * (v[m / 2 - 1] + v[m / 2]);
    };
    const double med = median(x);
    std::vector<double> dev;
    for (double v : x) dev.push_back(std::fabs(v - med));
    std::sort(dev.begin(), dev.end());
    const double fence = 3.0 * 1.4826 * median(dev);
    double lo = 0.0, hi = 0.0;
    bool any = false;
    for (double v : x)
        if (std::fabs(v - med) <= fence) {
            if (!any) lo = v;
            hi = v;
            any = true;
        }
    return hi - lo;
}

double scaleFor(double factor, bool relative, bool hampel, const EstimatorScratch& s, int K) {
    if (hampel) {
        const double fenced = hampelRange(s);
        if (fenced > 0.0 || K < 2) return factor * fenced;
        return 1e-300 * (s.sorted[size_t(K) - 1] - s.sorted[0]);  // MAD 0: the selection limit
    }
    return relative ? factor * (s.sorted[size_t(K) - 1] - s.sorted[0]) : factor;
}

void setKeys(const PixelBuffers& px, const EstimatorParams& p, EstimatorScratch& s, int ch) {
    for (int j : s.order) {
        const float* m = px.mean + 3 * j;
        s.key[j] = ch < 0 ? p.luma[0] * m[0] + p.luma[1] * m[1] + p.luma[2] * m[2] : double(m[ch]);
    }
}

}  // namespace

double myriadCost(const double* x, const double* w, int K, double gamma, double beta) {
    gamma = saneScale(gamma);
    double c = 0.0;
    for (int j = 0; j < K; ++j) c += w[j] * logSquareTerm(x[j] - beta, gamma);
    return c;
}

double myriadSorted(const double* x, const double* w, int K, double gamma) {
    if (K <= 0) return 0.0;
    if (K == 1) return x[0];
    gamma = saneScale(gamma);
    // Every local minimum lies within gamma of a sample (see the header), so the global one lies in
    // some window W_i = [x_i - gamma, x_i + gamma]. A lower bound of the cost on W_i replaces each
    // |x_j - beta| by its smallest value on W_i. Windows are visited by increasing bound, the
    // descent runs from x_i, and once a bound reaches the best cost found no later window can hold
    // a better minimum: they are skipped (this keeps the cost near one descent per pixel).
    thread_local std::vector<std::pair<double, int>> windows;
    windows.clear();
    for (int i = 0; i < K; ++i) {
        double bound = 0.0;
        for (int j = 0; j < K; ++j)
            bound += w[j] * logSquareTerm(std::max(0.0, std::fabs(x[j] - x[i]) - gamma), gamma);
        windows.emplace_back(bound, i);
    }
    std::sort(windows.begin(), windows.end());
    double best = x[0], bestCost = std::numeric_limits<double>::infinity();
    for (const auto& [bound, i] : windows) {
        if (clearlyLess(bestCost, bound)) break;
        const double b = myriadDescend(x, w, K, gamma, x[i]);
        const double c = myriadCost(x, w, K, gamma, b);
        if (std::isinf(bestCost) || clearlyLess(c, bestCost) ||
            (!clearlyLess(bestCost, c) && b < best)) {
            best = b;
            bestCost = c;
        }
    }
    return best;
}

double meridianCost(const double* x, const double* w, int K, double delta, double beta) {
    delta = saneScale(delta);
    double c = 0.0;
    for (int j = 0; j < K; ++j) c += w[j] * logAbsTerm(x[j] - beta, delta);
    return c;
}

int meridianSorted(const double* x, const double* w, int K, double delta) {
    if (K <= 1) return 0;
    // Eq. 4.8: beta is one of the samples; evaluate each and keep the smallest cost (ties: lowest).
    int best = 0;
    double bestCost = meridianCost(x, w, K, delta, x[0]);
    for (int i = 1; i < K; ++i) {
        const double c = meridianCost(x, w, K, delta, x[i]);
        if (clearlyLess(c, bestCost)) {
            best = i;
            bestCost = c;
        }
    }
    return best;
}

void estimateMyriad(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                    EstimatorScratch& s) {
    out = PixelEstimate{};
    const int Mv = reference::collectValidBuffers(px, s.order, out.excluded);
    if (Mv == 0) return;
    s.key.resize(size_t(px.M));
    const bool lum = p.mode == EstimatorMode::Luminance;
    for (int ch = lum ? -1 : 0; ch < (lum ? 0 : 3); ++ch) {
        setKeys(px, p, s, ch);
        const int K = distinctValues(px, s);
        const double gamma = scaleFor(p.gamma, p.scaleRelative, p.scaleHampel, s, K);
        const double beta = myriadSorted(s.sorted.data(), s.weight.data(), K, gamma);
        int kept = 0;
        double sum[3] = {0.0, 0.0, 0.0}, wsum = 0.0;
        for (int j : s.order) {
            // Final fixed-point weights k_j = gamma^2 / (gamma^2 + d^2); all 1 when K == 1.
            const double t = K == 1 ? 0.0 : (s.key[j] - beta) / saneScale(gamma);
            const double k = 1.0 / (1.0 + t * t);
            if (k >= 0.5) ++kept;
            if (lum) {
                const double nk = double(px.count[j]) * k;
                wsum += nk;
                for (int c = 0; c < 3; ++c) sum[c] += nk * double(px.mean[3 * j + c]);
            }
        }
        if (lum) {
            if (wsum > 0.0) {
                for (int c = 0; c < 3; ++c) out.rgb[c] = float(sum[c] / wsum);
            } else {  // every weight underflowed (cannot happen for beta at a sample): nearest
                      // buffer
                const int j = s.order[0];
                for (int c = 0; c < 3; ++c) out.rgb[c] = px.mean[3 * j + c];
            }
            out.kept.fill(kept);
        } else {
            out.rgb[ch] = float(beta);
            out.kept[ch] = kept;
        }
    }
}

void estimateMeridian(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                      EstimatorScratch& s) {
    out = PixelEstimate{};
    const int Mv = reference::collectValidBuffers(px, s.order, out.excluded);
    if (Mv == 0) return;
    s.key.resize(size_t(px.M));
    const bool lum = p.mode == EstimatorMode::Luminance;
    for (int ch = lum ? -1 : 0; ch < (lum ? 0 : 3); ++ch) {
        setKeys(px, p, s, ch);
        const int K = distinctValues(px, s);
        const double delta = scaleFor(p.delta, p.scaleRelative, p.scaleHampel, s, K);
        const double value =
            s.sorted[size_t(meridianSorted(s.sorted.data(), s.weight.data(), K, delta))];
        if (lum) {
            // s.order is ranked by luminance, ties by buffer index: the first match is the lowest
            // index.
            for (int j : s.order) {
                if (s.key[j] != value) continue;
                for (int c = 0; c < 3; ++c) out.rgb[c] = px.mean[3 * j + c];
                break;
            }
            out.kept.fill(1);
        } else {
            out.rgb[ch] = float(value);
            out.kept[ch] = int(std::count_if(s.order.begin(), s.order.end(),
                                             [&](int j) { return s.key[j] == value; }));
        }
    }
}

}  // namespace mcstat::reference
