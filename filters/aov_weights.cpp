// The shared step that carries AOVs through every operation (include/mcstat/filters/aov_weights.h).
#include "mcstat/filters/aov_weights.h"

#include <cmath>

namespace mcstat {

void applyAovWeights(const double* weight, size_t n, const float* aov, size_t A,
                     const AovClass* cls, float* out, AovScratch& s) {
    if (A == 0) return;
    s.sum.assign(A, 0.0);
    s.weight.assign(A, 0.0);
    size_t best = 0;  // input of largest weight, lowest index on ties (id channels)
    for (size_t i = 0; i < n; ++i) {
        const double w = weight[i];
        if (w > weight[best]) best = i;
        if (!(w > 0.0)) continue;
        const float* x = aov + i * A;
        for (size_t a = 0; a < A; ++a) {
            const double v = x[a];
            if (!std::isfinite(v)) continue;  // left out of this channel alone
            s.sum[a] += w * v;
            s.weight[a] += w;
        }
    }
    for (size_t a = 0; a < A; ++a) {
        if (cls[a] == AovClass::Id) {
            out[a] = n > 0 ? aov[best * A + a] : 0.f;
            continue;
        }
        const double w = s.weight[a];
        if (!(w > 0.0)) {
            out[a] = 0.f;
            continue;
        }
        // Every channel of a pixel whose values are all finite is divided by the same sum of
        // weights, so linear relations between channels hold to rounding.
        out[a] = float(s.sum[a] / w);
    }
}

std::vector<AovClass> aovClasses(const std::vector<AovChannel>& aovs) {
    std::vector<AovClass> out;
    out.reserve(aovs.size());
    for (const AovChannel& c : aovs) out.push_back(c.cls);
    return out;
}

}  // namespace mcstat
