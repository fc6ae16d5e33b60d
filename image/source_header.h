// Private to the image layer: the header of a statistics source, in memory or streamed, so that
// the templates over both (apply_operation.cpp, residual.cpp) read it one way.
#pragma once

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::detail {

inline const StatsHeader& headerOf(const StatsImage& s) { return s.header; }
inline const StatsHeader& headerOf(const StatsBlockSource& s) { return s.header(); }

}  // namespace mcstat::detail
