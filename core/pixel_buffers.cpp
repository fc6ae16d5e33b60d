// The rule of valid buffers (pixel_buffers.h), shared by every operation over sub-buffers.
#include "mcstat/core/pixel_buffers.h"

#include <cmath>

namespace mcstat {

int collectValidBuffers(const PixelBuffers& px, std::vector<int>& order, int& excluded) {
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
