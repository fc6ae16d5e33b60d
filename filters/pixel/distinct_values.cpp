// What the M-estimators share: distinct values, their weights and scale (distinct_values.h).
#include "distinct_values.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "mcstat/core/colour_space.h"
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

double scaleFor(double factor, bool relative, const EstimatorScratch& s, int K) {
    return relative ? factor * (s.sorted[size_t(K) - 1] - s.sorted[0]) : factor;
}

void setKeys(const PixelBuffers& px, const PixelParams& p, EstimatorScratch& s, int ch) {
    for (int j : s.order) {
        const float* m = px.mean + 3 * j;
        s.key[j] = ch < 0 ? luminance(p.luma, m) : double(m[ch]);
    }
}

}  // namespace mcstat::detail
