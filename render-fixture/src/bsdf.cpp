#include "bsdf.h"

#include <cmath>

#include "sampling.h"

namespace mcstat::render {

namespace {

Vec3 reflect(const Vec3& wo, const Vec3& n) { return -wo + n * (2 * dot(wo, n)); }

}  // namespace

double fresnelDielectric(double cosI, double etaI, double etaT) {
    const double sinT = etaI / etaT * std::sqrt(std::max(0.0, 1 - cosI * cosI));
    if (sinT >= 1) return 1;
    const double cosT = std::sqrt(std::max(0.0, 1 - sinT * sinT));
    const double rs = (etaI * cosI - etaT * cosT) / (etaI * cosI + etaT * cosT);
    const double rp = (etaT * cosI - etaI * cosT) / (etaT * cosI + etaI * cosT);
    return 0.5 * (rs * rs + rp * rp);
}

bool hasSmoothComponent(const Bsdf& m) {
    return m.type == MaterialType::Diffuse && !isBlack(m.albedo);
}

Vec3 featureAlbedo(const Bsdf& m) { return m.type == MaterialType::Glass ? Vec3(1.0) : m.albedo; }

Vec3 evalBsdfCos(const Bsdf& m, const Vec3& n, const Vec3& wo, const Vec3& wi) {
    if (m.type != MaterialType::Diffuse) return {};
    // Two-sided: light must arrive on the side the viewer is on.
    const double cosO = dot(n, wo), cosI = dot(n, wi);
    if (cosO * cosI <= 0) return {};
    return m.albedo * (std::abs(cosI) / kPi);
}

double pdfBsdf(const Bsdf& m, const Vec3& n, const Vec3& wo, const Vec3& wi) {
    if (m.type != MaterialType::Diffuse) return 0;
    const double cosO = dot(n, wo), cosI = dot(n, wi);
    if (cosO * cosI <= 0) return 0;
    return std::abs(cosI) / kPi;
}

bool sampleBsdf(const Bsdf& m, const Vec3& n, const Vec3& wo, Pcg32& rng, BsdfSample& bs) {
    const double cosO = dot(n, wo);
    if (cosO == 0) return false;
    // The normal on the viewer's side.
    const Vec3 nf = cosO > 0 ? n : -n;
    switch (m.type) {
        case MaterialType::Diffuse: {
            const double u1 = rng.uniform(), u2 = rng.uniform();
            bs.u1 = u1;
            bs.u2 = u2;
            const Vec3 local = sampleCosineHemisphere(u1, u2);
            if (local.z <= 0) return false;
            bs.wi = Frame(nf).toWorld(local);
            bs.pdf = local.z / kPi;
            bs.weight = m.albedo;  // (albedo/pi) * cos / (cos/pi)
            bs.delta = false;
            bs.etaScale = 1;
            return true;
        }
        case MaterialType::Mirror:
            bs.wi = reflect(wo, nf);
            bs.pdf = 0;
            bs.weight = m.albedo;
            bs.delta = true;
            bs.etaScale = 1;
            return true;
        case MaterialType::Glass: {
            // The viewer is outside when wo is on the normal's side (normals point out of solids).
            const bool outside = cosO > 0;
            const double etaI = outside ? 1.0 : m.ior;  // medium wo lies in
            const double etaT = outside ? m.ior : 1.0;  // medium across the boundary
            const double cosI = std::abs(cosO);
            const double F = fresnelDielectric(cosI, etaI, etaT);
            bs.delta = true;
            bs.pdf = 0;
            // Reflect or refract with probabilities F and 1-F: the Fresnel factors cancel.
            bs.u1 = rng.uniform();
            bs.u2 = 0;
            if (bs.u1 < F) {
                bs.wi = reflect(wo, nf);
                bs.weight = Vec3(1.0);
                bs.etaScale = 1;
                return true;
            }
            const double eta = etaI / etaT;
            const double sin2T = eta * eta * (1 - cosI * cosI);
            const double cosT = std::sqrt(std::max(0.0, 1 - sin2T));
            bs.wi = normalize(-wo * eta + nf * (eta * cosI - cosT));
            // Radiance is compressed by (etaI/etaT)^2 crossing into the denser medium as seen from
            // the camera side; the factors cancel over a closed object's way in and out.
            bs.weight = Vec3(eta * eta);
            bs.etaScale = 1 / (eta * eta);
            return true;
        }
    }
    return false;
}

}  // namespace mcstat::render
