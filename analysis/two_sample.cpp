// Two-sample tests on sub-buffer means (include/mcstat/analysis/two_sample.h): the summaries of
// one side, Welch's test with a tolerance, and the multiple-testing thresholds.
#include "mcstat/analysis/two_sample.h"

#include <algorithm>
#include <boost/math/distributions/non_central_t.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "mcstat/core/detail/math_policy.h"
#include "mcstat/core/location_stats.h"

namespace mcstat {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// No exceptions, double computed in double: the one policy (core/math_policy.h).
using Policy = detail::MathPolicy;

}  // namespace

SideSummary meanSummary(const double* values, const double* counts, int M) {
    SideSummary s;
    std::vector<double> y, n;  // the non-empty buffers
    for (int j = 0; j < M; ++j) {
        const double w = counts ? counts[j] : 1.0;
        if (!(w > 0.0)) continue;
        if (!std::isfinite(values[j])) s.finite = false;
        y.push_back(values[j]);
        n.push_back(w);
    }
    s.buffers = int(y.size());
    // The arithmetic is core's, shared with the per-pixel confidence intervals.
    const LocationSummary l = weightedMeanSummary(y.data(), n.data(), s.buffers);
    s.estimate = l.estimate;
    if (s.buffers == 0 || !s.finite) return s;
    s.variance = l.variance;
    s.df = l.df;
    return s;
}

SideSummary trimmedSummary(const double* values, const double* counts, int M, double trim) {
    SideSummary s;
    std::vector<double> y;
    y.reserve(size_t(std::max(M, 0)));
    for (int j = 0; j < M; ++j) {
        if (counts && !(counts[j] > 0.0)) continue;
        if (!std::isfinite(values[j])) s.finite = false;
        y.push_back(values[j]);
    }
    s.buffers = int(y.size());
    if (y.empty() || !s.finite) {
        s.estimate = kNaN;
        return s;
    }
    std::sort(y.begin(), y.end());
    const int m = s.buffers;
    const int g = int(std::floor(std::clamp(trim, 0.0, 0.4999) * m));
    // Yuen's winsorised variance: core's, shared with the per-pixel confidence intervals.
    const LocationSummary l = yuenSummary(y.data(), m, g);
    s.estimate = l.estimate;
    s.variance = l.variance;
    s.df = l.df;
    return s;
}

SideSummary exactSummary(double value) {
    SideSummary s;
    s.estimate = value;
    s.variance = 0.0;
    s.df = kInf;
    s.buffers = 1;
    s.finite = std::isfinite(value);
    return s;
}

double studentTail(double t, double df) {
    if (std::isnan(t) || std::isnan(df) || !(df > 0.0)) return kNaN;
    if (t == kInf) return 0.0;
    if (t == -kInf) return 1.0;
    // Beyond ~1e7 degrees of freedom the t distribution is the normal to double precision, and
    // Boost's t with df = Inf is not defined in every version: use the normal.
    if (!(df < 1e7)) {
        const boost::math::normal_distribution<double, Policy> n;
        return boost::math::cdf(boost::math::complement(n, t));
    }
    const boost::math::students_t_distribution<double, Policy> dist(df);
    return boost::math::cdf(boost::math::complement(dist, t));
}

double studentUpperQuantile(double tail, double df) {
    if (!(tail > 0.0 && tail < 1.0) || std::isnan(df) || !(df > 0.0)) return kNaN;
    if (!(df < 1e7)) {
        const boost::math::normal_distribution<double, Policy> n;
        return boost::math::quantile(boost::math::complement(n, tail));
    }
    const boost::math::students_t_distribution<double, Policy> dist(df);
    return boost::math::quantile(boost::math::complement(dist, tail));
}

double detectableDifference(double se, double df, double margin, double alpha, double power) {
    if (!(se > 0.0) || !std::isfinite(se) || !(power > 0.0 && power < 1.0)) return kNaN;
    const double crit = studentUpperQuantile(alpha / 2.0, df);
    if (!std::isfinite(crit)) return kNaN;
    // The probability that |T| exceeds crit when the difference is ncp standard errors: T is
    // non-central t (df, ncp); the normal shifted by ncp beyond 1e7 degrees of freedom.
    auto found = [&](double ncp) {
        if (!(df < 1e7)) {
            const boost::math::normal_distribution<double, Policy> n(ncp);
            return boost::math::cdf(boost::math::complement(n, crit)) + boost::math::cdf(n, -crit);
        }
        // Boost's non-central t truncates a series index to an int, ignoring the policy, and
        // throws far out (ncp^2 / 2 beyond 2^31: a critical t of tens of thousands, df of 1 or
        // 2): there the t shifted by ncp, which the non-central t approaches, is the answer.
        try {
            const boost::math::non_central_t_distribution<double, Policy> t(df, ncp);
            return boost::math::cdf(boost::math::complement(t, crit)) + boost::math::cdf(t, -crit);
        } catch (const std::exception&) {
            return studentTail(crit - ncp, df) + studentTail(crit + ncp, df);
        }
    };
    // Bisection on ncp in [0, hi]: the probability grows with ncp.
    double lo = 0.0, hi = crit + studentUpperQuantile(1.0 - power, df) + 1.0;
    for (int i = 0; i < 60 && !(found(hi) >= power); ++i) hi *= 2.0;
    for (int i = 0; i < 60; ++i) {
        const double mid = 0.5 * (lo + hi);
        (found(mid) >= power ? hi : lo) = mid;
    }
    return margin + hi * se;
}

