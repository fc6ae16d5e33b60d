// Confidence intervals per pixel (confidence.h); the statistics are core's
// (core/location_stats.h), shared with --compare's tests (analysis/two_sample.cpp).
#include "mcstat/filters/pixel/confidence.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "mcstat/core/location_stats.h"

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

/// estimate +- t_{1 - (1 - level) / 2, df} sqrt(variance).
ValueInterval tInterval(const LocationSummary& s, double level) {
    const double half = twoSidedQuantile(level, s.df) * std::sqrt(s.variance);
    // variance 0 (all equal): zero width, not 0 * quantile's rounding.
    if (s.variance == 0.0) return {s.estimate, s.estimate, false};
    return {s.estimate - half, s.estimate + half, false};
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
    // As a double key: a negative n keeps its entries apart from the quantile's.
    const int k =
        int(remembered(level, -double(m), [&] { return double(medianIntervalRank(m, level)); }));
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

}  // namespace mcstat
