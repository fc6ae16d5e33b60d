#include "integrator.h"

#include <cmath>

#include "bsdf.h"
#include "sampling.h"

namespace mcstat::render {

namespace {

/// Where a hit's texture is looked up: the hit point, except that on a quad perpendicular to an
/// axis the coordinate along that axis is the plane's exactly. Otherwise rounding would put hits
/// on a plane lying on a checker cell boundary (a floor at y = 0) randomly on either side.
Vec3 texturePoint(const Shape& s, const Vec3& p, double time) {
    if (s.type != ShapeType::Quad) return p;
    const Vec3 n = cross(s.edge1, s.edge2);
    const Vec3 corner = s.moving() ? s.corner + s.velocity * time : s.corner;
    Vec3 q = p;
    if (n.y == 0 && n.z == 0) q.x = corner.x;
    if (n.x == 0 && n.z == 0) q.y = corner.y;
    if (n.x == 0 && n.y == 0) q.z = corner.z;
    return q;
}

}  // namespace

const char* lightPathAovName(int aov) {
    static const char* const kNames[kLightPathAovs] = {"emission",        "background",
                                                       "diffuse_direct",  "diffuse_indirect",
                                                       "specular_direct", "specular_indirect"};
    return aov >= 0 && aov < kLightPathAovs ? kNames[aov] : "";
}

Vec3 PathIntegrator::sampleDirect(const Bsdf& m, const Hit& hit, const Vec3& wo, double time,
                                  Pcg32& rng, LightSample& ls) const {
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
    if (segLen > 0 && dot(seg, wi) > 0 && accel_.occluded(from, seg / segLen, segLen, time))
        return {};
    const double w = powerHeuristic(pdfLight, pdfBsdf(m, hit.n, wo, wi));
    return f * Le * (w / pdfLight);
}

namespace {

/// The features of the path's first hit (normal, position, distance, albedo) and second hit
/// (normal, position) at vertex `depth`, which the feature buffers store.
void recordHitFeatures(PathSample& out, int depth, const Hit& hit, const Material* mat,
                       const Bsdf& bsdf) {
    if (depth == 0) {
        out.hit = true;
        out.normal = hit.n;
        out.position = hit.p;
        out.depth = hit.t;
        out.albedo = mat ? featureAlbedo(bsdf) : Vec3();
    } else if (depth == 1) {
        out.hit2 = true;
        out.normal2 = hit.n;
        out.position2 = hit.p;
    }
}

}  // namespace

PathSample PathIntegrator::trace(const Ray& cameraRay, Pcg32& rng) const {
    PathSample out;
    Ray ray = cameraRay;
    Vec3 beta(1.0);
    bool specular = true;  // the camera "bounce" is a delta event: emission seen first counts fully
    double prevPdf = 0;    // solid-angle pdf of the BSDF sample that produced `ray`
    Vec3 prevP;            // the vertex `ray` left (for the light pdf of MIS)
    double etaScale = 1;
    // Which light-path AOV a contribution found at `depth` belongs to (LightPathAov): the
    // emitter or background seen first, then by the first hit's lobe, direct for the light
    // sample at the first hit and what its bounce finds, indirect for everything later. L is
    // summed exactly as without AOVs, so the beauty does not change.
    bool specularLobe = false;
    auto add = [&](const Vec3& c, int depth, bool lightSample, bool background) {
        out.L += c;
        int aov = 0;
        if (depth == 0 && !lightSample)
            aov = background ? kAovBackground : kAovEmission;
        else if ((depth == 0 && lightSample) || (depth == 1 && !lightSample))
            aov = specularLobe ? kAovSpecularDirect : kAovDiffuseDirect;
        else
            aov = specularLobe ? kAovSpecularIndirect : kAovDiffuseIndirect;
        out.lightPath[aov] += c;
    };

    for (int depth = 0;; ++depth) {
        Hit hit;
        if (!accel_.intersect(ray, hit)) {
            // No environment sampling exists, so BSDF sampling is the only strategy: weight 1.
            add(beta * scene_.background, depth, false, true);
            break;
        }
        const Shape& shape = scene_.shapes[size_t(hit.shape)];
        const Material* mat =
            shape.material >= 0 ? &scene_.materials[size_t(shape.material)] : nullptr;
        // The material here, its texture looked up at this point (at the path's time).
        const Bsdf bsdf = mat ? bsdfAt(*mat, texturePoint(shape, hit.p, ray.time)) : Bsdf{};
        recordHitFeatures(out, depth, hit, mat, bsdf);
        if (depth == 0) specularLobe = mat && bsdf.type != MaterialType::Diffuse;
        const Vec3 wo = -ray.d;

        const Vec3 Le = lights_.emitted(hit.shape, hit.n, wo);
        if (!isBlack(Le)) {
            if (specular) {
                add(beta * Le, depth, false, false);
            } else {
                const double pdfLight = lights_.pdfSolidAngle(hit.shape, prevP, hit.p, hit.n);
                add(beta * Le * powerHeuristic(prevPdf, pdfLight), depth, false, false);
            }
        }
        if (depth == scene_.maxDepth || !mat) break;

        if (hasSmoothComponent(bsdf)) {
            LightSample ls;
            add(beta * sampleDirect(bsdf, hit, wo, ray.time, rng, ls), depth, true, false);
            if (depth == 0 && ls.shape >= 0) {
                out.lightU = ls.u1, out.lightV = ls.u2;
                out.lightNumbers = 2;
            }
        }

        BsdfSample bs;
        const bool bounced = sampleBsdf(bsdf, hit.n, wo, rng, bs);
        if (depth == 0) {
            out.bounceU = bs.u1, out.bounceV = bs.u2;
            out.bounceNumbers = bsdf.type == MaterialType::Diffuse ? 2
                                : bsdf.type == MaterialType::Glass ? 1
                                                                   : 0;
        }
        if (!bounced) break;
        beta *= bs.weight;
        if (isBlack(beta)) break;
        etaScale *= bs.etaScale;
        specular = bs.delta;
        prevPdf = bs.pdf;
        prevP = hit.p;
        ray = {offsetOrigin(hit.p, hit.n, bs.wi), bs.wi, ray.time};

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

PathSample samplePixel(const Camera& camera, const PathIntegrator& integrator, int width,
                       uint64_t seed, int x, int y, int64_t index) {
    const uint64_t pixel = uint64_t(y) * uint64_t(width) + uint64_t(x);
    Pcg32 rng = sampleRng(seed, pixel, uint64_t(index));
    const CameraSample cs = camera.sample(x, y, rng);
    PathSample s = integrator.trace(camera.generateRay(cs), rng);
    s.screenX = cs.screenX, s.screenY = cs.screenY;
    s.lensU = cs.lensU, s.lensV = cs.lensV;
    s.time = cs.time;
    // Numbers the path did not draw: independent uniforms from a generator of their own (see
    // PathSample), seeded apart from the path's so that the path is unchanged.
    if (s.lightNumbers < 2 || s.bounceNumbers < 2) {
        Pcg32 filler = sampleRng(~seed, pixel, uint64_t(index));
        const double u[4] = {filler.uniform(), filler.uniform(), filler.uniform(),
                             filler.uniform()};
        if (s.lightNumbers < 2) s.lightU = u[0], s.lightV = u[1];
        if (s.bounceNumbers < 1) s.bounceU = u[2];
        if (s.bounceNumbers < 2) s.bounceV = u[3];
    }
    return s;
}

void clampSample(PathSample& s, double limit) {
    if (!(limit > 0.0)) return;
    const double sum = std::abs(s.L[0]) + std::abs(s.L[1]) + std::abs(s.L[2]);
    if (!std::isfinite(sum) || sum <= limit) return;
    const double scale = limit / sum;
    s.L = s.L * scale;
    for (Vec3& part : s.lightPath) part = part * scale;
}

}  // namespace mcstat::render
