// The registry's per-sample operation "pajot" (filters/samples/pajot.cpp).
#pragma once

#include <string>

#include "mcstat/filters/operation.h"

namespace mcstat {

/// SamplesFn of "pajot": R, G, B and `delayed` (samples still delayed per pixel).
bool pajotSamples(const SamplesRequest& req, OperationImage& out, std::string& err);
/// The registry entry "pajot".
Operation pajotOperation();

}  // namespace mcstat
