// Internal: validation of the headers of a statistics file, before any pixel memory is allocated.
// Uses OpenEXR's Core C API, which parses headers without sizing anything by the declared image
// size and checks attribute sizes against the file size.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::detail {

/// Checks every rule of FORMAT.md "Validation" that concerns headers, reading from the open file
/// `fd` of `size` bytes. On success fills `hdr`; on failure `err` is "<path>: <problem>".
bool checkStatsHeaders(int fd, uint64_t size, const std::string& path, const ReadLimits& limits,
                       StatsHeader& hdr, std::string& err);
/// The OpenEXR file open as `fd` (`size` bytes, magic number already seen): every part's name
/// ("" without one) and whether a part declares an mcstat:formatVersion newer than this reader's,
/// from its headers only (checkExrAttributeSizes first, then OpenEXR's Core API). False with
/// "<path>: <problem>" on damaged headers.
bool readExrPartNames(int fd, uint64_t size, const std::string& path,
                      std::vector<std::string>& names, bool& newerStats, std::string& err);

}  // namespace mcstat::detail
