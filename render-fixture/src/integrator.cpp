#include "integrator.h"

#include <cmath>

#include "bsdf.h"
#include "sampling.h"

namespace mcstat::render {

Vec3 PathIntegrator::sampleDirect(const Material& m, const Hit& hit, const Vec3& wo,
                                  Pcg32& rng) const {
    LightSample ls;
    if (!lights_.sample(rng, ls)) return {};
    const Vec3 d = ls.p - hit.p;
    const double dist2 = dot(d, d);
    if (!(dist2 > 0)) return {};
    const double dist = std::sqrt(dist2);
    const Vec3 wi = d / dist;
    const Vec3 Le = lights_.emitted(ls.shape, ls.n, -wi);
    if (isBlack(Le)) return {};
    const Vec3 f = evalBsdfCos(m, hit.n, wo, wi);
    if (isBlack(f)) return {};
    const double cosL = std::abs(dot(ls.n, wi));
    if (cosL <= 0) return {};
    const double pdfLight = ls.pdfArea * dist2 / cosL;
    // Shadow ray between the two offset end points, so neither surface occludes itself.
    const Vec3 from = offsetOrigin(hit.p, hit.n, wi);
    const Vec3 to = offsetOrigin(ls.p, ls.n, -wi);
    const Vec3 seg = to - from;
    const double segLen = length(seg);
    if (segLen > 0 && dot(seg, wi) > 0 && accel_.occluded(from, seg / segLen, segLen)) return {};
    const double w = powerHeuristic(pdfLight, pdfBsdf(m, hit.n, wo, wi));
    return f * Le * (w / pdfLight);
}

PathSample PathIntegrator::trace(const Ray& cameraRay, Pcg32& rng) const {
    PathSample out;
    Ray ray = cameraRay;
    Vec3 beta(1.0);
    bool specular = true;  // the camera "bounce" is a delta event: emission seen first counts fully
    double prevPdf = 0;    // solid-angle pdf of the BSDF sample that produced `ray`
    Vec3 prevP;            // the vertex `ray` left (for the light pdf of MIS)
    double etaScale = 1;

    for (int depth = 0;; ++depth) {
        Hit hit;
        if (!accel_.intersect(ray, hit)) {
            // No environment sampling exists, so BSDF sampling is the only strategy: weight 1.
            out.L += beta * scene_.background;
            break;
        }
        const Shape& shape = scene_.shapes[size_t(hit.shape)];
        const Material* mat =
            shape.material >= 0 ? &scene_.materials[size_t(shape.material)] : nullptr;
        if (depth == 0) {
            out.hit = true;
            out.normal = hit.n;
            out.position = hit.p;
            out.depth = hit.t;
            out.albedo = mat ? featureAlbedo(*mat) : Vec3();
        }
        const Vec3 wo = -ray.d;

        const Vec3 Le = lights_.emitted(hit.shape, hit.n, wo);
        if (!isBlack(Le)) {
            if (specular) {
                out.L += beta * Le;
            } else {
                const double pdfLight = lights_.pdfSolidAngle(hit.shape, prevP, hit.p, hit.n);
                out.L += beta * Le * powerHeuristic(prevPdf, pdfLight);
            }
        }
        if (depth == scene_.maxDepth || !mat) break;

        if (hasSmoothComponent(*mat)) out.L += beta * sampleDirect(*mat, hit, wo, rng);

        BsdfSample bs;
        if (!sampleBsdf(*mat, hit.n, wo, rng, bs)) break;
        beta *= bs.weight;
        if (isBlack(beta)) break;
        etaScale *= bs.etaScale;
        specular = bs.delta;
        prevPdf = bs.pdf;
        prevP = hit.p;
        ray = {offsetOrigin(hit.p, hit.n, bs.wi), bs.wi};

        // Russian roulette on the throughput without the radiance scaling of refraction (which
        // cancels on leaving the object): survive with probability min(1, max component), and
        // divide by it so the estimator stays unbiased.
        if (depth + 1 >= scene_.rrDepth) {
            const double survive = maxComponent(beta * etaScale);
            if (survive < 1) {
                if (rng.uniform() >= survive) break;
                beta /= survive;
            }
        }
    }
    return out;
}

}  // namespace mcstat::render
