// The registry's per-sample operation "rpf" (filters/samples/rpf.cpp): random parameter
// filtering over a statistics file's per-sample records, by blocks of rows.
#pragma once

#include <string>

#include "mcstat/filters/operation.h"
#include "mcstat/filters/samples/rpf_filter.h"

namespace mcstat {

/// SamplesFn of "rpf": R, G, B filtered by random parameter filtering.
bool rpfSamples(const SamplesRequest& req, OperationImage& out, std::string& err);
/// The registry entry "rpf".
Operation rpfOperation();

/// RpfParams from the registry entry's parsed values.
bool rpfParamsFrom(const ParamValues& values, RpfParams& out, std::string& err);

}  // namespace mcstat
