// Camera: a pinhole, or a thin lens (depth of field) when the aperture is positive; position,
// look-at point, up vector and vertical field of view. It also draws each camera sample's random
// parameters: pixel jitter, lens position, shutter time.
#pragma once

#include "mcstat/render-fixture/scene.h"
#include "ray.h"
#include "rng.h"

namespace mcstat::render {

/// The random parameters of one camera sample, in the form the camera uses them (Sen and Darabi
/// 2011, section 3.1).
struct CameraSample {
    double screenX = 0, screenY = 0;  ///< raster position: pixel corner + jitter in [0, 1)
    double lensU = 0, lensV = 0;      ///< point on the unit disk (before the aperture scales it)
    double time = 0;                  ///< shutter time in [0, 1)
};

class Camera {
  public:
    /// `motion`: every sample draws a shutter time (Scene::hasMotion()).
    Camera(const CameraDesc& desc, int width, int height, bool motion = false);

    bool hasLens() const { return aperture_ > 0; }
    bool hasMotion() const { return motion_; }
    double focusDistance() const { return focusDistance_; }

    /// Draws the camera sample of pixel (x, y) from `rng`, in this order: the jitter in x and y
    /// (box filter); with a lens, two numbers mapped to the unit disk (concentric mapping); with
    /// motion, the time. Without a lens or motion their fields stay 0 and nothing is drawn.
    CameraSample sample(int x, int y, Pcg32& rng) const;

    /// The ray of a camera sample: from the lens point toward the point of the plane in focus
    /// that the pinhole ray through (screenX, screenY) meets; it carries the sample's time.
    Ray generateRay(const CameraSample& cs) const;

    /// Pinhole ray (lens centre, time 0) through raster position (px, py): x to the right, y down,
    /// pixel (i, j) covers [i, i+1) x [j, j+1). The direction is unit length, so hit distances are
    /// depths.
    Ray generateRay(double px, double py) const;

  private:
    Vec3 origin_, forward_, right_, up_;
    double invWidth_, invHeight_, tanHalfFov_, aspect_;
    double aperture_, focusDistance_;
    bool motion_;
};

}  // namespace mcstat::render
