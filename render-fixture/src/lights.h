// Area lights: every shape with non-zero emission. Quads emit on their normal side only; spheres
// emit on both sides (so an emissive sphere lights its inside, as the furnace needs). Light
// sampling picks a light in proportion to its power and a point uniformly on its area.
#pragma once

#include <vector>

#include "mcstat/render-fixture/scene.h"
#include "rng.h"

namespace mcstat::render {

struct LightSample {
    Vec3 p;              ///< point on the light
    Vec3 n;              ///< the light shape's unit normal there
    int shape = -1;      ///< index into Scene::shapes
    double pdfArea = 0;  ///< selection probability / area: pdf with respect to area
    /// The two numbers in [0, 1) that chose the point on the light (after the one that chose the
    /// light): the light sample's random parameters (Sen and Darabi 2011, section 3.1).
    double u1 = 0, u2 = 0;
};

class LightSet {
  public:
    explicit LightSet(const Scene& scene);
    bool empty() const { return lights_.empty(); }

    /// Picks a light and a point on it. False when there are no lights.
    bool sample(Pcg32& rng, LightSample& ls) const;

    /// Solid-angle pdf, as seen from `ref`, that sample() returns point p (normal n) of `shape`.
    double pdfSolidAngle(int shape, const Vec3& ref, const Vec3& p, const Vec3& n) const;

    /// Radiance leaving `shape` at a point with normal n toward direction w (unit, away from it).
    Vec3 emitted(int shape, const Vec3& n, const Vec3& w) const;

  private:
    const Scene& scene_;
    std::vector<int> lights_;  ///< shape index of each light
    std::vector<double> cdf_;  ///< cumulative selection probability, last = 1
    std::vector<double>
        shapePdfArea_;  ///< per shape: selection probability / area (0: not a light)
};

}  // namespace mcstat::render
