#include "camera.h"

#include <cmath>

#include "sampling.h"

namespace mcstat::render {

Camera::Camera(const CameraDesc& desc, int width, int height, bool motion)
    : origin_(desc.position),
      invWidth_(1.0 / width),
      invHeight_(1.0 / height),
      tanHalfFov_(std::tan(desc.fovDeg * kPi / 360.0)),
      aspect_(double(width) / height),
      aperture_(desc.aperture),
      focusDistance_(desc.focusDistance > 0 ? desc.focusDistance
                                            : length(desc.lookAt - desc.position)),
      motion_(motion) {
    // Right-handed: the camera looks down -z of its own frame, like OpenGL and pbrt's LookAt.
    forward_ = normalize(desc.lookAt - desc.position);
    right_ = normalize(cross(forward_, desc.up));
    up_ = cross(right_, forward_);
}

CameraSample Camera::sample(int x, int y, Pcg32& rng) const {
    CameraSample cs;
    const double jx = rng.uniform(), jy = rng.uniform();
    cs.screenX = x + jx;
    cs.screenY = y + jy;
    if (hasLens()) {
        const double u1 = rng.uniform(), u2 = rng.uniform();
        const auto [du, dv] = sampleConcentricDisk(u1, u2);
        cs.lensU = du;
        cs.lensV = dv;
    }
    if (motion_) cs.time = rng.uniform();
    return cs;
}

Ray Camera::generateRay(double px, double py) const {
    const double sx = (2 * px * invWidth_ - 1) * tanHalfFov_ * aspect_;
    const double sy = (1 - 2 * py * invHeight_) * tanHalfFov_;
    return {origin_, normalize(forward_ + right_ * sx + up_ * sy)};
}

Ray Camera::generateRay(const CameraSample& cs) const {
    Ray ray = generateRay(cs.screenX, cs.screenY);
    ray.time = cs.time;
    if (!hasLens()) return ray;
    // Every ray through the lens toward the point where the pinhole ray meets the plane in focus
    // (perpendicular to the view direction at focusDistance) converges there: that plane is sharp.
    const Vec3 focus = ray.o + ray.d * (focusDistance_ / dot(ray.d, forward_));
    ray.o = origin_ + (right_ * cs.lensU + up_ * cs.lensV) * aperture_;
    ray.d = normalize(focus - ray.o);
    return ray;
}

}  // namespace mcstat::render
