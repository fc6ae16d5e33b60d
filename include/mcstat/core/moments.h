// The one variance accumulator: a running mean and sum of squared deviations, updated one value at
// a time (Welford 1962: numerically stable even when the mean dwarfs the spread) and pooled
// exactly (Chan, Golub and LeVeque 1979), so that a statistics file's moments, their merge across
// seeds and the renderer's and the online operations' running statistics all agree in one
// arithmetic. Header only: it sits in the innermost loops.
#pragma once

#include <cmath>
#include <cstdint>

namespace mcstat {

struct RunningMoments {
    double n = 0.0;     ///< values (a count; double so that counts beyond 2^53 stay ordered)
    double mean = 0.0;  ///< their mean
    double m2 = 0.0;    ///< sum of squared deviations from the mean

    /// The moments of `count` values of this mean and unbiased variance (how a file stores them).
    static RunningMoments fromVariance(double count, double mean, double variance) {
        return {count, mean, count > 1.0 ? variance * (count - 1.0) : 0.0};
    }

    /// Welford's update.
    void add(double x) {
        n += 1.0;
        const double d = x - mean;
        mean += d / n;
        m2 += d * (x - mean);
    }

    /// Chan et al.'s pooling: the moments of both sets of values. An empty side leaves the other
    /// as it is.
    void merge(const RunningMoments& o) {
        if (o.n == 0.0) return;
        if (n == 0.0) {
            *this = o;
            return;
        }
        const double total = n + o.n;
        const double delta = o.mean - mean;
        mean = mean + delta * (o.n / total);
        m2 = m2 + o.m2 + delta * delta * (n * o.n / total);
        n = total;
    }

    /// The unbiased variance; 0 with fewer than two values.
    double variance() const { return n > 1.0 ? m2 / (n - 1.0) : 0.0; }
    /// Its square root.
    double sigma() const { return std::sqrt(variance()); }
};

}  // namespace mcstat
