// One pixel's sub-buffers as every per-pixel operation takes them: the view the statistics file
// (exr-deep) hands out and the estimators (filters/pixel) read. A core type: it depends on nothing.
#pragma once

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
int collectValidBuffers(const PixelBuffers& px, std::vector<int>& order, int& excluded);

}  // namespace mcstat
