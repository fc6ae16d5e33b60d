// Jung's analytic error rates (thesis eq. 4.10-4.13, 5.3, 5.9, 5.10, 5.16, 5.22) and the planner's
// design searches (sections 4.1.4 and 5.3.1), in log space. See include/mcstat/analysis/planner.h.
#include "mcstat/analysis/planner.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace mcstat::planner {

namespace {

constexpr double kNegInf = -std::numeric_limits<double>::infinity();

/// log of sum exp(t_i) over terms, exact for -inf terms (probability 0).
double logSumExp(const std::vector<double>& t, size_t lo, size_t hi) {
    double mx = kNegInf;
    for (size_t i = lo; i < hi; ++i) mx = std::max(mx, t[i]);
    if (mx == kNegInf) return kNegInf;
    double s = 0.0;
    for (size_t i = lo; i < hi; ++i) s += std::exp(t[i] - mx);
    return mx + std::log(s);
}

/// i * log(q) with 0 * log(0) = 0 (the binomial term q^0 = 1 even for q = 0).
double times(int i, double logq) { return i == 0 ? 0.0 : double(i) * logq; }

int halfUp(long n) { return int((n + 1) / 2); }  // ceil(n / 2)

}  // namespace

double LogProb::value() const { return std::exp(lnP); }
double LogProb::log10() const { return lnP / std::log(10.0); }

LogProb fromProbability(double q) {
    q = std::clamp(q, 0.0, 1.0);
    return {std::log(q), std::log1p(-q)};
}

LogProb fromLog(double logq) {
    logq = std::min(logq, 0.0);
    // log(1 - e^a): log1p(-e^a) when e^a < 1/2, log(-expm1(a)) near a = 0 (both without
    // cancellation).
    const double lnNot =
        logq < -0.6931471805599453 ? std::log1p(-std::exp(logq)) : std::log(-std::expm1(logq));
    return {logq, lnNot};
}

LogProb binomialTail(int n, int k, const LogProb& q) {
    if (k <= 0) return {0.0, kNegInf};
    if (k > n) return {kNegInf, 0.0};
    // Eq. 4.9 terms in log space: log C(n, i) + i log q + (n - i) log(1 - q).
    std::vector<double> t(size_t(n) + 1);
    const double lgn = std::lgamma(double(n) + 1.0);
    for (int i = 0; i <= n; ++i) {
        t[size_t(i)] = lgn - std::lgamma(double(i) + 1.0) - std::lgamma(double(n - i) + 1.0) +
                       times(i, q.lnP) + times(n - i, q.lnNot);
    }
    // Both tails summed directly: no 1 - (sum) anywhere. Rounding can put a sum 1 ulp above 1:
    // clamp the logs to 0.
    return {std::min(0.0, logSumExp(t, size_t(k), size_t(n) + 1)),
            std::min(0.0, logSumExp(t, 0, size_t(k)))};
}

const char* methodName(Method m) {
    switch (m) {
        case Method::MPE:
            return "MPE";
        case Method::MIF:
            return "MIF";
        case Method::MPEMIF:
            return "MPE+MIF";
        case Method::DMF3:
            return "3DMF";
    }
    return "?";
}

std::string designName(const Design& d) {
    const int k = int(std::lround(std::sqrt(double(d.n))));
    const std::string win =
        k * k == d.n ? std::to_string(k) + "x" + std::to_string(k) : std::to_string(d.n);
    switch (d.method) {
        case Method::MPE:
            return "MPE(" + std::to_string(d.m) + ")";
        case Method::MIF:
            return "MIF(" + win + ")";
        case Method::MPEMIF:
            return "MPE(" + std::to_string(d.m) + ")+MIF(" + win + ")";
        case Method::DMF3:
            return "3DMF(" + std::to_string(d.m) + "x" + win + ")";
    }
    return "?";
}

LogProb unitProbabilityLinear(const Design& d, double np) {
    if (!(np > 0.0)) return {kNegInf, 0.0};
    // Eq. 4.10 (last line): p_estimate = (N / m) p_sample; MIF: p_pixel = N p_sample (eq. 5.10).
    const double per = d.method == Method::MIF ? 1.0 : double(std::max(d.m, 1));
    return fromLog(std::log(np) - std::log(per));
}

