// The one registry of estimators. The `mcstat` commands, the (future) OIIO plugin and the
// benchmarks all enumerate it, so a new estimator is written once: add a function to estimators.h
// and an entry to filters/registry.cpp.
#pragma once

#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "mcstat/estimators.h"

namespace mcstat {

using EstimatorFn = void (*)(const PixelBuffers&, const EstimatorParams&, PixelEstimate&,
                             EstimatorScratch&);

struct EstimatorParamInfo {
    std::string name;          ///< modifier / config key, e.g. "mode"
    std::string defaultValue;  ///< as text
    std::string help;
};

struct EstimatorInfo {
    std::string name;   ///< command name without dashes, e.g. "gmon"
    std::string title;  ///< e.g. "G-MoN"
    std::string help;   ///< one line for --help
    EstimatorFn fn = nullptr;
    std::vector<EstimatorParamInfo> params;
};

/// Every estimator, in a stable order.
const std::vector<EstimatorInfo>& estimatorRegistry();
/// nullptr when unknown.
const EstimatorInfo* findEstimator(std::string_view name);

/// Parses key=value parameters for `info` into `out` (which already holds luma coefficients).
/// An unknown key or a bad value is an error naming it and listing the accepted keys.
bool parseEstimatorParams(const EstimatorInfo& info, const std::map<std::string, std::string>& kv,
                          EstimatorParams& out, std::string& err);

}  // namespace mcstat
