// The statistics of a location from replicates (include/mcstat/core/location_stats.h).
#include "mcstat/core/location_stats.h"

#include <algorithm>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <limits>

#include "mcstat/core/detail/math_policy.h"

namespace mcstat {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// No exceptions, double computed in double: the one policy (core/math_policy.h).
using Policy = detail::MathPolicy;

}  // namespace

LocationSummary weightedMeanSummary(const double* values, const double* counts, int m) {
    LocationSummary s;
    if (m <= 0) {
        s.estimate = kNaN;
        return s;
    }
    double n = 0.0, sum = 0.0;
    for (int j = 0; j < m; ++j) {
        const double w = counts ? counts[j] : 1.0;
        n += w;
        sum += w * values[j];
    }
    s.estimate = sum / n;
    if (m < 2) return s;
    // Second pass about the mean: no cancellation for values far from 0.
    double ss = 0.0;
    for (int j = 0; j < m; ++j) {
        const double w = counts ? counts[j] : 1.0;
        const double d = values[j] - s.estimate;
        ss += w * d * d;
    }
    s.df = m - 1;
    s.variance = ss / s.df / n;
    return s;
}

LocationSummary yuenSummary(const double* y, int m, int g) {
    LocationSummary s;
    if (m <= 0) {
        s.estimate = kNaN;
        return s;
    }
    g = std::clamp(g, 0, (m - 1) / 2);
    const int h = m - 2 * g;
    double sum = 0.0;
    for (int j = g; j < m - g; ++j) sum += y[j];
    s.estimate = sum / h;
    if (h < 2) return s;
    // Winsorised values: the g smallest become y[g], the g largest y[m - g - 1].
    auto wins = [&](int j) { return y[std::clamp(j, g, m - g - 1)]; };
    double wsum = 0.0;
    for (int j = 0; j < m; ++j) wsum += wins(j);
    const double wmean = wsum / m;
    double ss = 0.0;
    for (int j = 0; j < m; ++j) {
        const double d = wins(j) - wmean;
        ss += d * d;
    }
    // (m - 1) s_w^2 / (h (h - 1)) with s_w^2 = ss / (m - 1).
    s.variance = ss / (double(h) * (h - 1));
    s.df = h - 1;
    return s;
}

double studentQuantile(double p, double df) {
    if (!(p > 0.0 && p < 1.0) || !(df > 0.0)) return kNaN;
    if (!(df < 1e7)) {
        const boost::math::normal_distribution<double, Policy> n;
        return boost::math::quantile(n, p);
    }
    const boost::math::students_t_distribution<double, Policy> dist(df);
    return boost::math::quantile(dist, p);
}

double medianIntervalCoverage(int m, int k) {
    if (k < 1 || 2 * k > m) return 0.0;
    // 1 - 2 P(B <= k - 1), the binomial terms C(m, i) 2^-m built in logs (m up to thousands).
    double tail = 0.0;
    for (int i = 0; i < k; ++i)
        tail += std::exp(std::lgamma(m + 1.0) - std::lgamma(i + 1.0) - std::lgamma(m - i + 1.0) -
                         m * std::log(2.0));
    return std::max(0.0, 1.0 - 2.0 * tail);
}

int medianIntervalRank(int m, double level) {
    int best = 0;
    for (int k = 1; 2 * k <= m; ++k) {
        if (medianIntervalCoverage(m, k) >= level)
            best = k;
        else
            break;  // coverage falls as k grows
    }
    return best;
}

}  // namespace mcstat
