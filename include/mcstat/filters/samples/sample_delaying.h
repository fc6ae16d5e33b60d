// Density-based sample delaying, the registry's per-sample operation "pajot": Pajot, Barthe and
// Paulin, "Sample-Space Bright Spots Removal Using Density Estimation", Graphics Interface 2011,
// Algorithm 1 (filters/samples/sample_delaying.cpp; the per-pixel estimator in
// sample_delaying_kde.h, its stored state in sample_delaying_state.h).
#pragma once

#include <string>

#include "mcstat/filters/operation.h"
#include "mcstat/filters/samples/sample_delaying_kde.h"

namespace mcstat {

/// SamplesFn of "pajot": R, G, B and `delayed` (samples still delayed per pixel).
bool pajotSamples(const SamplesRequest& req, OperationImage& out, std::string& err);
/// Pajot's parameters from the registry entry's parsed values (method adr, rot or hybrid) and
/// the luminance weights (the values' `luma` when set, else `luma`): what `mcstat
/// --pajot:method=...`, mcstat-render's --pajot options and a stored parameter text go through.
/// Method "stored" names a file's own parameters and is refused here.
bool pajotParamsFrom(const ParamValues& values, const std::array<double, 3>& luma, PajotParams& p,
                     std::string& err);
/// `p` as the registry entry's parameter text ("delayed=64:delta=0:luma=0.2126,0.7152,0.0722:
/// method=hybrid:n=50:t=2", each number the shortest text that reads back exactly): what the
/// state parts carry, and what messages show.
std::string pajotParamText(const PajotParams& p);
/// The inverse: parseParamText, then parseOperationParams over the entry, every key required
/// (a stored run names its luma too). False with one line in `problem`.
bool pajotParamsFromText(const std::string& text, PajotParams& p, std::string& problem);
/// The registry entry "pajot".
Operation pajotOperation();

}  // namespace mcstat
