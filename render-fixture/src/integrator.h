// Unidirectional path tracer: next-event estimation and BSDF sampling combined by multiple
// importance sampling (power heuristic), unbiased Russian roulette, a hard maximum depth.
#pragma once

#include "accel.h"
#include "bsdf.h"
#include "camera.h"
#include "lights.h"
#include "rng.h"

namespace mcstat::render {

/// The fixture renderer's light-path AOVs (mcstat-render --aovs; docs/aovs.md), named as Arnold
/// names its own. Every contribution to a sample's radiance goes to exactly one of them, so they
/// sum to the beauty sample by sample (up to the rounding of sums in double). The lobe is the
/// first hit's material: diffuse, or specular for mirror and glass; "direct" is light arriving at
/// the first hit straight from an emitter or the background (the light sample there, or the
/// emitter the first bounce found), "indirect" everything after a second hit.
enum LightPathAov {
    kAovEmission,          ///< emitters seen by the camera
    kAovBackground,        ///< the background seen by the camera
    kAovDiffuseDirect,     ///< diffuse first hit, light from an emitter or the background
    kAovDiffuseIndirect,   ///< diffuse first hit, light after more bounces
    kAovSpecularDirect,    ///< mirror or glass first hit, light from an emitter or background
    kAovSpecularIndirect,  ///< mirror or glass first hit, light after more bounces
    kLightPathAovs
};
/// The AOV's name (its channels are NAME.R, NAME.G, NAME.B).
const char* lightPathAovName(int aov);

/// One camera sample: its radiance, the first-hit G-buffer features, and what random parameter
/// filtering (Sen and Darabi 2011, section 3.1) needs besides: the sample's random parameters and
/// the second intersection. Recording them changes neither the random numbers drawn nor L.
struct PathSample {
    Vec3 L;
    Vec3 lightPath[kLightPathAovs];  ///< L split by light path (LightPathAov); sums to L
    bool hit = false;  ///< the camera ray hit geometry (features below are valid only then)
    Vec3 normal, position;
    Vec3 albedo;       ///< textured albedo at the first hit (the "texture value" feature)
    double depth = 0;  ///< distance from the camera (lens point) along the ray

    // Random parameters of the camera sample (set by the caller that draws them).
    double screenX = 0, screenY = 0;  ///< raster position: pixel (x, y) + jitter in [0, 1)^2
    double lensU = 0, lensV = 0;      ///< lens point on the unit disk, in [-1, 1]; 0 without lens
    double time = 0;                  ///< shutter time in [0, 1); 0 when nothing moves
    // Random parameters at the first hit. A number the path did not draw (no light sample or
    // no bounce there, glass's unused second number, a mirror's none, a miss) holds an
    // independent uniform number from a generator of its own (samplePixel): it carries no
    // information about the colour, as an unused input should, so mutual information sees no
    // dependency (a constant 0 would tie "ended at an emitter" to "parameter = 0"). The path's
    // own random numbers and its radiance do not change.
    double lightU = 0, lightV = 0;    ///< the two numbers in [0, 1) that chose the point on the
                                      ///< light for the light sample there
    double bounceU = 0, bounceV = 0;  ///< the numbers in [0, 1) that chose the first bounce there
                                      ///< (diffuse: both; glass: U = reflect/refract choice)
    int lightNumbers = 0;             ///< how many of lightU, lightV the path drew (0 or 2)
    int bounceNumbers = 0;            ///< how many of bounceU, bounceV the path drew (0, 1 or 2)
    // The second intersection: where the first bounce's ray hits (zero when it has none).
    bool hit2 = false;
    Vec3 normal2, position2;  ///< as normal and position, at the second hit
};

class PathIntegrator {
  public:
    PathIntegrator(const Scene& scene, const Accel& accel, const LightSet& lights)
        : scene_(scene), accel_(accel), lights_(lights) {}

    PathSample trace(const Ray& cameraRay, Pcg32& rng) const;

  private:
    /// Light-sampling estimate of direct light at a non-delta vertex, MIS-weighted, the scene at
    /// `time`. `used` receives the light sample drawn (untouched when there are no lights).
    Vec3 sampleDirect(const Bsdf& m, const Hit& hit, const Vec3& wo, double time, Pcg32& rng,
                      LightSample& used) const;

    const Scene& scene_;
    const Accel& accel_;
    const LightSet& lights_;
};

/// Camera sample `index` of pixel (x, y) of an image `width` pixels wide, as every render takes
/// it: a generator seeded by (seed, pixel, index), the camera's numbers first (Camera::sample:
/// jitter, then lens only with a lens, then time only with motion), then the path's.
PathSample samplePixel(const Camera& camera, const PathIntegrator& integrator, int width,
                       uint64_t seed, int x, int y, int64_t index);

/// A renderer's clamp, as Cycles' "Clamp" settings limit a contribution: when the sum of the
/// sample's channel magnitudes |R| + |G| + |B| exceeds `limit`, the sample and its light-path
/// split are scaled by limit / sum, so its hue and the split's sum to it are kept. Cycles clamps
/// direct and indirect light separately; this clamps the whole path sample. Biased by design: the
/// light above the limit is lost. `limit` <= 0 leaves the sample alone, as does a non-finite sum
/// (the film counts and drops such samples; scaling infinity would make a NaN of it).
void clampSample(PathSample& s, double limit);

}  // namespace mcstat::render
