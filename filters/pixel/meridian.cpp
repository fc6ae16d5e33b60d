// Meridian (Jung 2016, eq. 4.8) over one pixel's sub-buffer means: a selection M-estimator whose
// scale delta moves it from the mode (small) to the median (large).
// Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical Estimation
// Techniques", PhD thesis, University of Minnesota, 2016, section 4.1.3 (M-estimators) and
// section 4.2 (scale 0.05 x input range, luminance-driven selection). Rules: meridian.h.
#include "mcstat/filters/pixel/meridian.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "distinct_values.h"

namespace mcstat {

using detail::clearlyLess;
using detail::saneScale;

namespace {

/// log1p(t) for t = |d| / scale, without overflow.
double logAbsTerm(double d, double scale) {
    const double ad = std::fabs(d);
    const double t = ad / scale;
    if (t < 1e300) return std::log1p(t);
    return std::log(ad) - std::log(scale);
}

}  // namespace

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

void estimateMeridian(const PixelBuffers& px, const MeridianParams& p, PixelEstimate& out,
                      EstimatorScratch& s) {
    const bool lum = p.mode == EstimatorMode::Luminance;
    detail::estimateLocation(px, p, p.delta, out, s, [&](int ch, int K, double delta) {
        const double value =
            s.sorted[size_t(meridianSorted(s.sorted.data(), s.weight.data(), K, delta))];
        if (!lum) {
            out.rgb[ch] = float(value);
            out.kept[ch] = int(std::count_if(s.order.begin(), s.order.end(),
                                             [&](int j) { return s.key[j] == value; }));
            return;
        }
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
    });
}

namespace {

PixelKernel bindMeridian(const ParamValues& values, const std::array<double, 3>& luma) {
    auto p = pixelParamsAs<MeridianParams>(values, luma);
    p.delta = values.at("delta").real;
    p.scale = scaleRule(values);
    return pixelKernel(p, &estimateMeridian, /*smallestRobustM=*/2);
}

}  // namespace

Operation meridianOperation() {
    return pixelOperation(
        "meridian", "meridian",
        "Meridian (Jung eq. 4.8): the buffer mean minimising sum n_j log(delta + |x_j - b|)",
        "Jung eq. 4.8",
        {modeParam(),
         realParam("delta", 0.0, HUGE_VAL, true, "0.05",
                   "scale (small: mode-like, large: the median)"),
         scaleParam()},
        &bindMeridian);
}

}  // namespace mcstat
