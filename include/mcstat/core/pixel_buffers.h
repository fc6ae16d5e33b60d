// One pixel's sub-buffers as every per-pixel operation takes them: the view the statistics file
// (exr-deep) hands out and the estimators (filters/pixel) read, and the rule of valid buffers
// every operation over them shares. A core type: it depends on nothing.
#pragma once

#include <cmath>
#include <vector>

namespace mcstat {

/// One pixel's sub-buffers: M means (RGB interleaved) and M counts.
struct PixelBuffers {
    const float* mean = nullptr;   ///< [j*3 + c]
    const float* count = nullptr;  ///< [j]
    int M = 0;
};

/// Fills `order` with the indices of the valid buffers (count > 0, count and every channel finite),
/// in index order, and sets `excluded` to the number of NaN/Inf buffers. Returns M_v.
inline int collectValidBuffers(const PixelBuffers& px, std::vector<int>& order, int& excluded) {
    order.clear();
    excluded = 0;
    for (int j = 0; j < px.M; ++j) {
        const float n = px.count[j];
        const float* m = px.mean + 3 * j;
        if (!std::isfinite(n) || n < 0.f || !std::isfinite(m[0]) || !std::isfinite(m[1]) ||
            !std::isfinite(m[2])) {
            ++excluded;
            continue;
        }
        if (n == 0.f) continue;  // empty buffer (spp < M): no information, not an error
        order.push_back(j);
    }
    return int(order.size());
}

}  // namespace mcstat
