// The estimator registry: one table feeds `mcstat` commands, the plugin and the benchmarks.
#include "mcstat/registry.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>

#include "mcstat/jung_estimators.h"

namespace mcstat {

namespace {

const EstimatorParamInfo kModeParam{"mode", "lum",
                                    "lum: rank buffers by luminance and return the chosen buffers' "
                                    "RGB; channel: R, G, B independently"};

const EstimatorParamInfo kScaleParam{
    "scale", "rel",
    "rel: gamma/delta is a factor of the pixel's input range max - min; abs: an absolute value"};

/// Parses a finite number in [lo, hi] (lo excluded when loOpen); on failure the error names the
/// estimator, the key, the expected range (`expected`) and the rejected text.
bool parseNumber(const std::string& estimator, const std::string& key, const std::string& value,
                 double lo, double hi, bool loOpen, const char* expected, double& out,
                 std::string& err) {
    errno = 0;
    char* end = nullptr;
    const double v = std::strtod(value.c_str(), &end);
    const bool inRange = (loOpen ? v > lo : v >= lo) && v <= hi;
    if (value.empty() || *end != '\0' || errno != 0 || !std::isfinite(v) || !inRange) {
        err = "estimator '" + estimator + "': " + key + " must be " + expected + ", not '" + value +
              "'";
        return false;
    }
    out = v;
    return true;
}

}  // namespace

const std::vector<EstimatorInfo>& estimatorRegistry() {
    static const std::vector<EstimatorInfo> registry = {
        {"mean",
         "mean",
         "Plain mean of every sample (eq. 1), from the sub-buffers",
         &estimateMean,
         {}},
        {"mon",
         "MoN",
         "Median of the M sub-buffer means (Buisine et al. eq. 2)",
         &estimateMoN,
         {kModeParam}},
        {"gmon",
         "G-MoN",
         "Adaptive median of means: trims c = floor(G*floor(M/2)) means per side (eq. 4, 6)",
         &estimateGMoN,
         {kModeParam}},
        {"gmonb",
         "G-MoN_b",
         "Mean when the Gini coefficient G <= threshold, else MoN (eq. 5)",
         &estimateGMoNb,
         {kModeParam, {"threshold", "0.25", "Gini threshold in [0, 1]"}}},
        // Jung 2016 thesis (chapters 4, 5). MPE(m) (eq. 4.6, 5.2) is MoN, even-M rule included.
        {"median",
         "MPE (median)",
         "Median pixel estimate MPE (Jung eq. 4.6, 5.2): the same estimator as --mon",
         &estimateMoN,
         {kModeParam}},
        {"tmpe",
         "TMPE",
         "Trimmed mean TMPE(alpha) (Jung eq. 5.1): drops floor(alpha*M) means per side, averages "
         "the rest",
         &estimateTMPE,
         {kModeParam,
          {"alpha", "0.25", "breakdown point in [0, 0.5]: 0 = mean, 0.5 = median (MPE)"}}},
        {"myriad",
         "myriad",
         "Myriad (Jung eq. 4.7): argmin sum n_j log(gamma^2 + (x_j - b)^2), global minimum",
         &estimateMyriad,
         {kModeParam,
          {"gamma", "0.05", "scale > 0 (small: mode-like, large: the mean)"},
          kScaleParam}},
        {"meridian",
         "meridian",
         "Meridian (Jung eq. 4.8): the buffer mean minimising sum n_j log(delta + |x_j - b|)",
         &estimateMeridian,
         {kModeParam,
          {"delta", "0.05", "scale > 0 (small: mode-like, large: the median)"},
          kScaleParam}},
    };
    return registry;
}

const EstimatorInfo* findEstimator(std::string_view name) {
    for (const EstimatorInfo& e : estimatorRegistry())
        if (e.name == name) return &e;
    return nullptr;
}

bool parseEstimatorParams(const EstimatorInfo& info, const std::map<std::string, std::string>& kv,
                          EstimatorParams& out, std::string& err) {
    auto accepted = [&info] {
        if (info.params.empty()) return std::string("it takes no parameters");
        std::string s = "accepted: ";
        for (size_t i = 0; i < info.params.size(); ++i) s += (i ? ", " : "") + info.params[i].name;
        return s;
    };
    // Defaults first, so every parameter is set the same way whether given or not.
    std::map<std::string, std::string> all;
    for (const EstimatorParamInfo& pi : info.params) all[pi.name] = pi.defaultValue;
    for (const auto& [key, value] : kv) {
        if (!all.count(key)) {
            err =
                "estimator '" + info.name + "' has no parameter '" + key + "' (" + accepted() + ")";
            return false;
        }
        all[key] = value;
    }
    for (const auto& [key, value] : all) {
        if (key == "mode") {
            if (value == "lum" || value == "luminance")
                out.mode = EstimatorMode::Luminance;
            else if (value == "channel" || value == "rgb")
                out.mode = EstimatorMode::PerChannel;
            else {
                err = "estimator '" + info.name + "': mode must be 'lum' or 'channel', not '" +
                      value + "'";
                return false;
            }
        } else if (key == "threshold") {
            if (!parseNumber(info.name, key, value, 0.0, 1.0, false, "a number in [0, 1]",
                             out.giniThreshold, err))
                return false;
        } else if (key == "alpha") {
            if (!parseNumber(info.name, key, value, 0.0, 0.5, false, "a number in [0, 0.5]",
                             out.alpha, err))
                return false;
        } else if (key == "gamma" || key == "delta") {
            double& dst = key == "gamma" ? out.gamma : out.delta;
            if (!parseNumber(info.name, key, value, 0.0, HUGE_VAL, true, "a finite number > 0", dst,
                             err))
                return false;
        } else if (key == "scale") {
            if (value == "rel" || value == "relative")
                out.scaleRelative = true;
            else if (value == "abs" || value == "absolute")
                out.scaleRelative = false;
            else {
                err = "estimator '" + info.name + "': scale must be 'rel' or 'abs', not '" + value +
                      "'";
                return false;
            }
        }
    }
    return true;
}

}  // namespace mcstat
