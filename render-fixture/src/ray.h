// A ray with unit direction, and the offset that keeps secondary rays off the surface they leave.
#pragma once

#include "mcstat/render-fixture/vec3.h"

namespace mcstat::render {

struct Ray {
    Vec3 o, d;        ///< origin, unit direction
    double time = 0;  ///< shutter time in [0, 1): where moving shapes are (0 without motion)
};

/// Moves p off its surface (geometric normal n) to the side `dir` points to. Embree works in float,
/// so the offset scales with the coordinates' magnitude to stay above float rounding.
inline Vec3 offsetOrigin(const Vec3& p, const Vec3& n, const Vec3& dir) {
    const double eps = 1e-4 * (1.0 + maxAbs(p));
    return p + n * (dot(n, dir) > 0 ? eps : -eps);
}

}  // namespace mcstat::render
