// Colour management through OpenColorIO (see include/mcstat/color/color.h).
#include "mcstat/color/color.h"

#include <OpenColorIO/OpenColorIO.h>
#include <strings.h>

#include <cmath>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <sstream>
#include <vector>

#include "mcstat/core/color_space.h"
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
    /// Non-empty when $OCIO names a config this OCIO cannot give (an ocio:// URI before OCIO 2.2):
    /// every use of the config fails with it rather than working in another config unasked.
    std::string error;
};

/// "ocio://..." needs OCIO's built-in configs (OpenColorIO 2.2); empty when this OCIO has them.
std::string uriProblem(const std::string& uri) {
    if (uri.rfind("ocio://", 0) != 0) return "";
#if OCIO_VERSION_HEX < 0x02020000
    return "'" + printable(uri) +
           "': ocio:// URIs (OCIO's built-in configs) need OpenColorIO 2.2 or " +
           "later; this mcstat is built with " + OCIO::GetVersion() + ": give a config file";
#else
    return "";
#endif
}

ActiveConfig loadDefault() {
    ActiveConfig a;
    const char* env = std::getenv("OCIO");
    if (env && *env) {
        const std::string problem = uriProblem(env);
        if (!problem.empty()) {
            a.error = "$OCIO=" + problem + " (or unset $OCIO for mcstat's own config)";
        } else {
            try {
                a.config = OCIO::Config::CreateFromEnv();
                return a;
            } catch (const std::exception& e) {
                a.warning = std::string("$OCIO=") + env + " unusable (" + oneLine(e.what()) +
                            "); using mcstat's built-in config";
            }
        }
    }
    std::istringstream in(detail::kBuiltinOcioConfig);
    a.config = OCIO::Config::CreateFromStream(in);  // our own text: a failure is a build bug
    return a;
}

std::mutex& configMutex() {
    static std::mutex m;
    return m;
}
/// Every config made active, kept for the process's life: a reference handed out stays valid
/// when --colorconfig replaces the config.
std::vector<std::unique_ptr<ActiveConfig>>& configs() {
    static std::vector<std::unique_ptr<ActiveConfig>> v;
    return v;
}

// The config is loaded once per process (or set by setColorConfig): OCIO configs are immutable and
// thread-safe to share.
const ActiveConfig& activeConfig() {
    std::lock_guard<std::mutex> lock(configMutex());
    if (configs().empty()) configs().push_back(std::make_unique<ActiveConfig>(loadDefault()));
    return *configs().back();
}

/// The active config, or false with `err` when $OCIO named one this OCIO cannot give.
bool usableConfig(const ActiveConfig*& a, std::string& err) {
    a = &activeConfig();
    if (a->error.empty()) return true;
    err = a->error;
    return false;
}

/// Where display transforms of pixels in working space `space` start: `src`, a colour space of
/// the config; `matrix` is set (with `note`) when the pixels must first go through a matrix from
/// their chromaticities to the config's scene-linear space because the config lacks the space.
bool displaySource(const OCIO::ConstConfigRcPtr& cfg, const std::string& space,
                   const std::string& disp, const std::string& vw, std::string& src,
                   std::array<std::array<double, 3>, 3>* matrix, bool& useMatrix, std::string& note,
                   std::string& err) {
    src = OCIO::ROLE_SCENE_LINEAR;
    useMatrix = false;
    const WorkingSpace* ws = space.empty() ? nullptr : findWorkingSpace(space);
    const OCIO::ConstColorSpaceRcPtr sl = cfg->getColorSpace(OCIO::ROLE_SCENE_LINEAR);
    const WorkingSpace* slws = sl ? findWorkingSpace(sl->getName()) : nullptr;
    if (!ws || slws == ws) return true;
    if (cfg->getColorSpace(ws->name)) {
        src = ws->name;  // the config knows the space (an ACES config and ACEScg)
        return true;
    }
    if (!slws) {
        err = std::string("the OCIO config has no colour space ") + ws->name +
              " and its scene_linear is no space mcstat knows: give a config with " + ws->name +
              " (--colorconfig)";
        return false;
    }
    // A matrix from the chromaticities to the config's scene-linear space (Bradford between the
    // white points), then the config's view.
    std::array<std::array<double, 3>, 3> m{};
    if (!rgbToRgb(ws->xy, slws->xy, m)) {
        err = std::string("cannot convert ") + ws->name + " to " + slws->name;
        return false;
    }
    if (matrix) *matrix = m;
    useMatrix = true;
    note = std::string(ws->name) + " shown through a matrix to " + slws->name +
           " (from the chromaticities, Bradford-adapted) and the config's " + disp + "/" + vw +
           " view: the config has no " + ws->name + "; give one that has (--colorconfig) for " +
           "its own view";
    return true;
}

}  // namespace

const char* builtinOcioConfig() { return detail::kBuiltinOcioConfig; }

std::string ocioVersion() { return OCIO::GetVersion(); }

