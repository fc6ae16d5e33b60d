#include "accel.h"

#include <cmath>
#include <limits>

namespace mcstat::render {

namespace {

void setRay(RTCRay& r, const Vec3& o, const Vec3& d, double tMax, double time) {
    r.org_x = float(o.x), r.org_y = float(o.y), r.org_z = float(o.z);
    r.dir_x = float(d.x), r.dir_y = float(d.y), r.dir_z = float(d.z);
    r.tnear = 0.0f;
    r.tfar = float(tMax);
    r.time = float(time);
    r.mask = ~0u;
    r.id = 0;
    r.flags = 0;
}

}  // namespace

Accel::~Accel() {
    if (rtcScene_) rtcReleaseScene(rtcScene_);
    if (device_) rtcReleaseDevice(device_);
}

bool Accel::build(const Scene& scene, std::string& err) {
    scene_ = &scene;
    device_ = rtcNewDevice(nullptr);
    if (!device_) {
        err = "cannot create the Embree device (error " +
              std::to_string(int(rtcGetDeviceError(nullptr))) + ")";
        return false;
    }
    rtcScene_ = rtcNewScene(device_);
    // Robust traversal: the furnace camera sits inside a sphere and paths graze quad edges; the
    // default fast mode may miss such hits, which would leak energy.
    rtcSetSceneFlags(rtcScene_, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(rtcScene_, RTC_BUILD_QUALITY_HIGH);

    for (size_t i = 0; i < scene.shapes.size(); ++i) {
        const Shape& s = scene.shapes[i];
        RTCGeometry geom = nullptr;
        // A static shape has one time step; a moving one two: slot 0 at time 0, slot 1 at time 1.
        const unsigned steps = s.moving() ? 2u : 1u;
        if (s.type == ShapeType::Sphere) {
            geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_SPHERE_POINT);
            if (steps > 1) rtcSetGeometryTimeStepCount(geom, steps);
            for (unsigned slot = 0; slot < steps; ++slot) {
                auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
                    geom, RTC_BUFFER_TYPE_VERTEX, slot, RTC_FORMAT_FLOAT4, 4 * sizeof(float), 1));
                const Vec3 c = slot == 0 ? s.center : s.center + s.velocity;
                v[0] = float(c.x), v[1] = float(c.y), v[2] = float(c.z);
                v[3] = float(s.radius);
            }
        } else {
            geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_QUAD);
            if (steps > 1) rtcSetGeometryTimeStepCount(geom, steps);
            for (unsigned slot = 0; slot < steps; ++slot) {
                auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
                    geom, RTC_BUFFER_TYPE_VERTEX, slot, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 4));
                const Vec3 o = slot == 0 ? s.corner : s.corner + s.velocity;
                const Vec3 c[4] = {o, o + s.edge1, o + s.edge1 + s.edge2, o + s.edge2};
                for (int k = 0; k < 4; ++k) {
                    v[3 * k + 0] = float(c[k].x), v[3 * k + 1] = float(c[k].y);
                    v[3 * k + 2] = float(c[k].z);
                }
            }
            auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
                geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 4 * sizeof(unsigned), 1));
            idx[0] = 0, idx[1] = 1, idx[2] = 2, idx[3] = 3;
        }
        rtcCommitGeometry(geom);
        // Attached in order to a fresh scene, so geomID == shape index.
        rtcAttachGeometryByID(rtcScene_, geom, unsigned(i));
        rtcReleaseGeometry(geom);
    }
    rtcCommitScene(rtcScene_);
    const RTCError e = rtcGetDeviceError(device_);
    if (e != RTC_ERROR_NONE) {
        err = scene.source + ": Embree failed to build the scene (error " + std::to_string(int(e)) +
              ")";
        return false;
    }
    return true;
}

bool Accel::intersect(const Ray& ray, Hit& hit) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    setRay(rh.ray, ray.o, ray.d, std::numeric_limits<double>::infinity(), ray.time);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(rtcScene_, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;

    const Shape& s = scene_->shapes[rh.hit.geomID];
    hit.shape = int(rh.hit.geomID);
    hit.t = rh.ray.tfar;
    // Where a moving shape is at the ray's time (translation only: normals do not change).
    const bool moving = s.moving();
    if (s.type == ShapeType::Sphere) {
        const Vec3 center = moving ? s.center + s.velocity * ray.time : s.center;
        // Refine in double: of the two roots, take the one nearest Embree's float answer.
        const Vec3 oc = ray.o - center;
        const double b = dot(oc, ray.d);
        const double c = dot(oc, oc) - s.radius * s.radius;
        const double disc = b * b - c;
        if (disc >= 0) {
            const double sq = std::sqrt(disc);
            const double t0 = -b - sq, t1 = -b + sq;
            const double best = std::abs(t0 - hit.t) <= std::abs(t1 - hit.t) ? t0 : t1;
            if (best > 0) hit.t = best;
        }
        hit.p = ray.o + ray.d * hit.t;
        hit.n = normalize(hit.p - center);
    } else {
        const Vec3 n = normalize(cross(s.edge1, s.edge2));
        const Vec3 corner = moving ? s.corner + s.velocity * ray.time : s.corner;
        // Exact plane intersection in double (the ray is known to cross the quad here).
        const double denom = dot(n, ray.d);
        if (denom != 0) {
            const double t = dot(corner - ray.o, n) / denom;
            if (t > 0) hit.t = t;
        }
        hit.p = ray.o + ray.d * hit.t;
        hit.n = n;
    }
    return true;
}

bool Accel::occluded(const Vec3& o, const Vec3& d, double tMax, double time) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRay r;
    setRay(r, o, d, tMax, time);
    rtcOccluded1(rtcScene_, &ctx, &r);
    return r.tfar < 0;  // Embree sets tfar = -inf when it finds an occluder
}

}  // namespace mcstat::render
