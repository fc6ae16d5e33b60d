// Embree 3 geometry for a Scene: one Embree geometry per shape (quads as RTC quads, spheres as
// RTC_GEOMETRY_TYPE_SPHERE_POINT), so the hit's geomID is the shape index. Hit points and normals
// are recomputed in double from the shape, Embree only decides which shape is hit and roughly
// where. A moving shape has two time steps (its position at time 0 and translated by its velocity
// at time 1), which Embree interpolates linearly at the ray's time.
#pragma once

#include <embree3/rtcore.h>

#include <string>

#include "mcstat/render-fixture/scene.h"
#include "ray.h"

namespace mcstat::render {

struct Hit {
    double t = 0;    ///< distance along the (unit) ray
    int shape = -1;  ///< index into Scene::shapes
    Vec3 p;          ///< hit point
    Vec3 n;          ///< unit geometric normal as the shape defines it (not flipped toward the ray)
};

class Accel {
  public:
    Accel() = default;
    ~Accel();
    Accel(const Accel&) = delete;
    Accel& operator=(const Accel&) = delete;

    bool build(const Scene& scene, std::string& err);
    /// Closest hit with t in (0, inf), the shapes placed at ray.time. Thread-safe after build.
    bool intersect(const Ray& ray, Hit& hit) const;
    /// True when something lies on the ray within (0, tMax), the shapes placed at `time`.
    bool occluded(const Vec3& o, const Vec3& d, double tMax, double time = 0) const;

  private:
    const Scene* scene_ = nullptr;
    RTCDevice device_ = nullptr;
    RTCScene rtcScene_ = nullptr;
};

}  // namespace mcstat::render
