// Scene loading: JSON text -> validated Scene. Every error is one line naming the source and the
// JSON path of the offending value ("scene.json: shapes[2].radius: expected a number, got string").
#include "mcstat/render-fixture/scene.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <initializer_list>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "builtin_scenes.h"
#include "mcstat/core/untrusted_text.h"

namespace mcstat::render {

namespace {

using nlohmann::json;

const char* typeName(const json& j) {
    switch (j.type()) {
        case json::value_t::null:
            return "null";
        case json::value_t::boolean:
            return "boolean";
        case json::value_t::string:
            return "string";
        case json::value_t::array:
            return "array";
        case json::value_t::object:
            return "object";
        case json::value_t::number_integer:
        case json::value_t::number_unsigned:
        case json::value_t::number_float:
            return "number";
        default:
            return "value";
    }
}

/// Reads typed values out of JSON objects, recording the first error with its path.
class Reader {
  public:
    Reader(const std::string& source, std::string& err) : source_(source), err_(err) {}

    bool fail(const std::string& path, const std::string& msg) {
        err_ = source_ + ": " + (path.empty() ? "" : path + ": ") + msg;
        return false;
    }

    bool expectObject(const json& j, const std::string& path) {
        if (j.is_object()) return true;
        return fail(path, std::string("expected an object, got ") + typeName(j));
    }

    /// Rejects keys outside `allowed`: a misspelt key would otherwise be silently ignored.
    bool checkKeys(const json& obj, const std::string& path,
                   std::initializer_list<const char*> allowed) {
        for (auto it = obj.begin(); it != obj.end(); ++it) {
            bool ok = false;
            for (const char* a : allowed) ok = ok || it.key() == a;
            if (!ok) return fail(path, "unknown key \"" + it.key() + "\"");
        }
        return true;
    }

    const json* find(const json& obj, const char* key, const std::string& path, bool required) {
        auto it = obj.find(key);
        if (it == obj.end()) {
            if (required) fail(path, std::string("missing \"") + key + "\"");
            return nullptr;
        }
        return &*it;
    }

    /// Each get* returns false only on error; an absent optional key leaves `out` unchanged.
    bool getNumber(const json& obj, const char* key, const std::string& path, double& out,
                   bool required) {
        const json* j = find(obj, key, path, required);
        if (!j) return !required;
        if (!j->is_number())
            return fail(join(path, key), std::string("expected a number, got ") + typeName(*j));
        out = j->get<double>();
        if (!std::isfinite(out)) return fail(join(path, key), "must be finite");
        return true;
    }

    bool getInt(const json& obj, const char* key, const std::string& path, int& out, int lo, int hi,
                bool required) {
        const json* j = find(obj, key, path, required);
        if (!j) return !required;
        if (!j->is_number_integer())
            return fail(join(path, key), std::string("expected an integer, got ") + typeName(*j));
        const auto v = j->get<int64_t>();
        if (v < lo || v > hi)
            return fail(join(path, key), "must be between " + std::to_string(lo) + " and " +
                                             std::to_string(hi) + " (got " + std::to_string(v) +
                                             ")");
        out = int(v);
        return true;
    }

    bool getString(const json& obj, const char* key, const std::string& path, std::string& out,
                   bool required) {
        const json* j = find(obj, key, path, required);
        if (!j) return !required;
        if (!j->is_string())
            return fail(join(path, key), std::string("expected a string, got ") + typeName(*j));
        out = j->get<std::string>();
        return true;
    }

    bool getVec3(const json& obj, const char* key, const std::string& path, Vec3& out,
                 bool required) {
        const json* j = find(obj, key, path, required);
        if (!j) return !required;
        if (!j->is_array() || j->size() != 3)
            return fail(join(path, key),
                        std::string("expected an array of 3 numbers, got ") +
                            (j->is_array() ? "an array of " + std::to_string(j->size())
                                           : std::string(typeName(*j))));
        double v[3];
        for (size_t i = 0; i < 3; ++i) {
            const json& e = (*j)[i];
            if (!e.is_number() || !std::isfinite(e.get<double>()))
                return fail(join(path, key), "expected an array of 3 finite numbers");
            v[i] = e.get<double>();
        }
        out = {v[0], v[1], v[2]};
        return true;
    }

    static std::string join(const std::string& path, const std::string& key) {
        return path.empty() ? key : path + "." + key;
    }

