// Colour management through OpenColorIO (see include/mcstat/color.h).
#include "mcstat/color.h"

#include <OpenColorIO/OpenColorIO.h>
#include <strings.h>

#include <cmath>
#include <cstdlib>
#include <mutex>
#include <sstream>

#include "mcstat/core/colour_space.h"
#include "mcstat/core/untrusted_text.h"

namespace OCIO = OCIO_NAMESPACE;

namespace mcstat {
namespace detail {
extern const char* const kBuiltinOcioConfig;  // generated from color/config.ocio
}

namespace {

struct ActiveConfig {
    OCIO::ConstConfigRcPtr config;
    std::string warning;  // non-empty when $OCIO was set but could not be used
};

// The config is loaded once per process: OCIO configs are immutable and thread-safe to share.
const ActiveConfig& activeConfig() {
    static const ActiveConfig active = [] {
        ActiveConfig a;
        const char* env = std::getenv("OCIO");
        if (env && *env) {
            try {
                a.config = OCIO::Config::CreateFromEnv();
                return a;
            } catch (const std::exception& e) {
                a.warning = std::string("$OCIO=") + env + " unusable (" + e.what() +
                            "); using mcstat's built-in config";
            }
        }
        std::istringstream in(detail::kBuiltinOcioConfig);
        a.config = OCIO::Config::CreateFromStream(in);  // our own text: a failure is a build bug
        return a;
    }();
    return active;
}

}  // namespace

const char* builtinOcioConfig() { return detail::kBuiltinOcioConfig; }

bool lumaCoefficients(const std::string& space, std::array<double, 3>& luma, std::string& err,
                      std::string* warning) {
    const ActiveConfig& a = activeConfig();
    std::string warn = a.warning;
    const WorkingSpace* ws = findWorkingSpace(space);
    if (!ws) {
        err = "colour space '" + printable(space) +
              "' is unknown (known: " + knownWorkingSpaceNames() + ")";
        return false;
    }
    std::array<double, 3> fromPrimaries{};
    if (!lumaFromChromaticities(ws->xy, fromPrimaries)) {  // the table's own values: cannot fail
        err = "colour space '" + printable(space) + "' has degenerate chromaticities";
        return false;
    }
    luma = fromPrimaries;
    // The config's luma when the config's scene_linear space is this one.
    const OCIO::ConstColorSpaceRcPtr sl = a.config->getColorSpace(OCIO::ROLE_SCENE_LINEAR);
    const OCIO::ConstColorSpaceRcPtr named = a.config->getColorSpace(ws->name);
    if (sl && named && std::string(sl->getName()) == named->getName()) {
        std::array<double, 3> cfg{};
        a.config->getDefaultLumaCoefs(cfg.data());
        bool agrees = true;
        for (size_t c = 0; c < 3; ++c)
            agrees = agrees && std::fabs(cfg[c] - fromPrimaries[c]) <= 1e-3;
        if (agrees) {
            luma = cfg;
        } else {
            if (!warn.empty()) warn += "; ";
            warn += "the OCIO config's luma (" + std::to_string(cfg[0]) + ", " +
                    std::to_string(cfg[1]) + ", " + std::to_string(cfg[2]) + ") is not " +
                    ws->name + "'s: using the Y row of its RGB-to-XYZ matrix";
        }
    }
    if (warning) *warning = warn;
    return true;
}

std::array<double, 3> lumaCoefficients(std::string* warning) {
    std::array<double, 3> luma{};
    std::string err;
    lumaCoefficients(kSceneLinear, luma, err, warning);  // a known space: cannot fail
    return luma;
}

bool applyDisplayTransform(float* rgb, long npixels, std::string& err, const std::string& display,
                           const std::string& view) {
    try {
        const ActiveConfig& a = activeConfig();
        const OCIO::ConstConfigRcPtr& cfg = a.config;
        std::string disp = display.empty() ? cfg->getDefaultDisplay() : display;
        std::string vw = view.empty() ? cfg->getDefaultView(disp.c_str()) : view;
        auto t = OCIO::DisplayViewTransform::Create();
        t->setSrc(OCIO::ROLE_SCENE_LINEAR);
        t->setDisplay(disp.c_str());
        t->setView(vw.c_str());
        OCIO::ConstProcessorRcPtr proc = cfg->getProcessor(t);
        OCIO::ConstCPUProcessorRcPtr cpu = proc->getDefaultCPUProcessor();
        OCIO::PackedImageDesc desc(rgb, npixels, 1, 3);
        cpu->apply(desc);
        return true;
    } catch (const std::exception& e) {
        err = std::string("OCIO display transform failed: ") + e.what();
        return false;
    }
}

namespace {
/// What toSceneLinear converts to: kSceneLinear (every statistics file's colour space) when the
/// config has it (the built-in one does; ACES configs alias it), else the scene_linear role.
const char* sceneLinearTarget(const OCIO::ConstConfigRcPtr& cfg) {
    return cfg->getColorSpace(kSceneLinear) ? kSceneLinear : OCIO::ROLE_SCENE_LINEAR;
}
}  // namespace

std::string sceneLinearName() {
    const OCIO::ConstConfigRcPtr& cfg = activeConfig().config;
    const OCIO::ConstColorSpaceRcPtr cs = cfg->getColorSpace(sceneLinearTarget(cfg));
    return cs ? cs->getName() : std::string(sceneLinearTarget(cfg));
}

bool toSceneLinear(float* rgb, long npixels, const std::string& from, bool& converted,
                   std::string& err) {
    converted = false;
    // OIIO names linear data "Linear" (OpenEXR, HDR) whatever the config calls it.
    for (const char* linear : {"linear", "lin_srgb", "lin_rec709", "scene_linear"})
        if (strcasecmp(from.c_str(), linear) == 0) return true;
    try {
        const OCIO::ConstConfigRcPtr& cfg = activeConfig().config;
        if (!cfg->getColorSpace(from.c_str())) {
            err = "colour space '" + printable(from) + "' is not in the OCIO config" +
                  (std::getenv("OCIO") ? std::string(" ($OCIO)") : std::string(" (mcstat's own)"));
            return false;
        }
        OCIO::ConstProcessorRcPtr proc = cfg->getProcessor(from.c_str(), sceneLinearTarget(cfg));
        if (proc->isNoOp()) return true;
        OCIO::PackedImageDesc desc(rgb, npixels, 1, 3);
        proc->getDefaultCPUProcessor()->apply(desc);
        converted = true;
        return true;
    } catch (const std::exception& e) {
        err = "OCIO conversion from '" + printable(from) +
              "' to scene-linear failed: " + oneLine(e.what());
        return false;
    }
}

}  // namespace mcstat
