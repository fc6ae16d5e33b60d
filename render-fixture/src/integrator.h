// Unidirectional path tracer: next-event estimation and BSDF sampling combined by multiple
// importance sampling (power heuristic), unbiased Russian roulette, a hard maximum depth.
#pragma once

#include "accel.h"
#include "lights.h"
#include "rng.h"

namespace mcstat::render {

/// One camera sample: its radiance and the first-hit G-buffer features.
struct PathSample {
    Vec3 L;
    bool hit = false;  ///< the camera ray hit geometry (features below are valid only then)
    Vec3 normal, position, albedo;
    double depth = 0;  ///< distance from the camera along the ray
};

class PathIntegrator {
  public:
    PathIntegrator(const Scene& scene, const Accel& accel, const LightSet& lights)
        : scene_(scene), accel_(accel), lights_(lights) {}

    PathSample trace(const Ray& cameraRay, Pcg32& rng) const;

  private:
    /// Light-sampling estimate of direct light at a non-delta vertex, MIS-weighted.
    Vec3 sampleDirect(const Material& m, const Hit& hit, const Vec3& wo, Pcg32& rng) const;

    const Scene& scene_;
    const Accel& accel_;
    const LightSet& lights_;
};

}  // namespace mcstat::render