  private:
    const std::string& source_;
    std::string& err_;
};

bool inUnitRange(const Vec3& v) {
    return v.x >= 0 && v.x <= 1 && v.y >= 0 && v.y <= 1 && v.z >= 0 && v.z <= 1;
}
bool nonNegative(const Vec3& v) { return v.x >= 0 && v.y >= 0 && v.z >= 0; }

/// The optional "texture" of a diffuse material.
bool parseTexture(Reader& r, const json& mj, const std::string& matPath, Texture& tex) {
    const json* tj = r.find(mj, "texture", matPath, false);
    if (!tj) return true;
    const std::string path = matPath + ".texture";
    if (!r.expectObject(*tj, path)) return false;
    std::string type;
    if (!r.getString(*tj, "type", path, type, true)) return false;
    if (type != "checker")
        return r.fail(path + ".type", "unknown texture type \"" + type + "\" (expected checker)");
    tex.type = TextureType::Checker;
    if (!r.checkKeys(*tj, path, {"type", "scale", "albedo2"}) ||
        !r.getNumber(*tj, "scale", path, tex.scale, true) ||
        !r.getVec3(*tj, "albedo2", path, tex.albedo2, true))
        return false;
    if (!(tex.scale > 0)) return r.fail(path + ".scale", "must be positive");
    if (!inUnitRange(tex.albedo2))
        return r.fail(path + ".albedo2", "components must lie in [0, 1]");
    return true;
}

bool parseMaterials(Reader& r, const json& root, Scene& scene, std::map<std::string, int>& ids) {
    const json* mats = r.find(root, "materials", "", true);
    if (!mats) return false;
    if (!r.expectObject(*mats, "materials")) return false;
    for (auto it = mats->begin(); it != mats->end(); ++it) {
        const std::string path = "materials." + it.key();
        const json& mj = it.value();
        if (!r.expectObject(mj, path)) return false;
        Material m;
        m.name = it.key();
        std::string type;
        if (!r.getString(mj, "type", path, type, true)) return false;
        if (type == "diffuse") {
            m.type = MaterialType::Diffuse;
            if (!r.checkKeys(mj, path, {"type", "albedo", "texture"})) return false;
            if (!r.getVec3(mj, "albedo", path, m.albedo, false)) return false;
            if (!inUnitRange(m.albedo))
                return r.fail(path + ".albedo", "components must lie in [0, 1]");
            if (!parseTexture(r, mj, path, m.texture)) return false;
        } else if (type == "mirror") {
            m.type = MaterialType::Mirror;
            m.albedo = Vec3(1.0);
            if (!r.checkKeys(mj, path, {"type", "reflectance"})) return false;
            if (!r.getVec3(mj, "reflectance", path, m.albedo, false)) return false;
            if (!inUnitRange(m.albedo))
                return r.fail(path + ".reflectance", "components must lie in [0, 1]");
        } else if (type == "glass") {
            m.type = MaterialType::Glass;
            if (!r.checkKeys(mj, path, {"type", "ior"})) return false;
            if (!r.getNumber(mj, "ior", path, m.ior, false)) return false;
            if (!(m.ior > 0)) return r.fail(path + ".ior", "must be positive");
        } else {
            return r.fail(path + ".type", "unknown material type \"" + type +
                                              "\" (expected diffuse, glass or mirror)");
        }
        ids[m.name] = int(scene.materials.size());
        scene.materials.push_back(m);
    }
    return true;
}

/// Appends the six outward-facing quads of an axis-aligned box.
void addBox(const Vec3& lo, const Vec3& hi, const Shape& proto, std::vector<Shape>& out) {
    const Vec3 dx(hi.x - lo.x, 0, 0), dy(0, hi.y - lo.y, 0), dz(0, 0, hi.z - lo.z);
    auto quad = [&](const Vec3& corner, const Vec3& e1, const Vec3& e2) {
        Shape s = proto;
        s.type = ShapeType::Quad;
        s.corner = corner, s.edge1 = e1, s.edge2 = e2;  // e1 x e2 points out of the box
        out.push_back(s);
    };
    quad(lo, dz, dy);                  // -x
    quad({hi.x, lo.y, lo.z}, dy, dz);  // +x
    quad(lo, dx, dz);                  // -y
    quad({lo.x, hi.y, lo.z}, dz, dx);  // +y
    quad(lo, dy, dx);                  // -z
    quad({lo.x, lo.y, hi.z}, dx, dy);  // +z
}

bool parseShapes(Reader& r, const json& root, const std::map<std::string, int>& ids, Scene& scene) {
    const json* shapes = r.find(root, "shapes", "", true);
    if (!shapes) return false;
    if (!shapes->is_array())
        return r.fail("shapes", std::string("expected an array, got ") + typeName(*shapes));
    if (shapes->empty()) return r.fail("shapes", "the scene has no shapes");
    for (size_t i = 0; i < shapes->size(); ++i) {
        const std::string path = "shapes[" + std::to_string(i) + "]";
        const json& sj = (*shapes)[i];
        if (!r.expectObject(sj, path)) return false;
        Shape s;
        std::string type, material;
        if (!r.getString(sj, "type", path, type, true)) return false;
        if (!r.getString(sj, "material", path, material, false)) return false;
        if (!material.empty()) {
            auto it = ids.find(material);
            if (it == ids.end())
                return r.fail(path + ".material", "unknown material \"" + material + "\"");
            s.material = it->second;
        }
        if (!r.getVec3(sj, "emission", path, s.emission, false)) return false;
        if (!nonNegative(s.emission))
            return r.fail(path + ".emission", "components must be non-negative");
        if (!r.getVec3(sj, "velocity", path, s.velocity, false)) return false;
        if (s.moving() && !isBlack(s.emission))
            return r.fail(path + ".velocity",
                          "emitters must be static (light sampling assumes it): a shape with "
                          "emission cannot have a non-zero velocity");
        if (type == "sphere") {
            if (!r.checkKeys(sj, path,
                             {"type", "material", "emission", "velocity", "center", "radius"}) ||
                !r.getVec3(sj, "center", path, s.center, true) ||
                !r.getNumber(sj, "radius", path, s.radius, true))
                return false;
            if (!(s.radius > 0)) return r.fail(path + ".radius", "must be positive");
            s.type = ShapeType::Sphere;
            scene.shapes.push_back(s);
        } else if (type == "quad") {
            if (!r.checkKeys(
                    sj, path,
                    {"type", "material", "emission", "velocity", "corner", "edge1", "edge2"}) ||
                !r.getVec3(sj, "corner", path, s.corner, true) ||
                !r.getVec3(sj, "edge1", path, s.edge1, true) ||
                !r.getVec3(sj, "edge2", path, s.edge2, true))
                return false;
            if (!(length(cross(s.edge1, s.edge2)) > 0))
                return r.fail(path, "edge1 and edge2 must span a non-degenerate quad");
            s.type = ShapeType::Quad;
            scene.shapes.push_back(s);
        } else if (type == "box") {
            Vec3 lo, hi;
            if (!r.checkKeys(sj, path,
                             {"type", "material", "emission", "velocity", "min", "max"}) ||
                !r.getVec3(sj, "min", path, lo, true) || !r.getVec3(sj, "max", path, hi, true))
                return false;
            if (!(hi.x > lo.x && hi.y > lo.y && hi.z > lo.z))
                return r.fail(path, "max must exceed min on every axis");
            addBox(lo, hi, s, scene.shapes);
        } else {
            return r.fail(path + ".type",
                          "unknown shape type \"" + type + "\" (expected sphere, quad or box)");
        }
    }
    return true;
}

}  // namespace

namespace {

bool parseSceneText(const std::string& jsonText, const std::string& source, Scene& scene,
                    std::string& err);

}  // namespace

bool parseScene(const std::string& jsonText, const std::string& source, Scene& scene,
                std::string& err) {
    const bool ok = parseSceneText(jsonText, source, scene, err);
    if (ok) {
        uint64_t hash = 14695981039346656037ull;  // FNV-1a 64
        for (const char c : jsonText) {
            hash ^= static_cast<unsigned char>(c);
            hash *= 1099511628211ull;
        }
        const size_t slash = source.find_last_of("/:");
        char hex[24];
        std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(hash));
        scene.identity =
            (slash == std::string::npos ? source : source.substr(slash + 1)) + " h" + hex;
    }
    // A message on one line: a scene file's strings (an escaped "\n" in a key the message
    // quotes) are shown through oneLine (core/untrusted_text.h). Found by fuzzing.
    if (!ok) err = oneLine(err);
    return ok;
}

