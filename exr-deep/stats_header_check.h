// Internal: validation of the headers of a statistics file, before any pixel memory is allocated.
// Uses OpenEXR's Core C API, which parses headers without sizing anything by the declared image
// size and checks attribute sizes against the file size.
#pragma once

#include <cstdint>
#include <string>

#include "mcstat/stats_file.h"

namespace mcstat::detail {

/// Checks every rule of FORMAT.md "Validation" that concerns headers, reading from the open file
/// `fd` of `size` bytes. On success fills `hdr`; on failure `err` is "<path>: <problem>".
bool checkStatsHeaders(int fd, uint64_t size, const std::string& path, const ReadLimits& limits,
                       StatsHeader& hdr, std::string& err);
/// checkExrAttributeSizes (stats_file.h) over an open file.
bool checkExrAttributeSizes(int fd, uint64_t size, const std::string& path, std::string& err);

}  // namespace mcstat::detail
