#include "lights.h"

#include <algorithm>
#include <cmath>

#include "sampling.h"

namespace mcstat::render {

namespace {

double shapeArea(const Shape& s) {
    if (s.type == ShapeType::Sphere) return 4 * kPi * s.radius * s.radius;
    return length(cross(s.edge1, s.edge2));
}

}  // namespace

LightSet::LightSet(const Scene& scene) : scene_(scene), shapePdfArea_(scene.shapes.size(), 0.0) {
    std::vector<double> power;
    double total = 0;
    for (size_t i = 0; i < scene.shapes.size(); ++i) {
        const Shape& s = scene.shapes[i];
        // Luminance * area is proportional to emitted power for both kinds of emitter (the
        // factor pi of a one-sided Lambertian emitter is common to all, a sphere's two sides count
        // once: only one side is ever seen from outside).
        const double w = luminance(s.emission) * shapeArea(s);
        if (!(w > 0)) continue;
        lights_.push_back(int(i));
        power.push_back(w);
        total += w;
    }
    double acc = 0;
    for (size_t k = 0; k < lights_.size(); ++k) {
        const double sel = power[k] / total;
        acc += sel;
        cdf_.push_back(acc);
        shapePdfArea_[size_t(lights_[k])] = sel / shapeArea(scene.shapes[size_t(lights_[k])]);
    }
    if (!cdf_.empty()) cdf_.back() = 1.0;
}

bool LightSet::sample(Pcg32& rng, LightSample& ls) const {
    if (lights_.empty()) return false;
    const double u = rng.uniform();
    const size_t k = size_t(std::upper_bound(cdf_.begin(), cdf_.end(), u) - cdf_.begin());
    const int shape = lights_[std::min(k, lights_.size() - 1)];
    const Shape& s = scene_.shapes[size_t(shape)];
    const double u1 = rng.uniform(), u2 = rng.uniform();
    if (s.type == ShapeType::Sphere) {
        // Uniform over the whole sphere: the inside of an emissive sphere sees all of it; from
        // outside, the far half is wasted (occluded) but the estimate stays unbiased.
        ls.n = sampleUniformSphere(u1, u2);
        ls.p = s.center + ls.n * s.radius;
    } else {
        ls.p = s.corner + s.edge1 * u1 + s.edge2 * u2;
        ls.n = normalize(cross(s.edge1, s.edge2));
    }
    ls.shape = shape;
    ls.u1 = u1;
    ls.u2 = u2;
    ls.pdfArea = shapePdfArea_[size_t(shape)];
    return true;
}

double LightSet::pdfSolidAngle(int shape, const Vec3& ref, const Vec3& p, const Vec3& n) const {
    const double pa = shapePdfArea_[size_t(shape)];
    if (pa == 0) return 0;
    const Vec3 d = p - ref;
    const double dist2 = dot(d, d);
    const double cosL = std::abs(dot(n, d)) / std::sqrt(dist2);
    if (cosL <= 0) return 0;
    return pa * dist2 / cosL;
}

Vec3 LightSet::emitted(int shape, const Vec3& n, const Vec3& w) const {
    const Shape& s = scene_.shapes[size_t(shape)];
    if (s.type == ShapeType::Quad && dot(n, w) <= 0) return {};
    return s.emission;
}

}  // namespace mcstat::render
