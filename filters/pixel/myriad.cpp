// Myriad (eq. 4.7) and meridian (eq. 4.8) over one pixel's sub-buffer means.
// Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical Estimation
// Techniques", PhD thesis, University of Minnesota, 2016, section 4.1.3 (M-estimators) and
// section 4.2 (scale 0.05 x input range, luminance-driven selection). Rules:
// filters/pixel/myriad.h.
#include "mcstat/filters/pixel/myriad.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

namespace mcstat {

namespace {

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
///
/// myriadVisit runs that iteration for eight windows at a time (GCC vector extension, 2 x 4
/// doubles): lane l runs exactly the scalar loop (as first written) from its window's sample; each
/// lane's operations are the scalar ones in the same order (the terms, their sums over j in index
/// order, the step choice, the clamp, the stopping tests and the 2000-iteration cap), IEEE
/// operations that round the same in any width (no FMA in either clone). A descent is a chain of
/// dependent additions and divisions, so one descent leaves the CPU mostly waiting; eight
/// interleaved keep its dividers busy (on the benchmark image a pixel runs ~13 descents, ~300
/// steps). A lane that stops hands its result over and takes the next window.
///
/// The results are then used exactly as the scalar visit in myriadSorted used them: in the
/// windows' order, each window's bound tested against the best cost of the windows before it
/// (clearlyLess(bestCost, bound): stop), then its cost and the choice of the best. Descents of
/// windows after that stop were computed ahead and are not used: the scalar visit would not have
/// run them.
__attribute__((target_clones("avx2", "default"))) double myriadVisit(
    const double* x, const double* w, int K, double gamma, const std::pair<double, int>* windows,
    int nw) {
    // Two halves of four lanes: 32-byte vectors are AVX2 registers (SSE2 pairs in the default
    // clone); lane l is half l / 4, element l % 4.
    typedef double V __attribute__((vector_size(32)));
    typedef long long VI __attribute__((vector_size(32)));
    thread_local std::vector<double> result;
    thread_local std::vector<unsigned char> ready;
    result.assign(size_t(nw), 0.0);
    ready.assign(size_t(nw), 0);
    V beta[2] = {};
    VI active[2] = {};
    int win[8] = {}, iters[8] = {};
    int assigned = 0, visited = 0;
    double best = x[0], bestCost = std::numeric_limits<double>::infinity();
    const double lo = x[0], hi = x[K - 1];
    const VI absMask = VI{} + 0x7fffffffffffffffll;  // |v| clears the sign bit
    const double nearStep = 0.01 * gamma, tiny = 1e-10 * gamma;
    const double ulp2 = 2.0 * std::numeric_limits<double>::epsilon();
    for (;;) {
        for (int l = 0; l < 8; ++l)
            if (!active[l / 4][l % 4] && assigned < nw) {
                win[l] = assigned;
                beta[l / 4][l % 4] = x[windows[assigned].second];
                active[l / 4][l % 4] = -1;
                iters[l] = 0;
                ++assigned;
            }
        // One step of every active lane (the body of the scalar loop).
        V grad[2] = {}, mm[2] = {}, curv[2] = {};  // sums of w k t, w k, w (1 - t^2) k^2
        for (int j = 0; j < K; ++j) {
            const double xj = x[j], wj = w[j];
            for (int h = 0; h < 2; ++h) {
                const V t = (xj - beta[h]) / gamma;
                const V k = 1.0 / (1.0 + t * t);  // t = inf gives 0: a far sample has no pull
                grad[h] += wj * k * t;
                mm[h] += wj * k;
                curv[h] += wj * (1.0 - t * t) * k * k;
            }
        }
        VI still[2];
        for (int h = 0; h < 2; ++h) {
            const VI ok = mm[h] > 0.0;  // else the scalar loop stops with beta unchanged
            // Step forms (beta + weighted mean of the offsets): exact at the fixed point.
            const V stepMM = gamma * (grad[h] / mm[h]);
            const V stepNewton = gamma * (grad[h] / curv[h]);
            const V absMM = (V)((VI)stepMM & absMask);
            const VI newton = (absMM < nearStep) & (curv[h] > 0.0) &
                              ((V)((VI)stepNewton & absMask) <= 8.0 * absMM) &
                              (beta[h] + stepNewton >= lo) & (beta[h] + stepNewton <= hi);
            const V step = newton ? stepNewton : stepMM;
            const V moved0 = beta[h] + step;
            const V next =
                moved0 < lo ? V{} + lo : (hi < moved0 ? V{} + hi : moved0);  // std::clamp
            const V moved = (V)((VI)(next - beta[h]) & absMask);
            const VI update = active[h] & ok;
            beta[h] = update ? next : beta[h];
            const VI stop = (moved <= tiny) | (moved <= ulp2 * (V)((VI)next & absMask));
            still[h] = update & ~stop;
        }
        for (int l = 0; l < 8; ++l) {
            if (!active[l / 4][l % 4]) continue;
            if (still[l / 4][l % 4] && ++iters[l] < 2000) continue;
            active[l / 4][l % 4] = 0;  // this descent is over: its result is beta
            result[size_t(win[l])] = beta[l / 4][l % 4];
            ready[size_t(win[l])] = 1;
        }
        // The scalar visit, as far as the results allow.
        while (visited < nw) {
            if (clearlyLess(bestCost, windows[visited].first)) return best;
            if (!ready[size_t(visited)]) break;
            const double b = result[size_t(visited)];
            const double c = myriadCost(x, w, K, gamma, b);
            if (std::isinf(bestCost) || clearlyLess(c, bestCost) ||
                (!clearlyLess(bestCost, c) && b < best)) {
                best = b;
                bestCost = c;
            }
            ++visited;
        }
        if (visited == nw) return best;
    }
}

/// Sorts s.order by s.key (ties by buffer index). Up to 64 buffers the position of each is counted
/// (branch-free, no comparison sort's mispredictions): the same order, as the order is total.
void sortOrderByKey(EstimatorScratch& s) {
    const int n = int(s.order.size());
    if (n > 64 || std::any_of(s.order.begin(), s.order.end(),
                              [&s](int j) { return std::isnan(s.key[size_t(j)]); })) {
        std::sort(s.order.begin(), s.order.end(), [&s](int a, int b) {
            return s.key[a] < s.key[b] || (s.key[a] == s.key[b] && a < b);
        });
        return;
    }
    double key[64];
    int idx[64];
    for (int i = 0; i < n; ++i) {
        idx[i] = s.order[size_t(i)];
        key[i] = s.key[size_t(idx[i])];
    }
    // s.order may hold the previous channel's order: ties compare buffer indices.
    bool ascending = true;
    for (int i = 1; i < n; ++i) ascending &= idx[i - 1] < idx[i];
    if (!ascending) {
        for (int i = 0; i < n; ++i) {
            int r = 0;
            for (int j = 0; j < n; ++j)
                r += (key[j] < key[i]) | ((key[j] == key[i]) & (idx[j] < idx[i]));
            s.order[size_t(r)] = idx[i];
        }
        return;
    }
    // In index order (luminance, or the first channel) a lower position is a lower index, so
    // the rank estimators' ranking (ties by position) gives the same order.
    int pos[64];
    detail::rankKeys(key, n, pos);
    for (int r = 0; r < n; ++r) s.order[size_t(r)] = idx[pos[r]];
}

/// Sorts the valid buffers by key (ties by buffer index) and merges equal keys:
/// s.sorted = distinct values ascending, s.weight = their summed counts. Returns the distinct
/// count.
int distinctValues(const PixelBuffers& px, EstimatorScratch& s) {
    sortOrderByKey(s);
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

double scaleFor(double factor, bool relative, const EstimatorScratch& s, int K) {
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
    // The bound's terms are symmetric in (i, j) (|x_j - x_i| is exactly |x_i - x_j|), and zero
    // (log1p(0), and w * 0 adds nothing to a sum >= +0) within gamma: each log is taken once, for
    // i < j, and the sums still run over j in index order, as before.
    thread_local std::vector<double> term;
    term.assign(size_t(K) * size_t(K), 0.0);
    for (int i = 0; i < K; ++i)
        for (int j = i + 1; j < K; ++j) {
            const double d = std::max(0.0, std::fabs(x[j] - x[i]) - gamma);
            if (d == 0.0) continue;
            const double v = logSquareTerm(d, gamma);
            term[size_t(i) * size_t(K) + size_t(j)] = v;
            term[size_t(j) * size_t(K) + size_t(i)] = v;
        }
    for (int i = 0; i < K; ++i) {
        double bound = 0.0;
        const double* ti = term.data() + size_t(i) * size_t(K);
        for (int j = 0; j < K; ++j) bound += w[j] * ti[j];
        windows.emplace_back(bound, i);
    }
    std::sort(windows.begin(), windows.end());
    return myriadVisit(x, w, K, gamma, windows.data(), int(windows.size()));
}

double meridianCost(const double* x, const double* w, int K, double delta, double beta) {
    delta = saneScale(delta);
    double c = 0.0;
    for (int j = 0; j < K; ++j) c += w[j] * logAbsTerm(x[j] - beta, delta);
    return c;
}

namespace {

/// The scan of eq. 4.8 as first written: every sample's cost, in index order, the smallest kept
/// (a later sample wins only when clearly less: ties go to the lowest index).
int meridianScan(const double* x, const double* w, int K, double delta) {
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

/// log1p(t) for finite t >= 0 with |error| < 3e-8, against the correctly rounded value and against
/// libm's log1p alike: s = 1 + t (relative rounding 2^-53, i.e. 1.2e-16 in the log), s = 2^e m
/// with m in [sqrt(1/2), sqrt(2)] (exact), log m = 2 atanh z, z = (m - 1) / (m + 1), |z| <= 0.1716,
/// by its series to z^7: the rest is at most 2 |z|^9 / 9 / (1 - z^2) < 2.93e-8. Rounding in the
/// evaluation adds < 1e-12 for t < 1e300 (e ln 2 <= 710). Used only to *bound* costs (see
/// meridianSorted), never as a result.
inline double log1pApprox(double t) {
    const double s = 1.0 + t;
    uint64_t bits;
    std::memcpy(&bits, &s, sizeof bits);
    // Integer operations only (no branch, no FP compare), so that rows vectorise. s >= 1 is
    // positive and normal; m > sqrt(2) exactly when the mantissa bits exceed sqrt(2)'s, and then
    // m / 2 (exponent field - 1) with e + 1. The exponent becomes a double as 2^52 + field minus
    // 2^52 + 1023, both exact.
    const uint64_t mant = bits & 0x000fffffffffffffull;
    const uint64_t high = mant > 0x6a09e667f3bcdull ? 1 : 0;
    const uint64_t ebits = ((bits >> 52) + high) | 0x4330000000000000ull;
    const uint64_t mbits = mant | (0x3ff0000000000000ull - (high << 52));
    double e, m;
    std::memcpy(&e, &ebits, sizeof e);
    std::memcpy(&m, &mbits, sizeof m);
    e -= 4503599627371519.0;
    const double z = (m - 1.0) / (m + 1.0);
    const double z2 = z * z;
    const double lm = 2.0 * z * (1.0 + z2 * (1.0 / 3.0 + z2 * (1.0 / 5.0 + z2 * (1.0 / 7.0))));
    return e * 0.6931471805599453 + lm;
}

/// The approximate costs of step 1 below for all K samples: approx[i] (zeroed by the caller) +=
/// w_j log1pApprox(|x_j - x_i| * inv) over j != i, each pair's term computed once (i < j) and added
/// to both. x, w and approx have 3 more entries: copies of x[K-1] with weight 0, so that every row
/// runs in whole groups of 4 (no scalar tail); they add w * g = +0 (g is finite) and their own
/// approx is ignored. Every argument is below 1e299 (checked by the caller). Only bounds come out
/// of it, so neither the clone's arithmetic nor the order of the sums needs bit-identity: the
/// rounding bound of a sum of positive terms holds in any order. One call for all rows (not one per
/// row), and four partial sums per row, keep the loops vectorised and cheap.
__attribute__((target_clones("avx2", "default"))) void log1pApproxCosts(const double* x,
                                                                        const double* w, int K,
                                                                        double inv,
                                                                        double* approx) {
    for (int i = 0; i < K; ++i) {
        const double xi = x[i], wi = w[i];
        double part[4] = {0.0, 0.0, 0.0, 0.0};
        for (int j = i + 1; j < K; j += 4)
            for (int t = 0; t < 4; ++t) {
                const double g = log1pApprox((x[j + t] - xi) * inv);
                part[t] += w[j + t] * g;
                approx[j + t] += wi * g;
            }
        approx[i] += (part[0] + part[1]) + (part[2] + part[3]);
    }
}

}  // namespace

int meridianSorted(const double* x, const double* w, int K, double delta) {
    if (K <= 1) return 0;
    // Eq. 4.8: beta is one of the samples; the scan (meridianScan) evaluates each and keeps the
    // smallest cost, a later one only when clearly less (ties: lowest index). Every cost takes K
    // logarithms, so that is K^2 of them. Here the same answer, bit for bit, from far fewer:
    // 1. A_i, an approximate cost of every sample from log1pApprox (one log per pair: the terms are
    //    symmetric). With eps = 3e-8 and W = sum w_j, the cost meridianCost computes is at least
    //    LB_i = A_i (1 - 1e-12) - 4e-8 W (the factor covers the rounding of two sums of <= 999
    //    positive terms, < 2.6e-13 relative; 4e-8 > eps covers the rounding of LB_i itself).
    // 2. U = the exact cost of the sample with the smallest A_i; T = U (1 + 1e-9).
    // 3. Samples with LB_i >= T are "far": their exact cost is >= T. The others ("near") get their
    //    exact cost, and each must be < T (1 - 4e-12), else the plain scan decides (never seen,
    //    kept for rigour). Then the scan over the near samples alone gives the scan's answer:
    //    before the first near sample the scan's best is far (cost B >= T), and a near cost c <
    //    T (1 - 4e-12) <= B (1 - 4e-12) is clearly less than B, so the scan takes the first near
    //    sample too; from then on its best cost is < T and no far sample (cost >= T) is clearly
    //    less. Near samples are compared with the same clearlyLess as the scan.
    delta = saneScale(delta);
    thread_local std::vector<double> approx, row;
    approx.assign(size_t(K), 0.0);
    row.resize(size_t(K));
    double W = 0.0;
    for (int j = 0; j < K; ++j) W += w[j];
    const double inv = 1.0 / delta;
    // t = d * inv is within 2 ulp of d / delta: < 2.3e-16 more error in the log.
    const bool moderate = (x[K - 1] - x[0]) * inv < 1e299;
    if (moderate) {
        thread_local std::vector<double> xp, wp;
        xp.assign(x, x + K);
        xp.resize(size_t(K) + 3, x[K - 1]);
        wp.assign(w, w + K);
        wp.resize(size_t(K) + 3, 0.0);
        approx.resize(size_t(K) + 3, 0.0);
        log1pApproxCosts(xp.data(), wp.data(), K, inv, approx.data());
    }
    for (int i = 0; i < K && !moderate; ++i) {
        const int n = K - i - 1;  // pairs (i, j > i); d = x_j - x_i > 0 (sorted, distinct)
        double* g = row.data();
        for (int j = 0; j < n; ++j) {
            const double d = x[i + 1 + j] - x[i];
            g[j] = d * inv < 1e299 ? log1pApprox(d * inv) : logAbsTerm(d, delta);
        }
        double acc = approx[size_t(i)];
        for (int j = 0; j < n; ++j) {
            acc += w[i + 1 + j] * g[j];
            approx[size_t(i + 1 + j)] += w[i] * g[j];
        }
        approx[size_t(i)] = acc;
    }
    int u = 0;
    for (int i = 1; i < K; ++i)
        if (approx[size_t(i)] < approx[size_t(u)]) u = i;
    const double slack = 4e-8 * W;
    if (moderate) {
        // 2'. The usual case needs no exact cost at all. The computed cost of x_u is at most
        //     UB = A_u (1 + 1e-12) + 4e-8 W (the bound of step 1 from above). If every other
        //     sample has LB_i >= T' = UB (1 + 1e-9), its cost exceeds that of x_u by more than a
        //     relative 1e-9 (>> the 1e-12 of clearlyLess and the rounding of T'), so the scan
        //     takes x_u when it reaches it (or starts there, u = 0) and nothing after is clearly
        //     less: the answer is u. Otherwise steps 2 and 3 decide.
        const double T1 = (approx[size_t(u)] * (1.0 + 1e-12) + slack) * (1.0 + 1e-9);
        bool alone = true;
        for (int i = 0; i < K; ++i)
            alone &= i == u || approx[size_t(i)] * (1.0 - 1e-12) - slack >= T1;
        if (alone) return u;
    }
    const double U = meridianCost(x, w, K, delta, x[u]);
    const double T = U * (1.0 + 1e-9);
    const double nearLimit = T * (1.0 - 4e-12);
    int best = -1;
    double bestCost = 0.0;
    for (int i = 0; i < K; ++i) {
        const double lb = approx[size_t(i)] * (1.0 - 1e-12) - slack;
        if (lb >= T) continue;  // far
        const double c = i == u ? U : meridianCost(x, w, K, delta, x[i]);
        if (!(c < nearLimit)) return meridianScan(x, w, K, delta);
        if (best < 0 || clearlyLess(c, bestCost)) {
            best = i;
            bestCost = c;
        }
    }
    return best < 0 ? meridianScan(x, w, K, delta) : best;
}

void estimateMyriad(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                    EstimatorScratch& s) {
    out = PixelEstimate{};
    s.bufferWeight.clear();
    if (s.wantWeights && p.mode == EstimatorMode::Luminance)
        s.bufferWeight.assign(size_t(px.M), 0.0);  // stays 0 when no buffer is valid
    const int Mv = collectValidBuffers(px, s.order, out.excluded);
    if (Mv == 0) return;
    s.key.resize(size_t(px.M));
    const bool lum = p.mode == EstimatorMode::Luminance;
    for (int ch = lum ? -1 : 0; ch < (lum ? 0 : 3); ++ch) {
        setKeys(px, p, s, ch);
        const int K = distinctValues(px, s);
        const double gamma = scaleFor(p.gamma, p.scaleRelative, s, K);
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
            if (s.wantWeights) {
                // The final weights n_j k_j / sum n k (or the one buffer used above).
                s.bufferWeight.assign(size_t(px.M), 0.0);
                for (int j : s.order) {
                    const double t = K == 1 ? 0.0 : (s.key[j] - beta) / saneScale(gamma);
                    const double k = 1.0 / (1.0 + t * t);
                    const double nk = double(px.count[j]) * k;
                    if (wsum > 0.0) s.bufferWeight[size_t(j)] = nk / wsum;
                }
                if (!(wsum > 0.0)) s.bufferWeight[size_t(s.order[0])] = 1.0;
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
    s.bufferWeight.clear();
    if (s.wantWeights && p.mode == EstimatorMode::Luminance)
        s.bufferWeight.assign(size_t(px.M), 0.0);  // stays 0 when no buffer is valid
    const int Mv = collectValidBuffers(px, s.order, out.excluded);
    if (Mv == 0) return;
    s.key.resize(size_t(px.M));
    const bool lum = p.mode == EstimatorMode::Luminance;
    for (int ch = lum ? -1 : 0; ch < (lum ? 0 : 3); ++ch) {
        setKeys(px, p, s, ch);
        const int K = distinctValues(px, s);
        const double delta = scaleFor(p.delta, p.scaleRelative, s, K);
        const double value =
            s.sorted[size_t(meridianSorted(s.sorted.data(), s.weight.data(), K, delta))];
        if (lum) {
            // s.order is ranked by luminance, ties by buffer index: the first match is the lowest
            // index.
            for (int j : s.order) {
                if (s.key[j] != value) continue;
                for (int c = 0; c < 3; ++c) out.rgb[c] = px.mean[3 * j + c];
                if (s.wantWeights) {  // a selection: the chosen buffer alone
                    s.bufferWeight.assign(size_t(px.M), 0.0);
                    s.bufferWeight[size_t(j)] = 1.0;
                }
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

}  // namespace mcstat
