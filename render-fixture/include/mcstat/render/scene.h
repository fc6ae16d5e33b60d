// Scene description: what a JSON scene file says, after validation. Nothing here knows Embree;
// render-fixture/SCENES.md documents every key, unit and default.
#pragma once

#include <string>
#include <vector>

#include "mcstat/render/vec3.h"

namespace mcstat::render {

enum class MaterialType { Diffuse, Glass, Mirror };

struct Material {
    std::string name;
    MaterialType type = MaterialType::Diffuse;
    Vec3 albedo{0.8};  ///< diffuse albedo, or mirror reflectance
    double ior = 1.5;  ///< glass index of refraction (outside is vacuum, ior 1)
};

enum class ShapeType { Sphere, Quad };

/// One primitive. Boxes are expanded into six quads (outward normals) when the scene is loaded.
struct Shape {
    ShapeType type = ShapeType::Sphere;
    Vec3 center;        ///< sphere
    double radius = 1;  ///< sphere
    Vec3 corner;        ///< quad: one corner; the quad is corner + u*edge1 + v*edge2, u,v in [0,1]
    Vec3 edge1, edge2;  ///< quad; its normal (and emission side) is normalize(edge1 x edge2)
    int material = -1;  ///< index into Scene::materials; -1 = black (absorbs everything)
    Vec3 emission;      ///< emitted radiance (quads: on the normal side only; spheres: both sides)
};

struct CameraDesc {
    Vec3 position{0, 0, 0};
    Vec3 lookAt{0, 0, -1};
    Vec3 up{0, 1, 0};
    double fovDeg = 40;  ///< vertical field of view in degrees
};

struct Scene {
    std::string source;  ///< file name or "builtin:NAME": used in messages
    std::string description;
    int width = 0, height = 0;
    CameraDesc camera;
    Vec3 background;    ///< constant radiance of rays that leave the scene
    int maxDepth = 64;  ///< maximum number of scattering events along a path
    int rrDepth = 3;    ///< Russian roulette starts after this many scattering events
    std::vector<Material> materials;
    std::vector<Shape> shapes;
};

/// Loads a built-in scene by name (see builtinSceneNames) or a JSON file by path. Names win over
/// paths; a path is anything that contains '/' or ends in ".json". On failure `err` is one line
/// that names the file (or built-in scene) and the problem.
bool loadScene(const std::string& nameOrPath, Scene& scene, std::string& err);

/// Parses scene JSON text; `source` names it in error messages.
bool parseScene(const std::string& jsonText, const std::string& source, Scene& scene,
                std::string& err);

/// Names of the scenes embedded at build time, sorted.
std::vector<std::string> builtinSceneNames();

}  // namespace mcstat::render
