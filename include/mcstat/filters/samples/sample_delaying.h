// The registry's per-sample operation "pajot" (filters/samples/pajot.cpp).
#pragma once

#include <string>

#include "mcstat/filters/operation.h"
#include "mcstat/filters/samples/pajot_kde.h"

namespace mcstat {

/// SamplesFn of "pajot": R, G, B and `delayed` (samples still delayed per pixel).
bool pajotSamples(const SamplesRequest& req, OperationImage& out, std::string& err);
/// Pajot's parameters from the registry entry's parsed values (method adr, rot or hybrid) and
/// the luminance weights: what `mcstat --pajot:method=...` and mcstat-render's --pajot options
/// go through. Method "stored" names a file's own parameters and is refused here.
bool pajotParamsFrom(const ParamValues& values, const std::array<double, 3>& luma, PajotParams& p,
                     std::string& err);
/// The registry entry "pajot".
Operation pajotOperation();

}  // namespace mcstat