TwoSampleResult mitsubaZTest(double mean, double samples, double ref, double refVariance,
                             double varianceFloor) {
    TwoSampleResult r;
    r.difference = mean - ref;
    r.df = kInf;
    const double var = std::max(refVariance, varianceFloor);
    if (!std::isfinite(r.difference) || !(samples > 0.0) || !(var > 0.0) || std::isnan(var)) {
        r.z = r.p = kNaN;
        return r;
    }
    r.se = std::sqrt(var / samples);
    r.z = r.difference / r.se;
    // 2 (1 - Phi(|z|)) = erfc(|z| / sqrt 2), without cancellation in the far tail.
    r.p = std::erfc(std::fabs(r.z) / std::sqrt(2.0));
    return r;
}

TwoSampleResult welchTest(const SideSummary& a, const SideSummary& b, double margin,
                          TwoSampleTest test) {
    TwoSampleResult r;
    r.margin = margin;
    r.difference = b.estimate - a.estimate;
    const double var = a.variance + b.variance;
    r.se = std::sqrt(var);
    if (!a.finite || !b.finite || !std::isfinite(r.difference) || !(margin >= 0.0)) {
        r.z = kNaN;
        r.p = kNaN;
        r.df = kNaN;
        return r;
    }
    const double absd = std::fabs(r.difference);
    if (var == 0.0) {
        // Both sides are constant (or one is exact and the other constant): the difference is
        // known exactly, unless a side simply had no second buffer to show its spread.
        r.df = kInf;
        r.z = r.difference == 0.0 ? 0.0 : std::copysign(kInf, r.difference);
        if (a.df == 0.0 || b.df == 0.0) {
            r.p = kNaN;
            return r;
        }
        // Equivalence: an exact difference inside the margin, or exactly none (black on both
        // sides), is shown.
        if (test == TwoSampleTest::Difference)
            r.p = absd > margin ? 0.0 : 1.0;
        else
            r.p = absd < margin || absd == 0.0 ? 0.0 : 1.0;
        return r;
    }
    // Each side needs degrees of freedom for its variance; one buffer has none.
    if (a.df == 0.0 || b.df == 0.0) {
        r.z = r.difference / r.se;
        r.df = kNaN;
        r.p = kNaN;
        return r;
    }
    double denom = 0.0;
    if (a.variance > 0.0 && std::isfinite(a.df)) denom += a.variance * a.variance / a.df;
    if (b.variance > 0.0 && std::isfinite(b.df)) denom += b.variance * b.variance / b.df;
    r.df = denom > 0.0 ? var * var / denom : kInf;
    r.z = r.difference / r.se;
    if (test == TwoSampleTest::Difference) {
        // At the boundary |b - a| = margin: P(|D| >= |d|) for D ~ margin + se T (and its mirror).
        const double near = studentTail((absd - margin) / r.se, r.df);
        r.p = margin > 0.0 ? near + studentTail((absd + margin) / r.se, r.df) : 2.0 * near;
    } else {
        const double lower = studentTail((r.difference + margin) / r.se, r.df);  // H0: d <= -m
        const double upper = studentTail((margin - r.difference) / r.se, r.df);  // H0: d >= m
        r.p = margin > 0.0 ? std::max(lower, upper) : 1.0;
    }
    r.p = std::min(r.p, 1.0);
    return r;
}

double rejectionThreshold(const std::vector<float>& p, double q, Multiplicity control,
                          size_t* tested) {
    // Only p-values <= q can be rejected by any of the three rules, and under a true null they are
    // a fraction q of the family: sort those, count the rest.
    std::vector<float> small;
    size_t m = 0;
    for (float v : p) {
        if (std::isnan(v)) continue;
        ++m;
        if (double(v) <= q) small.push_back(v);
    }
    if (tested) *tested = m;
    if (small.empty()) return -1.0;
    std::sort(small.begin(), small.end());
    double threshold = -1.0;
    switch (control) {
        case Multiplicity::None:
            threshold = small.back();
            break;
        case Multiplicity::FDR:
            // Step-up: the largest k with p_(k) <= k q / m rejects p_(1..k).
            for (size_t k = small.size(); k >= 1; --k)
                if (double(small[k - 1]) <= double(k) * q / double(m)) {
                    threshold = small[k - 1];
                    break;
                }
            break;
        case Multiplicity::FWER:
            // Step-down: reject while p_(k) <= q / (m - k + 1).
            for (size_t k = 1; k <= small.size(); ++k) {
                if (double(small[k - 1]) > q / double(m - k + 1)) break;
                threshold = small[k - 1];
            }
            break;
    }
    return threshold;
}

}  // namespace mcstat