bool setColorConfig(const std::string& path, std::string& err) {
    if (const std::string problem = uriProblem(path); !problem.empty()) {
        err = problem;
        return false;
    }
    auto a = std::make_unique<ActiveConfig>();
    try {
        a->config = OCIO::Config::CreateFromFile(path.c_str());
        a->config->validate();
    } catch (const std::exception& e) {
        err = "colour config '" + printable(path) + "' unusable: " + oneLine(e.what());
        return false;
    }
    std::lock_guard<std::mutex> lock(configMutex());
    configs().push_back(std::move(a));
    return true;
}

bool lumaCoefficients(const std::string& space, std::array<double, 3>& luma, std::string& err,
                      std::string* warning) {
    const ActiveConfig* ap = nullptr;
    if (!usableConfig(ap, err)) return false;
    const ActiveConfig& a = *ap;
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
    if (lumaCoefficients(kSceneLinear, luma, err, warning)) return luma;
    // Only an unusable config fails for a known space: the Y row of its primaries, said.
    lumaFromChromaticities(findWorkingSpace(kSceneLinear)->xy, luma);
    if (warning) *warning = err;
    return luma;
}

bool applyDisplayTransform(float* rgb, long npixels, std::string& err, const std::string& display,
                           const std::string& view, const std::string& space, std::string* note) {
    try {
        const ActiveConfig* a = nullptr;
        if (!usableConfig(a, err)) return false;
        const OCIO::ConstConfigRcPtr& cfg = a->config;
        const std::string disp = display.empty() ? cfg->getDefaultDisplay() : display;
        const std::string vw = view.empty() ? cfg->getDefaultView(disp.c_str()) : view;
        std::string src, said;
        std::array<std::array<double, 3>, 3> m{};
        bool useMatrix = false;
        if (!displaySource(cfg, space, disp, vw, src, &m, useMatrix, said, err)) return false;
        if (useMatrix) {
            for (long p = 0; p < npixels; ++p) {
                float* v = rgb + 3 * p;
                const double r = v[0], g = v[1], b = v[2];
                for (size_t i = 0; i < 3; ++i)
                    v[i] = float(m[i][0] * r + m[i][1] * g + m[i][2] * b);
            }
            if (note) *note = said;
        }
        auto t = OCIO::DisplayViewTransform::Create();
        t->setSrc(src.c_str());
        t->setDisplay(disp.c_str());
        t->setView(vw.c_str());
        OCIO::ConstProcessorRcPtr proc = cfg->getProcessor(t);
        OCIO::ConstCPUProcessorRcPtr cpu = proc->getDefaultCPUProcessor();
        OCIO::PackedImageDesc desc(rgb, npixels, 1, 3);
        cpu->apply(desc);
        return true;
    } catch (const std::exception& e) {
        err = std::string("OCIO display transform failed: ") + oneLine(e.what());
        return false;
    }
}

std::string displayNote(const std::string& space) {
    const ActiveConfig* a = nullptr;
    std::string err, src, note;
    bool useMatrix = false;
    if (!usableConfig(a, err)) return "";
    try {
        const OCIO::ConstConfigRcPtr& cfg = a->config;
        const std::string disp = cfg->getDefaultDisplay();
        const std::string vw = cfg->getDefaultView(disp.c_str());
        if (!displaySource(cfg, space, disp, vw, src, nullptr, useMatrix, note, err)) return "";
    } catch (const std::exception&) {
        return "";  // applyDisplayTransform reports it
    }
    return useMatrix ? note : std::string();
}

bool fileRuleColorSpace(const std::string& path, std::string& ocioName, std::string& space,
                        bool& sceneLinear, std::string& err) {
    ocioName.clear();
    space.clear();
    sceneLinear = false;
    const ActiveConfig* a = nullptr;
    if (!usableConfig(a, err)) return false;
    try {
        const OCIO::ConstConfigRcPtr& cfg = a->config;
        if (cfg->filepathOnlyMatchesDefaultRule(path.c_str())) return true;
        const char* name = cfg->getColorSpaceFromFilepath(path.c_str());
        const OCIO::ConstColorSpaceRcPtr cs = name ? cfg->getColorSpace(name) : nullptr;
        if (!cs) return true;  // a rule naming a missing space: validate() refuses such configs
        ocioName = cs->getName();
        const std::string encoding = cs->getEncoding();
        sceneLinear = !cs->isData() && (encoding.empty() || encoding == "scene-linear");
        const WorkingSpace* ws = findWorkingSpace(ocioName);
        for (size_t i = 0; !ws && i < cs->getNumAliases(); ++i)
            ws = findWorkingSpace(cs->getAlias(i));
        if (ws && sceneLinear) space = ws->name;
        return true;
    } catch (const std::exception& e) {
        err = "the OCIO config's file rules failed: " + oneLine(e.what());
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
        const ActiveConfig* a = nullptr;
        if (!usableConfig(a, err)) return false;
        const OCIO::ConstConfigRcPtr& cfg = a->config;
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
