// Small double-precision 3-vector shared by the scene description and the path tracer.
// Double everywhere on the CPU side: the renderer is a reference, speed matters less than the
// absence of precision surprises; only Embree's rays are float.
#pragma once

#include <algorithm>
#include <cmath>

namespace mcstat::render {

struct Vec3 {
    double x = 0, y = 0, z = 0;
    constexpr Vec3() = default;
    constexpr Vec3(double a, double b, double c) : x(a), y(b), z(c) {}
    constexpr explicit Vec3(double v) : x(v), y(v), z(v) {}
    constexpr double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }

    constexpr Vec3 operator-() const { return {-x, -y, -z}; }
    Vec3& operator+=(const Vec3& o) {
        x += o.x, y += o.y, z += o.z;
        return *this;
    }
    Vec3& operator*=(const Vec3& o) {
        x *= o.x, y *= o.y, z *= o.z;
        return *this;
    }
    Vec3& operator*=(double s) {
        x *= s, y *= s, z *= s;
        return *this;
    }
    Vec3& operator/=(double s) { return *this *= 1.0 / s; }
};

constexpr Vec3 operator+(const Vec3& a, const Vec3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
constexpr Vec3 operator-(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr Vec3 operator*(const Vec3& a, const Vec3& b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
constexpr Vec3 operator*(const Vec3& a, double s) { return {a.x * s, a.y * s, a.z * s}; }
constexpr Vec3 operator*(double s, const Vec3& a) { return a * s; }
constexpr Vec3 operator/(const Vec3& a, double s) { return {a.x / s, a.y / s, a.z / s}; }

constexpr double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double length(const Vec3& a) { return std::sqrt(dot(a, a)); }
inline Vec3 normalize(const Vec3& a) { return a / length(a); }
inline double maxComponent(const Vec3& a) { return std::max(a.x, std::max(a.y, a.z)); }
inline double maxAbs(const Vec3& a) {
    return std::max(std::abs(a.x), std::max(std::abs(a.y), std::abs(a.z)));
}
constexpr bool isBlack(const Vec3& a) { return a.x == 0 && a.y == 0 && a.z == 0; }
inline bool isFinite(const Vec3& a) {
    return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}
/// Rec.709 luminance: used to select lights by power and by the tests.
constexpr double luminance(const Vec3& c) { return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z; }

}  // namespace mcstat::render
