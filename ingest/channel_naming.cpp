// Finding the beauty and the features of a renderer's EXR by channel name (channel_naming.h,
// docs/ingest.md "Channel naming").
#include "mcstat/ingest/channel_naming.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <map>

#include "mcstat/core/untrusted_text.h"

namespace mcstat {

namespace {

/// Splits "a.b.C" into layer "a.b" and component "C"; "R" into "" and "R".
void splitName(const std::string& name, std::string& layer, std::string& component) {
    const size_t dot = name.rfind('.');
    if (dot == std::string::npos) {
        layer.clear();
        component = name;
    } else {
        layer = name.substr(0, dot);
        component = name.substr(dot + 1);
    }
}

int indexOf(const std::vector<std::string>& names, const std::string& name) {
    const auto it = std::find(names.begin(), names.end(), name);
    return it == names.end() ? -1 : int(it - names.begin());
}

/// Indices of layer.R, layer.G, layer.B ("R", "G", "B" for layer ""); false if one is missing.
bool rgbOf(const std::vector<std::string>& names, const std::string& layer,
           std::array<int, 3>& idx) {
    static const char* kRGB[3] = {"R", "G", "B"};
    for (int c = 0; c < 3; ++c) {
        idx[c] = indexOf(names, layer.empty() ? std::string(kRGB[c]) : layer + "." + kRGB[c]);
        if (idx[c] < 0) return false;
    }
    return true;
}

std::string quotedList(const std::vector<std::string>& items) { return printableList(items, 12); }

std::string layerLabel(const std::string& layer) {
    return layer.empty() ? std::string("(plain R,G,B)") : layer;
}

}  // namespace

std::vector<std::string> rgbLayers(const std::vector<std::string>& names) {
    std::vector<std::string> layers;
    std::string layer, comp;
    for (const std::string& n : names) {
        splitName(n, layer, comp);
        if (std::find(layers.begin(), layers.end(), layer) != layers.end()) continue;
        std::array<int, 3> idx{};
        if (rgbOf(names, layer, idx)) layers.push_back(layer);
    }
    return layers;
}

bool findBeauty(const std::vector<std::string>& names, const std::string& layer,
                BeautyChannels& out, std::string& problem) {
    const std::vector<std::string> layers = rgbLayers(names);
    std::vector<std::string> labels;
    for (const std::string& l : layers) labels.push_back(layerLabel(l));
    BeautyChannels b;
    if (!layer.empty()) {
        const std::string want = layer == "." ? std::string() : layer;
        if (!rgbOf(names, want, b.index)) {
            problem = want.empty()
                          ? fmt::format("no plain R, G, B channels (layers with R, G, B: {})",
                                        quotedList(labels))
                          : fmt::format(
                                "no channels '{0}.R', '{0}.G', '{0}.B' (layers with R, G, "
                                "B: {1})",
                                want, quotedList(labels));
            return false;
        }
        b.layer = want;
        b.rule = "layer given by :layer=";
    } else if (rgbOf(names, "", b.index)) {
        b.rule = "plain R,G,B";
    } else {
        // Blender/Cycles multilayer: "<ViewLayer>.Combined.R"; a single-layer Blender EXR has
        // "Combined.R" without the view layer.
        std::vector<std::string> combined;
        for (const std::string& l : layers)
            if (l == "Combined" || (l.size() > 9 && l.compare(l.size() - 9, 9, ".Combined") == 0))
                combined.push_back(l);
        if (combined.size() > 1) {
            problem = fmt::format(
                "several view layers have a Combined pass ({}): choose one with :layer=",
                quotedList(combined));
            return false;
        }
        if (combined.size() == 1) {
            b.layer = combined[0];
            b.rule = "Blender/Cycles Combined pass";
        } else {
            static const char* kBeautyAovs[] = {"RGBA", "rgba", "beauty", "Beauty", "Ci", "C"};
            for (const char* aov : kBeautyAovs)
                if (b.layer.empty() &&
                    std::find(layers.begin(), layers.end(), aov) != layers.end()) {
                    b.layer = aov;
                    b.rule = fmt::format("beauty AOV '{}'", aov);
                }
            if (b.layer.empty()) {
                if (layers.size() == 1) {
                    b.layer = layers[0];
                    b.rule = "the only RGB layer";
                } else if (layers.empty()) {
                    problem =
                        fmt::format("no RGB channels (R, G, B or <layer>.R/G/B; channels: {})",
                                    quotedList(names));
                    return false;
                } else {
                    problem = fmt::format(
                        "no recognisable beauty among the layers with R, G, B ({}): neither plain "
                        "R,G,B nor a Combined pass nor an AOV named RGBA, beauty, Ci or C; choose "
                        "one with :layer=",
                        quotedList(labels));
                    return false;
                }
            }
        }
        rgbOf(names, b.layer, b.index);
    }
    // Cycles' passes of a view layer share its prefix: "ViewLayer.Combined" -> "ViewLayer.".
    if (b.layer.size() > 9 && b.layer.compare(b.layer.size() - 9, 9, ".Combined") == 0)
        b.viewLayerPrefix = b.layer.substr(0, b.layer.size() - 8);
    out = b;
    return true;
}

namespace {

/// Tries `prefix + base + sep + component` for each component set; true with indices on a hit.
bool findVector(const std::vector<std::string>& names, const std::string& prefix,
                const std::vector<std::string>& bases, std::array<int, 3>& idx, std::string& used) {
    static const char* kSets[][3] = {
        {"X", "Y", "Z"}, {"x", "y", "z"}, {"R", "G", "B"}, {"r", "g", "b"}};
    for (const std::string& base : bases)
        for (const auto& set : kSets) {
            std::array<int, 3> found{};
            bool all = true;
            for (int c = 0; c < 3 && all; ++c) {
                found[c] = indexOf(names, prefix + base + "." + set[c]);
                all = found[c] >= 0;
            }
            if (all) {
                idx = found;
                used = fmt::format("{}{}.{}/{}/{}", prefix, base, set[0], set[1], set[2]);
                return true;
            }
        }
    return false;
}

/// pbrt-v4 before its channel renaming wrote "Px", "Py", "Pz", "Nsx", ... (no dot).
bool findUndotted(const std::vector<std::string>& names, const std::string& prefix,
                  const std::string& base, std::array<int, 3>& idx, std::string& used) {
    static const char* kXYZ[3] = {"x", "y", "z"};
    std::array<int, 3> found{};
    for (int c = 0; c < 3; ++c) {
        found[c] = indexOf(names, prefix + base + kXYZ[c]);
        if (found[c] < 0) return false;
    }
    idx = found;
    used = fmt::format("{0}{1}x/{0}{1}y/{0}{1}z", prefix, base);
    return true;
}

}  // namespace

FeatureChannels findFeatures(const std::vector<std::string>& names, const BeautyChannels& beauty) {
    FeatureChannels f;
    const std::string& pre = beauty.viewLayerPrefix;
    std::string used;
    if (findVector(names, pre, {"Denoising Normal", "Normal", "Ns", "N", "Nn"}, f.normal, used) ||
        findUndotted(names, pre, "Ns", f.normal, used) ||
        findUndotted(names, pre, "N", f.normal, used)) {
        f.present |= kFeatureNormal;
        f.sources.push_back("N <- " + used);
    }
    if (findVector(names, pre, {"Position", "P"}, f.position, used) ||
        findUndotted(names, pre, "P", f.position, used)) {
        f.present |= kFeaturePosition;
        f.sources.push_back("P <- " + used);
    }
    if (findVector(names, pre, {"Denoising Albedo", "Albedo", "albedo"}, f.albedo, used)) {
        f.present |= kFeatureAlbedo;
        f.sources.push_back("Albedo <- " + used);
    }
    for (const char* z : {"Denoising Depth.Z", "Depth.Z", "Z", "depth.Z", "Depth.V", "depth"}) {
        const int i = indexOf(names, pre + z);
        if (i >= 0) {
            f.depth = i;
            f.present |= kFeatureDepth;
            f.sources.push_back("Z <- " + pre + z);
            break;
        }
    }
    return f;
}

AovClass classifyAov(const std::string& name, const BeautyChannels& beauty) {
    std::string layer, comp;
    splitName(name, layer, comp);
    // The beauty layer's alpha; a plain A beside a layered beauty (RenderMan's `a` beside Ci).
    if ((comp == "A" || comp == "a") && (layer == beauty.layer || layer.empty()))
        return AovClass::Alpha;
    const auto lower = [](std::string t) {
        for (char& ch : t) ch = char(std::tolower(static_cast<unsigned char>(ch)));
        return t;
    };
    const std::string lname = lower(name);
    if (lname.find("crypto") != std::string::npos) return AovClass::Id;
    const size_t dot = layer.rfind('.');
    const std::string pass =
        lower(layer.empty() ? name : layer.substr(dot == std::string::npos ? 0 : dot + 1));
    for (const char* id : {"indexob", "indexma", "id", "objid", "matid", "objectid", "object_id",
                           "materialid", "material_id", "object_index", "material_index",
                           "instanceid", "instance_id", "primid", "elementid", "element_id"})
        if (pass == id) return AovClass::Id;
    if (pass.rfind("denoising", 0) == 0) return AovClass::Data;
    for (const char* d :
         {"n",        "nn",       "ns",   "p",      "pref",   "z",        "depth",   "normal",
          "position", "albedo",   "uv",   "vector", "motion", "velocity", "diffcol", "glosscol",
          "transcol", "variance", "mist", "dzdx",   "dzdy",   "u",        "v",       "nsx",
          "nsy",      "nsz",      "nx",   "ny",     "nz",     "px",       "py",      "pz"})
        if (pass == d) return AovClass::Data;
    return AovClass::Light;
}

}  // namespace mcstat
