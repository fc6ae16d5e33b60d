// How the renderers our users have name their channels, and how mcstat finds the beauty (RGB) and
// the G-buffer features among them: by name, never by position. Pure functions over a list of
// channel names (no I/O, no OIIO types), shared by `mcstat --ingest`, `--diff` and the review
// pictures. docs/ingest.md has the table of conventions.
//
// A channel name is split at its last '.' into a layer and a component: "ViewLayer.Combined.R" is
// layer "ViewLayer.Combined", component "R"; "R" is layer "" (the plain beauty), component "R".
#pragma once

#include <array>
#include <string>
#include <vector>

#include "mcstat/exr-deep/stats_file.h"  // Feature bits

namespace mcstat {

/// The beauty found in a channel list: indices of R, G, B in that list.
struct BeautyChannels {
    std::array<int, 3> index{-1, -1, -1};
    std::string layer;  ///< "" for plain R, G, B; else e.g. "ViewLayer.Combined", "RGBA"
    /// Which rule matched, for messages: "plain R,G,B", "Blender/Cycles Combined pass",
    /// "beauty AOV 'RGBA'", "the only RGB layer", "layer given by :layer=".
    std::string rule;
    /// Prefix of the layers that belong with this beauty: "ViewLayer." for
    /// "ViewLayer.Combined" (Cycles' features live in the same view layer), "" otherwise.
    std::string viewLayerPrefix;
};

/// Finds the beauty's R, G, B among `names`. With a non-empty `layer` the channels must be
/// `layer.R`, `layer.G`, `layer.B` (`layer` "." means the plain R, G, B). Otherwise, in order:
///  1. plain `R`, `G`, `B` (any renderer's beauty, pbrt-v4);
///  2. Blender/Cycles `<ViewLayer>.Combined.R/G/B` (an error when several view layers have one);
///  3. a beauty AOV layer `<aov>.R/G/B` named RGBA, rgba, beauty, Beauty, Ci (RenderMan) or C
///     (Karma), in that order of preference (Arnold/Karma/RenderMan-style `<aov>.R` layers);
///  4. the only layer with R, G and B.
/// Otherwise false with `problem` (no file name) saying what was found and that :layer= chooses.
bool findBeauty(const std::vector<std::string>& names, const std::string& layer,
                BeautyChannels& out, std::string& problem);

/// Layers (as above) that have all of R, G and B, in the order of their first channel.
std::vector<std::string> rgbLayers(const std::vector<std::string>& names);

/// Feature channels found in a channel list: indices (-1 when absent) and which are present.
struct FeatureChannels {
    std::array<int, 3> normal{-1, -1, -1};
    std::array<int, 3> position{-1, -1, -1};
    std::array<int, 3> albedo{-1, -1, -1};
    int depth = -1;
    unsigned present = 0;  ///< Feature bits
    /// The channel names used, e.g. "N <- ViewLayer.Denoising Normal.X/Y/Z", for --info and -v.
    std::vector<std::string> sources;
};

/// Finds the features that belong with `beauty` (same view layer for Cycles). Coverage (A) is
/// never found: no renderer's alpha is the fraction of camera samples that hit geometry (it is 1
/// without a transparent film), so it is recorded as absent. The candidates, in order:
///  N: Denoising Normal, Normal, Ns, N, Nn (components X/Y/Z, x/y/z or R/G/B), pbrt-v4's Nsx/Nx;
///  P: Position, P (same components), pbrt-v4's Px/Py/Pz;
///  Albedo: Denoising Albedo, Albedo, albedo (R/G/B);
///  Z: Denoising Depth.Z, Depth.Z, Z, depth.Z, Depth.V (Cycles), depth.
FeatureChannels findFeatures(const std::vector<std::string>& names, const BeautyChannels& beauty);

/// The class of a channel that is not the beauty's R, G, B (docs/aovs.md, "Classes"), by name:
///  alpha: the beauty layer's alpha (`A` beside plain R, G, B; `<layer>.A` or `.a` beside
///         `<layer>.R/G/B`, e.g. `ViewLayer.Combined.A`, `RGBA.A`), or a plain `A`/`a`
///         (RenderMan's `a` beside `Ci.*`);
///  id:    labels: any name containing "crypto" (Cryptomatte rank/coverage pairs and their
///         manifests), passes named IndexOB, IndexMA, id, objid, matid, objectid, object_id,
///         materialid, material_id, object_index, material_index, instanceid, primid,
///         elementid (any case);
///  data:  normals, positions, depth, albedo and colour filters, UV, motion, variance: passes
///         named N, Nn, Ns, P, Pref, Z, depth, Normal, Position, Albedo, UV, Vector, motion,
///         velocity, DiffCol, GlossCol, TransCol, Variance, Mist, any "Denoising ..." pass, and
///         pbrt-v4's undotted dzdx, dzdy, u, v, Nsx.., Px..; a plain `Z`;
///  light: everything else (light groups, light-path passes, emission, environment, any AOV a
///         renderer adds to its beauty).
/// The pass is the last dot-separated part of the channel's layer (`ViewLayer.IndexOB.X` ->
/// IndexOB), or the whole name when it has no layer.
AovClass classifyAov(const std::string& name, const BeautyChannels& beauty);

}  // namespace mcstat
