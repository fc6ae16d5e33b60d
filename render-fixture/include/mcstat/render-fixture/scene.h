// Scene description: what a JSON scene file says, after validation. Nothing here knows Embree;
// render-fixture/SCENES.md documents every key, unit and default.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "mcstat/render-fixture/vec3.h"

namespace mcstat::render {

enum class MaterialType { Diffuse, Glass, Mirror };

enum class TextureType { None, Checker };

/// A procedural albedo texture of a diffuse material, looked up at the world hit position.
struct Texture {
    TextureType type = TextureType::None;
    double scale = 1;  ///< checker: edge length of a cell, world units (> 0)
    Vec3 albedo2;      ///< checker: albedo of the odd cells (the even ones have Material::albedo)
};

/// The 3D checkerboard: cell (floor(x/s), floor(y/s), floor(z/s)); true when the sum of the three
/// cell indices is odd.
inline bool checkerOdd(const Vec3& p, double scale) {
    const double k = std::floor(p.x / scale) + std::floor(p.y / scale) + std::floor(p.z / scale);
    return std::fmod(std::abs(k), 2.0) == 1.0;
}

struct Material {
    std::string name;
    MaterialType type = MaterialType::Diffuse;
    Vec3 albedo{0.8};  ///< diffuse albedo, or mirror reflectance
    double ior = 1.5;  ///< glass index of refraction (outside is vacuum, ior 1)
    Texture texture;   ///< diffuse only: replaces the constant albedo when its type is not None

    /// The albedo (reflectance) at world position p: the texture's value there, or `albedo`.
    Vec3 albedoAt(const Vec3& p) const {
        if (texture.type == TextureType::Checker && checkerOdd(p, texture.scale))
            return texture.albedo2;
        return albedo;
    }
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
    /// Motion blur: displacement over the shutter interval; at time t in [0, 1) the shape is
    /// translated by velocity * t. Zero = static. Emitters are always static.
    Vec3 velocity;

    bool moving() const { return !isBlack(velocity); }
};

struct CameraDesc {
    Vec3 position{0, 0, 0};
    Vec3 lookAt{0, 0, -1};
    Vec3 up{0, 1, 0};
    double fovDeg = 40;  ///< vertical field of view in degrees
    /// Thin lens: radius of the lens in world units; 0 = pinhole (no lens sample is drawn).
    double aperture = 0;
    /// Distance from the lens, along the viewing direction, of the plane in focus; 0 = the
    /// distance from position to lookAt.
    double focusDistance = 0;

    bool hasLens() const { return aperture > 0; }
};

struct Scene {
    std::string source;  ///< file name or "builtin:NAME": used in messages
    /// What a statistics file records as its scene (mcstat:scene): the scene's name (the built-in
    /// name or the file's name) and an FNV-1a 64-bit hash of its JSON text, "default h0123...":
    /// --merge refuses renders whose scenes differ.
    std::string identity;
    std::string description;
    int width = 0, height = 0;
    CameraDesc camera;
    Vec3 background;    ///< constant radiance of rays that leave the scene
    int maxDepth = 64;  ///< maximum number of scattering events along a path
    int rrDepth = 3;    ///< Russian roulette starts after this many scattering events
    std::vector<Material> materials;
    std::vector<Shape> shapes;

    /// Whether camera samples have a lens position (aperture > 0): then PathSample::lensU, lensV
    /// are random parameters; otherwise they are always 0 and no lens numbers are drawn.
    bool hasLens() const { return camera.hasLens(); }
    /// Whether any shape moves: then every camera sample draws a time, PathSample::time is a
    /// random parameter; otherwise it is always 0 and no time is drawn.
    bool hasMotion() const {
        for (const Shape& s : shapes)
            if (s.moving()) return true;
        return false;
    }
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
