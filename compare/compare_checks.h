// Private to compare/: the checks of a comparison's options and sides (compare_checks.cpp), made
// before the engine (comparison.h) runs.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <string>

#include "mcstat/compare/compare.h"

namespace mcstat::detail {

/// The options' ranges and combinations (level, trim, tolerances, tile, refspp).
bool checkOptions(const CompareOptions& opt, std::string& err);
/// The reference's variance image (Mitsuba 3's `_var.exr`) and the rule against what they need.
bool checkReferenceVariance(const OIIO::ImageBuf* var, const OIIO::ImageBuf& ref,
                            const std::string& refName, const CompareOptions& opt,
                            std::string& err);
/// The result's data window (the statistics file's) and its tile side. A tile averages a buffer
/// index over its pixels; with adaptive M (compact files too) the indices do not line up, and the
/// tile is summed from its pixels' estimates and variances instead (PixelSums).
void setWindow(CompareResult& out, const StatsHeader& h, bool adaptive, const CompareOptions& opt);
/// The M a side's buffers give, or an error when they give no variance.
bool sideBuffers(const StatsBlockSource& s, int& M, std::string& err);
/// AOVs of a compact file: a pixel that keeps its mean alone keeps no spread of its AOVs.
bool compactQuantities(const StatsBlockSource& s, const CompareOptions& opt, std::string& err);

}  // namespace mcstat::detail
