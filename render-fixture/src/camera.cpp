#include "camera.h"

#include <cmath>

#include "sampling.h"

namespace mcstat::render {

Camera::Camera(const CameraDesc& desc, int width, int height)
    : origin_(desc.position),
      invWidth_(1.0 / width),
      invHeight_(1.0 / height),
      tanHalfFov_(std::tan(desc.fovDeg * kPi / 360.0)),
      aspect_(double(width) / height) {
    // Right-handed: the camera looks down -z of its own frame, like OpenGL and pbrt's LookAt.
    forward_ = normalize(desc.lookAt - desc.position);
    right_ = normalize(cross(forward_, desc.up));
    up_ = cross(right_, forward_);
}

Ray Camera::generateRay(double px, double py) const {
    const double sx = (2 * px * invWidth_ - 1) * tanHalfFov_ * aspect_;
    const double sy = (1 - 2 * py * invHeight_) * tanHalfFov_;
    return {origin_, normalize(forward_ + right_ * sx + up_ * sy)};
}

}  // namespace mcstat::render