namespace {

bool parseSceneText(const std::string& jsonText, const std::string& source, Scene& scene,
                    std::string& err) {
    json root;
    try {
        // Comments are allowed: scene files document themselves.
        root = json::parse(jsonText, nullptr, true, true);
    } catch (const json::exception& e) {
        // e.what() is "[json.exception.parse_error.101] parse error at line L, column C: ..." (or
        // out_of_range.406 for a number beyond double, "1E400"); keep the part after the id.
        std::string what = e.what();
        const size_t close = what.find("] ");
        if (close != std::string::npos) what = what.substr(close + 2);
        err = source + ": invalid JSON: " + what;
        return false;
    }
    Reader r(source, err);
    Scene s;
    s.source = source;
    if (!r.expectObject(root, "")) return false;
    if (!r.checkKeys(
            root, "",
            {"description", "image", "camera", "background", "integrator", "materials", "shapes"}))
        return false;
    if (!r.getString(root, "description", "", s.description, false)) return false;

    const json* image = r.find(root, "image", "", true);
    if (!image || !r.expectObject(*image, "image") ||
        !r.checkKeys(*image, "image", {"width", "height"}) ||
        !r.getInt(*image, "width", "image", s.width, 1, 16384, true) ||
        !r.getInt(*image, "height", "image", s.height, 1, 16384, true))
        return false;

    const json* cam = r.find(root, "camera", "", true);
    if (!cam || !r.expectObject(*cam, "camera") ||
        !r.checkKeys(*cam, "camera",
                     {"position", "lookAt", "up", "fov", "aperture", "focusDistance"}) ||
        !r.getVec3(*cam, "position", "camera", s.camera.position, true) ||
        !r.getVec3(*cam, "lookAt", "camera", s.camera.lookAt, true) ||
        !r.getVec3(*cam, "up", "camera", s.camera.up, false) ||
        !r.getNumber(*cam, "fov", "camera", s.camera.fovDeg, false) ||
        !r.getNumber(*cam, "aperture", "camera", s.camera.aperture, false))
        return false;
    if (!(s.camera.aperture >= 0)) return r.fail("camera.aperture", "must be non-negative");
    if (cam->contains("focusDistance")) {
        if (!r.getNumber(*cam, "focusDistance", "camera", s.camera.focusDistance, true))
            return false;
        if (!(s.camera.focusDistance > 0))
            return r.fail("camera.focusDistance", "must be positive");
    }
    if (!(s.camera.fovDeg > 0 && s.camera.fovDeg < 180))
        return r.fail("camera.fov", "must lie strictly between 0 and 180 degrees");
    const Vec3 fwd = s.camera.lookAt - s.camera.position;
    if (!(length(fwd) > 0)) return r.fail("camera", "position and lookAt coincide");
    if (!(length(cross(normalize(fwd), s.camera.up)) > 1e-9))
        return r.fail("camera.up", "must not be parallel to the viewing direction");

    if (!r.getVec3(root, "background", "", s.background, false)) return false;
    if (!nonNegative(s.background)) return r.fail("background", "components must be non-negative");

    if (const json* integ = r.find(root, "integrator", "", false)) {
        if (!r.expectObject(*integ, "integrator") ||
            !r.checkKeys(*integ, "integrator", {"maxDepth", "rrDepth"}) ||
            !r.getInt(*integ, "maxDepth", "integrator", s.maxDepth, 0, 100000, false) ||
            !r.getInt(*integ, "rrDepth", "integrator", s.rrDepth, 1, 100000, false))
            return false;
    }

    std::map<std::string, int> ids;
    if (!parseMaterials(r, root, s, ids) || !parseShapes(r, root, ids, s)) return false;
    scene = std::move(s);
    return true;
}

}  // namespace

