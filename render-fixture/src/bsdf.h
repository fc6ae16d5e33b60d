// Materials as BSDFs: two-sided Lambertian diffuse, smooth dielectric (glass) and perfect mirror.
// Directions point away from the surface: wo toward the viewer, wi toward the light.
#pragma once

#include "mcstat/render/scene.h"
#include "rng.h"

namespace mcstat::render {

struct BsdfSample {
    Vec3 wi;
    Vec3 weight;          ///< f * |cos| / pdf: what the path throughput is multiplied by
    double pdf = 0;       ///< solid-angle pdf (meaningless when delta)
    bool delta = false;   ///< specular: no light sampling, emission reached next counts fully
    double etaScale = 1;  ///< squared relative ior crossed: undoes radiance scaling for roulette
};

/// Samples wi for a surface with unit geometric normal n. Returns false if the path ends here.
bool sampleBsdf(const Material& m, const Vec3& n, const Vec3& wo, Pcg32& rng, BsdfSample& bs);

/// f * |cos(n, wi)| for non-delta materials (zero for delta ones): used by light sampling.
Vec3 evalBsdfCos(const Material& m, const Vec3& n, const Vec3& wo, const Vec3& wi);

/// Solid-angle pdf with which sampleBsdf would pick wi (zero for delta materials).
double pdfBsdf(const Material& m, const Vec3& n, const Vec3& wo, const Vec3& wi);

/// Whether light sampling can contribute at all (non-delta and not black).
bool hasSmoothComponent(const Material& m);

/// The G-buffer albedo: diffuse albedo, mirror reflectance, 1 for glass.
Vec3 featureAlbedo(const Material& m);

/// Unpolarised Fresnel reflectance of a smooth dielectric boundary; 1 under total internal
/// reflection. cosI > 0 is measured on the side with index etaI.
double fresnelDielectric(double cosI, double etaI, double etaT);

}  // namespace mcstat::render
