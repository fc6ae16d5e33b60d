// Sampling helpers: warps from the unit square, orthonormal frames, and the MIS power heuristic.
#pragma once

#include <cmath>
#include <utility>

#include "mcstat/render-fixture/vec3.h"

namespace mcstat::render {

inline constexpr double kPi = 3.14159265358979323846;

/// Cosine-weighted direction around +z (Malley's method); pdf = cos(theta) / pi.
inline Vec3 sampleCosineHemisphere(double u1, double u2) {
    const double r = std::sqrt(u1);
    const double phi = 2 * kPi * u2;
    return {r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0, 1 - u1))};
}

/// Shirley and Chiu's concentric map from [0, 1)^2 to the unit disk: uniform over the disk,
/// low distortion; (0.5, 0.5) goes to the centre. Returns (x, y) with x^2 + y^2 <= 1.
inline std::pair<double, double> sampleConcentricDisk(double u1, double u2) {
    const double a = 2 * u1 - 1, b = 2 * u2 - 1;
    if (a == 0 && b == 0) return {0.0, 0.0};
    double r, phi;
    if (std::abs(a) > std::abs(b)) {
        r = a;
        phi = (kPi / 4) * (b / a);
    } else {
        r = b;
        phi = kPi / 2 - (kPi / 4) * (a / b);
    }
    return {r * std::cos(phi), r * std::sin(phi)};
}

/// Uniform direction on the unit sphere; pdf = 1 / (4 pi).
inline Vec3 sampleUniformSphere(double u1, double u2) {
    const double z = 1 - 2 * u1;
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    const double phi = 2 * kPi * u2;
    return {r * std::cos(phi), r * std::sin(phi), z};
}

/// Orthonormal basis around unit n (Duff et al. 2017, branchless): maps local (x, y, z) to world.
struct Frame {
    Vec3 s, t, n;
    explicit Frame(const Vec3& nn) : n(nn) {
        const double sign = std::copysign(1.0, n.z);
        const double a = -1.0 / (sign + n.z);
        const double b = n.x * n.y * a;
        s = {1 + sign * n.x * n.x * a, sign * b, -sign * n.x};
        t = {b, sign + n.y * n.y * a, -n.y};
    }
    Vec3 toWorld(const Vec3& v) const { return s * v.x + t * v.y + n * v.z; }
};

/// Veach's power heuristic (beta = 2) for one sample from each of two strategies: the weight of the
/// strategy with density `pdfA`. An infinite pdfA (cannot happen here) would still give a weight.
inline double powerHeuristic(double pdfA, double pdfB) {
    const double a = pdfA * pdfA, b = pdfB * pdfB;
    return a + b > 0 ? a / (a + b) : 0.0;
}

}  // namespace mcstat::render
