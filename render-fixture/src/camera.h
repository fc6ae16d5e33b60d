// Pinhole camera: position, look-at point, up vector and vertical field of view.
#pragma once

#include "mcstat/render/scene.h"
#include "ray.h"

namespace mcstat::render {

class Camera {
  public:
    Camera(const CameraDesc& desc, int width, int height);
    /// Ray through raster position (px, py): x to the right, y down, pixel (i, j) covers
    /// [i, i+1) x [j, j+1). The direction is unit length, so hit distances are depths.
    Ray generateRay(double px, double py) const;

  private:
    Vec3 origin_, forward_, right_, up_;
    double invWidth_, invHeight_, tanHalfFov_, aspect_;
};

}  // namespace mcstat::render
