// The registry's Neighbourhood operations as commands: Jung's spatial and 3D robust filters (thesis
// chapter 5; docs/spatial_filters.md). --mif and --wmif filter the top image, so `--median --mif`
// is MPE+MIF (eq. 5.15) and `--tmpe:alpha=A --wmif:w=W` is TMPE+WMIF (eq. 5.14); --3dmf, --3dwmf
// and --3dwtmf filter the sub-buffers of the top statistics file (eq. 5.19-5.21). Their parameters,
// defaults and ranges are the registry's (filters/registry.cpp).
#include <OpenImageIO/strutil.h>

#include <cstdio>

#include "cli.h"
#include "mcstat/color.h"
#include "mcstat/filters/window/window_rank.h"
#include "mcstat/image/imageops.h"

namespace mcstat::cli {

namespace {

using OIIO::Strutil::fmt::format;

/// `op`'s SpatialParams from the modifiers (the table has already rejected modifiers it does not
/// take): the registry's defaults and fixed values, then the modifiers.
bool parseSpatialModifiers(const std::string& cmd, const Operation& op, const Modifiers& mods,
                           SpatialParams& p, std::string& err) {
    ParamValues values;
    if (!parseOperationParams(op, mods, values, err, cmd)) return false;
    std::string warning;
    p = spatialParams(values, lumaCoefficients(&warning));
    if (!warning.empty()) std::fprintf(stderr, "mcstat: warning: %s\n", warning.c_str());
    if (validateSpatialParams(p, err)) return true;
    err = cmd + ": " + err;
    return false;
}

void recordParams(OIIO::ImageBuf& img, const std::string& cmd, const SpatialParams& p) {
    OIIO::ImageSpec& spec = img.specmod();
    spec.attribute("mcstat:filter", cmd.substr(2));
    spec.attribute("mcstat:size", format("{}x{}", p.windowWidth, p.windowHeight));
    spec.attribute("mcstat:w", int(p.centreWeight));
    spec.attribute("mcstat:alpha", float(p.alpha));
    spec.attribute("mcstat:mode", p.mode == EstimatorMode::Luminance ? "lum" : "channel");
}

bool filterImage(State& st, const std::string& cmd, const Operation& op, const Modifiers& mods,
                 std::string& err) {
    if (st.stack.empty()) {
        err = format("{} needs an image on the stack", cmd);
        return false;
    }
    Item& top = st.stack.back();
    if (top.isStats()) {
        err = format("{}: {} is a statistics file; apply an estimator first (e.g. --median)", cmd,
                     top.name);
        return false;
    }
    SpatialParams p;
    if (!parseSpatialModifiers(cmd, op, mods, p, err)) return false;
    // The filter works on the first three channels: hand it R, G, B found by name. An
    // estimator's result over a file with AOVs (R, G, B first, then its AOVs, kAttrFirstAov)
    // goes whole: the filter gives each window pixel's AOVs the beauty's weights (docs/aovs.md).
    OIIO::ImageBuf rgb;
    const bool withAovs = top.image->spec().get_int_attribute(kAttrFirstAov, -1) == 3;
    if (!withAovs && !selectRGB(*top.image, "", top.name, rgb, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    auto img = std::make_shared<OIIO::ImageBuf>();
    if (!medianImageFilter(*img, withAovs ? *top.image : rgb, p, {}, st.nthreads)) {
        err = format("{}: {}", cmd, img->geterror());
        return false;
    }
    recordParams(*img, cmd, p);
    if (top.layout) {
        ParamValues values;
        if (parseOperationParams(op, mods, values, err, cmd))
            describeOperationResult(top, op, values, *img);
        err.clear();
    }
    replaceWithImage(top, cmd.substr(2), img, true);
    return true;
}

bool filterBuffers(State& st, const std::string& cmd, const Operation& op, const Modifiers& mods,
                   std::string& err) {
    if (st.stack.empty()) {
        err = format("{} needs a statistics file on the stack", cmd);
        return false;
    }
    Item& top = st.stack.back();
    if (!top.isStats()) {
        err = format(
            "{}: {} is an image, not a statistics file (.{}); renders of one image (one EXR "
            "per seed) become one with --ingest 'render_*.exr'",
            cmd, top.name, kStatsExtension);
        return false;
    }
    SpatialParams p;
    if (!parseSpatialModifiers(cmd, op, mods, p, err)) return false;
    ItemSource src;
    if (!top.stats && !openSource(st, top, src, err)) return false;
    auto img = std::make_shared<OIIO::ImageBuf>();
    if (!(top.stats ? filter3D(*img, *top.stats, p, {}, st.nthreads)
                    : filter3D(*img, *src.root, p, {}, st.nthreads))) {
        err = format("{}: {}", cmd, img->geterror());
        return false;
    }
    recordParams(*img, cmd, p);
    ParamValues values;
    if (!parseOperationParams(op, mods, values, err, cmd)) return false;
    describeOperationResult(top, op, values, *img);
    replaceWithImage(top, cmd.substr(2), img, true);
    return true;
}

}  // namespace

bool runNeighbourhood(State& st, const std::string& cmd, const Operation& op, const Modifiers& mods,
                      std::string& err) {
    switch (op.over) {
        case Neighbourhood::Image:
            return filterImage(st, cmd, op, mods, err);
        case Neighbourhood::SubBuffers:
            return filterBuffers(st, cmd, op, mods, err);
        case Neighbourhood::None:
            break;
    }
    err = format("{}: the registry entry says no neighbourhood to filter", cmd);
    return false;
}

}  // namespace mcstat::cli