LogProb unitProbabilityExact(const Design& d, double p, double spp) {
    if (!(p > 0.0) || !(spp > 0.0)) return {kNegInf, 0.0};
    if (p >= 1.0) return {0.0, kNegInf};
    // Eq. 4.10 (first lines): 1 - (1 - p)^(N/m), with N/m samples in a buffer (N in a pixel for
    // MIF).
    const double per = d.method == Method::MIF ? 1.0 : double(std::max(d.m, 1));
    const double lnNot = (spp / per) * std::log1p(-p);
    return {std::log(-std::expm1(lnNot)), lnNot};
}

LogProb reachProbability(const Design& d, const LogProb& q) {
    const int m = std::max(d.m, 1), n = std::max(d.n, 1);
    switch (d.method) {
        case Method::MPE:
            return binomialTail(m, halfUp(m), q);  // eq. 4.13 / 5.3
        case Method::MIF:
            return binomialTail(n, halfUp(n), q);  // eq. 5.9
        case Method::MPEMIF:                       // eq. 5.16: eq. 5.9 of eq. 5.3
            return binomialTail(n, halfUp(n), binomialTail(m, halfUp(m), q));
        case Method::DMF3: {  // eq. 5.22
            const long mn = long(m) * long(n);
            return binomialTail(int(mn), halfUp(mn), q);
        }
    }
    return {kNegInf, 0.0};
}

LogProb errorRate(const Design& d, double np) {
    return reachProbability(d, unitProbabilityLinear(d, np));
}

int smallestBuffers(double np, double pixels, int maxM) {
    const double target = -std::log(std::max(pixels, 1.0));  // P < 1 / pixels
    for (int m = 1; m <= maxM; m += 2)
        if (errorRate({Method::MPE, m, 1}, np).lnP < target) return m;
    return 0;
}

int smallestWindow(Method method, int m, double np, double pixels, int maxK) {
    const double target = -std::log(std::max(pixels, 1.0));
    for (int k = 1; k <= maxK; k += 2)
        if (errorRate({method, m, k * k}, np).lnP < target) return k;
    return 0;
}

SppPlan minimumSpp(const Design& d, double p, double certainty) {
    SppPlan plan;
    if (!(p > 0.0) || !(certainty > 0.0 && certainty < 1.0)) return plan;
    const double target = std::log1p(-certainty);  // log of the allowed miss probability
    // Linearised model: the miss probability falls as N p grows; at N p = m (1 for MIF) every
    // buffer holds the sample and it always reaches the pixel. Bisection on N p.
    double lo = 0.0, hi = d.method == Method::MIF ? 1.0 : double(std::max(d.m, 1));
    for (int it = 0; it < 200 && hi - lo > 1e-13 * hi; ++it) {
        const double mid = 0.5 * (lo + hi);
        (errorRate(d, mid).lnNot <= target ? hi : lo) = mid;
    }
    plan.np = hi;
    plan.sppLinear = std::ceil(hi / p);
    // Exact model: smallest integer N; doubling then bisection (N can be astronomically large for
    // tiny p: stop at a relative resolution of 1e-15 there).
    auto meets = [&](double N) {
        return reachProbability(d, unitProbabilityExact(d, p, N)).lnNot <= target;
    };
    double nhi = 1.0;
    while (!meets(nhi) && nhi < 1e300) nhi *= 2.0;
    if (!meets(nhi)) return plan;
    double nlo = nhi / 2.0;  // fails (or is below 1)
    if (nhi == 1.0) nlo = 0.0;
    while (nhi - nlo > std::max(1.0, 1e-15 * nhi)) {
        const double mid = std::floor(0.5 * (nlo + nhi));
        if (mid <= nlo) break;
        (meets(mid) ? nhi : nlo) = mid;
    }
    plan.sppExact = nhi;
    plan.feasible = true;
    return plan;
}

}  // namespace mcstat::planner
