// Materials as BSDFs: two-sided Lambertian diffuse, smooth dielectric (glass) and perfect mirror.
// Directions point away from the surface: wo toward the viewer, wi toward the light.
#pragma once

#include "mcstat/render-fixture/scene.h"
#include "rng.h"

namespace mcstat::render {

/// A material at one surface point, its texture looked up: what the BSDF functions evaluate.
struct Bsdf {
    MaterialType type = MaterialType::Diffuse;
    Vec3 albedo;  ///< diffuse albedo or mirror reflectance at this point
    double ior = 1.5;
};

/// Material m at world position p (where its texture, if any, is looked up).
inline Bsdf bsdfAt(const Material& m, const Vec3& p) { return {m.type, m.albedoAt(p), m.ior}; }

struct BsdfSample {
    Vec3 wi;
    Vec3 weight;          ///< f * |cos| / pdf: what the path throughput is multiplied by
    double pdf = 0;       ///< solid-angle pdf (meaningless when delta)
    bool delta = false;   ///< specular: no light sampling, emission reached next counts fully
    double etaScale = 1;  ///< squared relative ior crossed: undoes radiance scaling for roulette
    /// The numbers in [0, 1) the sample drew (its random parameters): diffuse, the two of the
    /// cosine-weighted direction; glass, u1 chose reflection or refraction (u2 = 0); mirror, none.
    double u1 = 0, u2 = 0;
};

/// Samples wi for a surface with unit geometric normal n. Returns false if the path ends here.
bool sampleBsdf(const Bsdf& m, const Vec3& n, const Vec3& wo, Pcg32& rng, BsdfSample& bs);

/// f * |cos(n, wi)| for non-delta materials (zero for delta ones): used by light sampling.
Vec3 evalBsdfCos(const Bsdf& m, const Vec3& n, const Vec3& wo, const Vec3& wi);

/// Solid-angle pdf with which sampleBsdf would pick wi (zero for delta materials).
double pdfBsdf(const Bsdf& m, const Vec3& n, const Vec3& wo, const Vec3& wi);

/// Whether light sampling can contribute at all (non-delta and not black).
bool hasSmoothComponent(const Bsdf& m);

/// The G-buffer albedo (textured where the material has a texture): diffuse albedo, mirror
/// reflectance, 1 for glass.
Vec3 featureAlbedo(const Bsdf& m);

/// Unpolarised Fresnel reflectance of a smooth dielectric boundary; 1 under total internal
/// reflection. cosI > 0 is measured on the side with index etaI.
double fresnelDielectric(double cosI, double etaI, double etaT);

}  // namespace mcstat::render
