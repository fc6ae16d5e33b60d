// The operation registry: one table feeds the `mcstat` commands and --help, the plugin and the
// benchmarks; parseParamValue is the one checked parser of parameter values.
#include "mcstat/filters/registry.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

#include "mcstat/filters/pixel/myriad.h"
#include "mcstat/filters/samples/pajot.h"
#include "mcstat/filters/samples/rpf.h"

namespace mcstat {

namespace {

// ---- parameters shared by several operations ----------------------------------------------------

ParamSpec modeParam(const std::string& help) {
    ParamSpec p;
    p.name = "mode";
    p.type = ParamType::Enum;
    p.defaultValue = "lum";
    p.choices = {"lum", "channel"};
    p.aliases = {{"luminance", "lum"}, {"rgb", "channel"}};
    p.help = help;
    return p;
}

// Functions, not namespace-scope constants: operationRegistry() may run during another translation
// unit's static initialisation (the benchmarks register from it), before such constants exist.
ParamSpec modeSpec() {
    return modeParam(
        "lum: rank buffers by luminance and return the chosen buffers' RGB, their weights applied "
        "to every AOV; channel: R, G, B independently, refused with AOVs (no one weight per "
        "buffer keeps them summing to the beauty)");
}

ParamSpec scaleSpec() {
    ParamSpec p;
    p.name = "scale";
    p.type = ParamType::Enum;
    p.defaultValue = "rel";
    p.choices = {"rel", "abs"};
    p.aliases = {{"relative", "rel"}, {"absolute", "abs"}};
    p.help =
        "rel: gamma/delta is a factor of the pixel's input range max - min; abs: an absolute "
        "value";
    return p;
}

// Jung's spatial and 3D filters (thesis chapter 5). SpatialParams's defaults are MIF's / 3DMF's
// values below (tests/filters/test_registry.cpp checks it).
ParamSpec sizeSpec() {
    ParamSpec p;
    p.name = "size";
    p.type = ParamType::Size;
    p.min = 1;
    p.max = kMaxSpatialWindow;
    p.odd = true;
    p.defaultValue = "3x3";
    p.help = "window width x height in pixels, centred; clipped at image borders";
    return p;
}

ParamSpec weightParam(const std::string& def, bool fixed) {
    ParamSpec p;
    p.name = "w";
    p.type = ParamType::Int;
    p.min = 1;
    p.max = double(kMaxCentreWeight);
    p.defaultValue = def;
    p.help = "integer weight of the centre pixel (eq. 5.28); 1 = unweighted";
    p.fixed = fixed;
    return p;
}

ParamSpec alphaParam(const std::string& def, bool fixed) {
    return realParam("alpha", 0.0, 0.5, false, def,
                     "breakdown point: floor(alpha*s) weighted copies trimmed per side; 0 = mean, "
                     "0.5 = the weighted median",
                     fixed);
}

ParamSpec spatialModeSpec() {
    return modeParam(
        "lum: rank by luminance, return the chosen pixels'/buffers' RGB, their weights applied to "
        "every AOV; channel: R, G, B independently, refused with AOVs");
}

Operation estimator(const std::string& name, const std::string& title, const std::string& help,
                    const std::string& equation, EstimatorFn fn, std::vector<ParamSpec> params) {
    Operation op;
    op.name = name;
    op.title = title;
    op.help = help;
    op.equation = equation;
    op.input = InputKind::BufferMeans;
    op.fn = fn;
    op.params = std::move(params);
    return op;
}

Operation neighbourhood(const std::string& name, const std::string& title, const std::string& help,
                        const std::string& equation, Neighbourhood over,
                        std::vector<ParamSpec> params) {
    Operation op;
    op.name = name;
    op.title = title;
    op.help = help;
    op.equation = equation;
    op.input = InputKind::Neighbourhood;
    op.over = over;
    op.params = std::move(params);
    return op;
}

// Pajot et al. 2011 (docs/pajot.md): per pixel, its samples in the order taken.
Operation pajot() {
    Operation op;
    op.name = "pajot";
    op.title = "Pajot (ADR/ROT)";
    op.help =
        "Pajot et al.: samples above the last extended kernel-density mode of log-luminance are "
        "delayed (Algorithm 1); from the per-sample records, or the stored online result";
    op.equation = "Pajot et al. Algorithm 1, eq. 3-5";
    op.input = InputKind::Samples;
    op.samples = &pajotOperation;
    ParamSpec method;
    method.name = "method";
    method.type = ParamType::Enum;
    method.defaultValue = "stored";
    method.choices = {"stored", "adr", "rot", "hybrid"};
    method.help =
        "stored: the parameters of the render's online run (hybrid, n=50 when the file has only "
        "records), the other keys ignored; adr (eq. 4), rot (eq. 5), hybrid (section 4.6)";
    op.params = {method, intParam("n", 1, 1e6, "50", "samples of the learning phase (section 4.1)"),
                 intParam("delayed", 0, 1e6, "64",
                          "bound of the dubious list; when full the brightest is discarded"),
                 intParam("t", 1, 1e6, "2", "hybrid: successive close maxima before ROT alone"),
                 realParam("delta", 0.0, HUGE_VAL, false, "0",
                           "hybrid: largest |m_rot - m_adr| / |m_adr| counted as close")};
    return op;
}

// Sen and Darabi 2011 (docs/rpf.md): every sample's colour, screen position, random parameters
// and scene features, filtered by the dependency of colour on the random parameters.
Operation rpf() {
    Operation op;
    op.name = "rpf";
    op.title = "RPF";
    op.help =
        "random parameter filtering (Sen & Darabi): cross-bilateral filter of the per-sample "
        "records weighted by the mutual information of colour and features with the random "
        "parameters; needs mcstat-render --keep-samples";
    op.equation = "Sen & Darabi Algorithms 1-4, eq. 1-20";
    op.input = InputKind::Samples;
    op.samples = &rpfOperation;
    const ParamSpec spikes =
        flagParam("spikes", "0",
                  "section 6.1 (for path-traced scenes with small bright lights, as "
                  "the report applies it): a filtered sample above its pixel's mean "
                  "by more than one deviation becomes the mean; it loses the energy "
                  "of partly covered bright edges (docs/rpf.md)");
    const ParamSpec maps =
        flagParam("maps", "0",
                  "add the first pass's dependency maps (the report's Fig. 6): channels "
                  "rpf.colourOnRandom (eq. 11), rpf.textureOnRandom (eq. 9), rpf.alpha (eq. 15), "
                  "rpf.textureBeta (eq. 16), rpf.neighbours (|N|)");
    op.params = {
        realParam("sigma8", 0.0, 1e6, true, "0.002",
                  "sigma_8^2 of section 6 (bilateral variance at 8 spp; the report uses 0.02 "
                  "for noisy indoor path tracing)"),
        realParam("samples", 0.0, 64.0, true, "0.5",
                  "at most box^2 x spp x this samples per neighbourhood (Algorithm 1 line 8)"),
        intParam("max", 1, 1e7, "16384",
                 "but never more than this many (a pixel costs its samples x |N|)"),
        intParam("passes", 1, 4, "4", "passes with boxes 55, 35, 17, 7 (section 3.2)"),
        spikes,
        intParam("seed", 0, 2147483647, "0", "seed of the neighbourhoods' random draws"),
        maps,
        intParam("rows", 0, 1e6, "0",
                 "output rows per block (0: as many as fit in about 256 MiB of samples); the "
                 "result does not depend on it"),
    };
    return op;
}

}  // namespace

// ---- the table ----------------------------------------------------------------------------------

const std::vector<Operation>& operationRegistry() {
    static const std::vector<Operation> registry = {
        // Buisine et al. 2021
        estimator("mean", "mean", "Plain mean of every sample (eq. 1), from the sub-buffers",
                  "Buisine et al. eq. 1", &estimateMean, {}),
        estimator("mon", "MoN", "Median of the M sub-buffer means (Buisine et al. eq. 2)",
                  "Buisine et al. eq. 2", &estimateMoN, {modeSpec()}),
        estimator(
            "gmon", "G-MoN",
            "Adaptive median of means: trims c = floor(G*floor(M/2)) means per side (eq. 4, 6)",
            "Buisine et al. eq. 4, 6", &estimateGMoN, {modeSpec()}),
        estimator("gmonb", "G-MoN_b",
                  "Mean when the Gini coefficient G <= threshold, else MoN (eq. 5)",
                  "Buisine et al. eq. 5", &estimateGMoNb,
                  {modeSpec(), realParam("threshold", 0.0, 1.0, false, "0.25", "Gini threshold")}),
        // Jung 2016 thesis (chapters 4, 5). MPE(m) (eq. 4.6, 5.2) is MoN, even-M rule included.
        estimator("median", "MPE (median)",
                  "Median pixel estimate MPE (Jung eq. 4.6, 5.2): the same estimator as --mon",
                  "Jung eq. 4.6, 5.2", &estimateMoN, {modeSpec()}),
        estimator("tmpe", "TMPE",
                  "Trimmed mean TMPE(alpha) (Jung eq. 5.1): drops floor(alpha*M) means per side, "
                  "averages the rest",
                  "Jung eq. 5.1", &estimateTMPE,
                  {modeSpec(), realParam("alpha", 0.0, 0.5, false, "0.25",
                                         "breakdown point: 0 = mean, 0.5 = median (MPE)")}),
        estimator("myriad", "myriad",
                  "Myriad (Jung eq. 4.7): argmin sum n_j log(gamma^2 + (x_j - b)^2), global "
                  "minimum",
                  "Jung eq. 4.7", &estimateMyriad,
                  {modeSpec(),
                   realParam("gamma", 0.0, HUGE_VAL, true, "0.05",
                             "scale (small: mode-like, large: the mean)"),
                   scaleSpec()}),
        estimator("meridian", "meridian",
                  "Meridian (Jung eq. 4.8): the buffer mean minimising sum n_j log(delta + |x_j - "
                  "b|)",
                  "Jung eq. 4.8", &estimateMeridian,
                  {modeSpec(),
                   realParam("delta", 0.0, HUGE_VAL, true, "0.05",
                             "scale (small: mode-like, large: the median)"),
                   scaleSpec()}),
        // Jung's spatial filters over an image (section 5.1) and 3D filters over the sub-buffers
        // (section 5.2); filters/window/window_rank.h.
        neighbourhood(
            "mif", "MIF",
            "Median image filter MIF(k x l) of the top image (Jung eq. 5.8); after "
            "--median: MPE+MIF (eq. 5.15)",
            "Jung eq. 5.8", Neighbourhood::Image,
            {sizeSpec(), weightParam("1", true), alphaParam("0.5", true), spatialModeSpec()}),
        neighbourhood(
            "wmif", "WMIF",
            "Weighted median image filter WMIF(w, k x l) of the top image, centre "
            "weight w (eq. 5.6, 5.28); after --tmpe: TMPE+WMIF (eq. 5.14)",
            "Jung eq. 5.6, 5.28", Neighbourhood::Image,
            {sizeSpec(), weightParam("3", false), alphaParam("0.5", true), spatialModeSpec()}),
        neighbourhood(
            "3dmf", "3DMF",
            "3D median filter 3DMF(M x k x l) of the top statistics file: median of "
            "every buffer mean in the window, one vote per buffer (eq. 5.21); "
            "adaptive-M files: one vote per sample",
            "Jung eq. 5.21", Neighbourhood::SubBuffers,
            {sizeSpec(), weightParam("1", true), alphaParam("0.5", true), spatialModeSpec()}),
        neighbourhood(
            "3dwmf", "3DWMF",
            "3D weighted median filter 3DWMF(w, M x k x l): the centre pixel's buffers "
            "weighted w (eq. 5.20, 5.28); adaptive-M files: one vote per sample, w for "
            "the centre's",
            "Jung eq. 5.20, 5.28", Neighbourhood::SubBuffers,
            {sizeSpec(), weightParam("3", false), alphaParam("0.5", true), spatialModeSpec()}),
        neighbourhood(
            "3dwtmf", "3DWTMF",
            "3D weighted trimmed mean filter 3DWTMF(alpha, w, M x k x l) (eq. 5.19); "
            "adaptive-M files: ranked and trimmed per sample",
            "Jung eq. 5.19", Neighbourhood::SubBuffers,
            {sizeSpec(), weightParam("3", false), alphaParam("0.25", false), spatialModeSpec()}),
        // Per-sample operations (InputKind::Samples, a SamplesFn).
        pajot(),
        rpf(),
    };
    return registry;
}

const Operation* findOperation(std::string_view name) {
    for (const Operation& op : operationRegistry())
        if (op.name == name) return &op;
    return nullptr;
}

const std::vector<EstimatorInfo>& estimatorRegistry() {
    static const std::vector<EstimatorInfo> estimators = [] {
        std::vector<EstimatorInfo> v;
        for (const Operation& op : operationRegistry())
            if (op.input == InputKind::BufferMeans) v.push_back(op);
        return v;
    }();
    return estimators;
}

const EstimatorInfo* findEstimator(std::string_view name) {
    for (const EstimatorInfo& e : estimatorRegistry())
        if (e.name == name) return &e;
    return nullptr;
}

std::vector<const ParamSpec*> Operation::settable() const {
    std::vector<const ParamSpec*> v;
    for (const ParamSpec& p : params)
        if (!p.fixed) v.push_back(&p);
    return v;
}

const ParamSpec* Operation::param(std::string_view key) const {
    for (const ParamSpec& p : params)
        if (p.name == key) return &p;
    return nullptr;
}

bool parseOperationParams(const Operation& op, const std::map<std::string, std::string>& kv,
                          ParamValues& out, std::string& err, const std::string& context) {
    const std::string ctx = context.empty() ? op.name : context;
    out.clear();
    // Defaults first, so every parameter is set the same way whether given or not.
    for (const ParamSpec& p : op.params)
        if (!parseParamValue(ctx, p, p.defaultValue, out[p.name], err)) return false;
    for (const auto& [key, value] : kv) {
        const ParamSpec* p = op.param(key);
        if (p == nullptr || p->fixed) {
            const std::vector<const ParamSpec*> keys = op.settable();
            std::string accepted = keys.empty() ? "it takes no parameters" : "accepted: ";
            for (size_t i = 0; i < keys.size(); ++i) accepted += (i ? ", " : "") + keys[i]->name;
            err = "estimator '" + op.name + "' has no parameter '" + key + "' (" + accepted + ")";
            return false;
        }
        if (!parseParamValue(ctx, *p, value, out[key], err)) return false;
    }
    return true;
}

void applyEstimatorParams(const ParamValues& values, EstimatorParams& out) {
    for (const auto& [key, v] : values) {
        if (key == "mode")
            out.mode = v.text == "lum" ? EstimatorMode::Luminance : EstimatorMode::PerChannel;
        else if (key == "threshold")
            out.giniThreshold = v.real;
        else if (key == "alpha")
            out.alpha = v.real;
        else if (key == "gamma")
            out.gamma = v.real;
        else if (key == "delta")
            out.delta = v.real;
        else if (key == "scale")
            out.scaleRelative = v.text == "rel";
    }
}

bool parseEstimatorParams(const EstimatorInfo& info, const std::map<std::string, std::string>& kv,
                          EstimatorParams& out, std::string& err) {
    ParamValues values;
    if (!parseOperationParams(info, kv, values, err, "estimator '" + info.name + "'")) return false;
    applyEstimatorParams(values, out);
    return true;
}

SpatialParams spatialParams(const ParamValues& values, const std::array<double, 3>& luma) {
    SpatialParams p;
    p.luma = luma;
    for (const auto& [key, v] : values) {
        if (key == "mode") {
            p.mode = v.text == "lum" ? EstimatorMode::Luminance : EstimatorMode::PerChannel;
        } else if (key == "size") {
            p.windowWidth = int(v.integer);
            p.windowHeight = int(v.integer2);
        } else if (key == "w") {
            p.centreWeight = v.integer;
        } else if (key == "alpha") {
            p.alpha = v.real;
        }
    }
    return p;
}

int smallestRobustM(const Operation& op, const EstimatorParams& p) {
    if (op.input != InputKind::BufferMeans) return 1;
    const std::string& n = op.name;
    if (n == "mon" || n == "median" || n == "gmonb") return 3;
    if (n == "gmon") return 4;
    if (n == "myriad" || n == "meridian") return 2;
    if (n == "tmpe") {
        constexpr int kLargestM = 999;  // a statistics file's limit
        for (int M = 1; M <= kLargestM; ++M)
            if (tmpeTrim(p.alpha, M) >= 1) return M;
        return kLargestM + 1;  // alpha = 0: TMPE is the mean at every M
    }
    return 1;
}

}  // namespace mcstat
