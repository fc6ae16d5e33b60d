// Jung's spatial and 3D robust filters as commands (thesis chapter 5; docs/spatial_filters.md):
// --mif and --wmif filter the top image, so `--median --mif` is MPE+MIF (eq. 5.15) and
// `--tmpe:alpha=A --wmif:w=W` is TMPE+WMIF (eq. 5.14); --3dmf, --3dwmf and --3dwtmf filter the
// sub-buffers of the top statistics file (eq. 5.19-5.21).
#include <OpenImageIO/strutil.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "cli.h"
#include "mcstat/color.h"
#include "mcstat/imageops.h"
#include "mcstat/spatial_filters.h"

namespace mcstat::cli {

namespace {

using OIIO::Strutil::fmt::format;

bool parseLong(const std::string& s, long& out) {
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(s.c_str(), &end, 10);
    if (s.empty() || *end != '\0' || errno != 0) return false;
    out = v;
    return true;
}

/// "KxL" (or "K" for K x K): odd window sides in [1, kMaxSpatialWindow].
bool parseSize(const std::string& cmd, const std::string& v, SpatialParams& p, std::string& err) {
    const size_t x = v.find('x');
    long k = 0, l = 0;
    const bool ok = x == std::string::npos
                        ? parseLong(v, k) && (l = k, true)
                        : parseLong(v.substr(0, x), k) && parseLong(v.substr(x + 1), l);
    if (!ok || k < 1 || l < 1 || k > kMaxSpatialWindow || l > kMaxSpatialWindow || k % 2 == 0 ||
        l % 2 == 0) {
        err = format("{}: size must be KxL with odd K, L in [1, {}] (e.g. 3x3), not '{}'", cmd,
                     kMaxSpatialWindow, v);
        return false;
    }
    p.windowWidth = int(k);
    p.windowHeight = int(l);
    return true;
}

/// Fills `p` from the modifiers common to every spatial command (the table has already rejected
/// modifiers a command does not take). `weighted`: w defaults to 3; otherwise it is 1.
bool parseSpatialModifiers(const std::string& cmd, const Modifiers& mods, bool weighted,
                           SpatialParams& p, std::string& err) {
    std::string warning;
    p.luma = lumaCoefficients(&warning);
    if (!warning.empty()) std::fprintf(stderr, "mcstat: warning: %s\n", warning.c_str());
    p.centreWeight = weighted ? 3 : 1;
    for (const auto& [k, v] : mods) {
        if (k == "size") {
            if (!parseSize(cmd, v, p, err)) return false;
        } else if (k == "mode") {
            if (v == "lum" || v == "luminance")
                p.mode = EstimatorMode::Luminance;
            else if (v == "channel" || v == "rgb")
                p.mode = EstimatorMode::PerChannel;
            else {
                err = format("{}: mode must be 'lum' or 'channel', not '{}'", cmd, v);
                return false;
            }
        } else if (k == "w") {
            long w = 0;
            if (!parseLong(v, w) || w < 1 || w > kMaxCentreWeight) {
                err = format("{}: w must be an integer in [1, {}], not '{}'", cmd, kMaxCentreWeight,
                             v);
                return false;
            }
            p.centreWeight = w;
        } else if (k == "alpha") {
            char* end = nullptr;
            errno = 0;
            const double a = std::strtod(v.c_str(), &end);
            if (v.empty() || *end != '\0' || errno != 0 || !(a >= 0.0 && a <= 0.5)) {
                err = format("{}: alpha must be a number in [0, 0.5], not '{}'", cmd, v);
                return false;
            }
            p.alpha = a;
        }
    }
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

}  // namespace

bool cmdMedianImageFilter(State& st, const std::string& cmd, const std::vector<std::string>&,
                          const Modifiers& mods, std::string& err) {
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
    p.alpha = 0.5;  // eq. 5.6: the weighted median
    if (!parseSpatialModifiers(cmd, mods, cmd == "--wmif", p, err)) return false;
    // The filter works on the first three channels: hand it R, G, B found by name.
    OIIO::ImageBuf rgb;
    if (!selectRGB(*top.image, "", top.name, rgb, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    auto img = std::make_shared<OIIO::ImageBuf>();
    if (!medianImageFilter(*img, rgb, p, {}, st.nthreads)) {
        err = format("{}: {}", cmd, img->geterror());
        return false;
    }
    recordParams(*img, cmd, p);
    replaceWithImage(top, cmd.substr(2), img);
    return true;
}

bool cmdFilter3D(State& st, const std::string& cmd, const std::vector<std::string>&,
                 const Modifiers& mods, std::string& err) {
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
    p.alpha = cmd == "--3dwtmf" ? 0.25 : 0.5;  // eq. 5.19; 5.20-5.21: the weighted median
    if (!parseSpatialModifiers(cmd, mods, cmd != "--3dmf", p, err)) return false;
    if (!loadStats(st, top, err)) return false;
    auto img = std::make_shared<OIIO::ImageBuf>();
    if (!filter3D(*img, *top.stats, p, {}, st.nthreads)) {
        err = format("{}: {}", cmd, img->geterror());
        return false;
    }
    recordParams(*img, cmd, p);
    replaceWithImage(top, cmd.substr(2), img);
    return true;
}

}  // namespace mcstat::cli