std::vector<std::string> builtinSceneNames() {
    std::vector<std::string> names;
    for (int i = 0; i < kBuiltinSceneCount; ++i) names.emplace_back(kBuiltinScenes[i].name);
    return names;
}

bool loadScene(const std::string& nameOrPath, Scene& scene, std::string& err) {
    for (int i = 0; i < kBuiltinSceneCount; ++i)
        if (nameOrPath == kBuiltinScenes[i].name)
            return parseScene(kBuiltinScenes[i].json, "builtin:" + nameOrPath, scene, err);
    const bool looksLikePath =
        nameOrPath.find('/') != std::string::npos ||
        (nameOrPath.size() > 5 && nameOrPath.compare(nameOrPath.size() - 5, 5, ".json") == 0);
    std::ifstream in(nameOrPath, std::ios::binary);
    if (!in) {
        if (looksLikePath) {
            err = nameOrPath + ": cannot open scene file";
        } else {
            std::string list;
            for (const auto& n : builtinSceneNames()) list += (list.empty() ? "" : ", ") + n;
            err = nameOrPath + ": no such built-in scene (" + list + ") or scene file";
        }
        return false;
    }
    std::ostringstream text;
    text << in.rdbuf();
    if (in.bad()) {
        err = nameOrPath + ": read error";
        return false;
    }
    return parseScene(text.str(), nameOrPath, scene, err);
}

}  // namespace mcstat::render
