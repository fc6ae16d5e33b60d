// The one registry of operations: everything an image can be made with, one line per operation
// (filters/registry.cpp). The `mcstat` commands and their --help, the OIIO plugin's
// `mcstat:estimator` / `?estimator=` choices, the streamed path, the benchmarks and the generic
// tests are all generated from it.
//
// The rule (docs/architecture.md): an operation is its file pair (filters/<input>/<method>.cpp and
// include/mcstat/filters/<input>/<method>.h, <input> being pixel, window or samples), its line in
// filters/registry.cpp, its line in filters/CMakeLists.txt and its tests. Its file declares its
// parameters, binds them to its own struct, holds the kernel and states its halo (operation.h);
// nothing outside it but the one dispatcher (image/imageops.cpp, applyOperation) names an
// operation or switches on its kind.
#pragma once

#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "mcstat/filters/operation.h"

namespace mcstat {

/// Every operation, in a stable order: the per-pixel estimators, then the neighbourhood filters,
/// then the per-sample operations.
const std::vector<Operation>& operationRegistry();
/// nullptr when unknown.
const Operation* findOperation(std::string_view name);

/// The BufferMeans operations (the estimators over sub-buffer means), in registry order.
const std::vector<Operation>& estimatorRegistry();
/// A BufferMeans operation; nullptr when unknown or of another kind.
const Operation* findEstimator(std::string_view name);

// parseOperationParams (operation.h) parses an operation's key=value parameters.

/// A BufferMeans operation's kernel with parameters `kv` over its defaults and the luminance
/// weights `luma`: parseOperationParams, then the operation's bindPixel. False with `err` for a
/// bad key or value, or an operation of another kind.
bool bindPixelKernel(const Operation& op, const std::map<std::string, std::string>& kv,
                     const std::array<double, 3>& luma, PixelKernel& out, std::string& err);

}  // namespace mcstat
