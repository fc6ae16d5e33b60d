// What the M-estimators share: distinct values, their weights and scale (distinct_values.h).
#include "distinct_values.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "mcstat/core/color_space.h"
#include "mcstat/filters/pixel/detail/rank_keys.h"
#include "mcstat/filters/pixel/ranking.h"

namespace mcstat::detail {

namespace {

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

}  // namespace

bool clearlyLess(double a, double b) {
    return a < b - 1e-12 * std::max(std::fabs(a), std::fabs(b));
}

double saneScale(double scale) {
    if (!(scale > 0.0)) return std::numeric_limits<double>::min();
    if (!std::isfinite(scale)) return std::numeric_limits<double>::max();
    return scale;
}

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

double hampelRange(const EstimatorScratch& s) {
    const size_t n = s.order.size();
    if (n < 2) return 0.0;
    auto key = [&s](size_t r) { return s.key[size_t(s.order[r])]; };  // rank r's key
    // The median of the ranked keys, then the median of the absolute deviations from it.
    const double med = n % 2 == 1 ? key(n / 2) : 0.5 * (key(n / 2 - 1) + key(n / 2));
    thread_local std::vector<double> dev;
    dev.resize(n);
    for (size_t r = 0; r < n; ++r) dev[r] = std::fabs(key(r) - med);
    std::nth_element(dev.begin(), dev.begin() + long(n / 2), dev.end());
    const double upper = dev[n / 2];
    // Even n: the lower middle value is the largest of the n / 2 below the upper one.
    const double mad =
        n % 2 == 1 ? upper
                   : 0.5 * (*std::max_element(dev.begin(), dev.begin() + long(n / 2)) + upper);
    // Hampel's identifier: 1.4826 MAD estimates a normal sigma; 3 sigma is its fence.
    const double fence = 3.0 * 1.4826 * mad;
    size_t lo = 0, hi = n - 1;
    while (lo < hi && !(std::fabs(key(lo) - med) <= fence)) ++lo;
    while (hi > lo && !(std::fabs(key(hi) - med) <= fence)) --hi;
    return key(hi) - key(lo);
}

double scaleFor(double factor, ScaleRule rule, const EstimatorScratch& s, int K) {
    switch (rule) {
        case ScaleRule::Hampel: {
            const double fenced = hampelRange(s);
            if (fenced > 0.0 || K < 2) return factor * fenced;
            // MAD 0: more than half of the buffers share one value, and the scale is 0, the
            // selection limit (that value). In arithmetic: 1e-300 x the whole range, so that every
            // |x_j - beta| / scale stays finite (an infinite ratio would make the myriad's step
            // 0 x inf) while two distinct float channel values, at least 1e-45 apart, are still
            // >= 1e-45 / (3.4e38 x 1e-300) ~ 3e216 scales apart: a weight below 1e-433, 0 in
            // double.
            return 1e-300 * (s.sorted[size_t(K) - 1] - s.sorted[0]);
        }
        case ScaleRule::Range:
            return factor * (s.sorted[size_t(K) - 1] - s.sorted[0]);
        case ScaleRule::Absolute:
            break;
    }
    return factor;
}

void setKeys(const PixelBuffers& px, const PixelParams& p, EstimatorScratch& s, int ch) {
    for (int j : s.order) {
        const float* m = px.mean + 3 * j;
        s.key[j] = ch < 0 ? luminance(p.luma, m) : double(m[ch]);
    }
}

}  // namespace mcstat::detail
