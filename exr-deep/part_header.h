// Internal: the header every part of a statistics file starts from (FORMAT.md "Header
// attributes"). The one piece the writer of the four parts (stats_write.cpp) and of the optional
// parts of format version 4 (sample_records.cpp) share: both call it, it calls neither.
#pragma once

#include <OpenEXR/ImfHeader.h>

#include <string>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::detail {

/// A part header with the attributes every part carries (FORMAT.md "Header attributes").
Imf::Header commonHeader(const StatsHeader& h, const std::string& name, bool deep);

}  // namespace mcstat::detail
