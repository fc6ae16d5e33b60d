// The estimator registry: one table feeds `mcstat` commands, the plugin and the benchmarks.
#include "mcstat/registry.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>

namespace mcstat {

namespace {

const EstimatorParamInfo kModeParam{
    "mode", "lum",
    "lum: rank buffers by luminance and return the chosen buffers' RGB; channel: R, G, B independently"};

}  // namespace

const std::vector<EstimatorInfo>& estimatorRegistry() {
    static const std::vector<EstimatorInfo> registry = {
        {"mean", "mean", "Plain mean of every sample (eq. 1), from the sub-buffers", &estimateMean, {}},
        {"mon", "MoN", "Median of the M sub-buffer means (Buisine et al. eq. 2)", &estimateMoN,
         {kModeParam}},
        {"gmon", "G-MoN",
         "Adaptive median of means: trims c = floor(G*floor(M/2)) means per side (eq. 4, 6)",
         &estimateGMoN,
         {kModeParam}},
        {"gmonb", "G-MoN_b", "Mean when the Gini coefficient G <= threshold, else MoN (eq. 5)",
         &estimateGMoNb,
         {kModeParam, {"threshold", "0.25", "Gini threshold in [0, 1]"}}},
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
        for (size_t i = 0; i < info.params.size(); ++i)
            s += (i ? ", " : "") + info.params[i].name;
        return s;
    };
    // Defaults first, so every parameter is set the same way whether given or not.
    std::map<std::string, std::string> all;
    for (const EstimatorParamInfo& pi : info.params) all[pi.name] = pi.defaultValue;
    for (const auto& [key, value] : kv) {
        if (!all.count(key)) {
            err = "estimator '" + info.name + "' has no parameter '" + key + "' (" + accepted() + ")";
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
            errno = 0;
            char* end = nullptr;
            const double t = std::strtod(value.c_str(), &end);
            if (value.empty() || *end != '\0' || errno != 0 || !(t >= 0.0 && t <= 1.0)) {
                err = "estimator '" + info.name + "': threshold must be a number in [0, 1], not '" +
                      value + "'";
                return false;
            }
            out.giniThreshold = t;
        }
    }
    return true;
}

}  // namespace mcstat
