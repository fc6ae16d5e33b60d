// Internal: the optional parts of format version 4 as the writer of the four parts needs them:
// implemented by sample_records.cpp, called by stats_write.cpp (the calls point one way; the part
// header both start from is part_header.h's).
#pragma once

#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfMultiPartOutputFile.h>

#include <string>
#include <vector>

#include "mcstat/exr-deep/codec/detail/core_part_writer.h"
#include "mcstat/exr-deep/sample_records.h"

namespace mcstat::detail {

/// Checks the extras against the image (sizes, version 4); `err` names `path`.
bool checkExtras(const std::string& path, const StatsImage& img, const StatsExtras& extras,
                 std::string& err);
/// Appends the headers of the state parts and part records as `extras` asks.
void appendExtraHeaders(std::vector<Imf::Header>& headers, const StatsHeader& h,
                        const StatsExtras& extras);
/// Bytes per pixel of the widest array the flat state part of `extras` points into.
size_t extraPixelBytes(const StatsExtras& extras);
/// Appends the rows of the state parts and records as `extras` asks for the Core writer (`img`:
/// the whole image; the rows point into `extras`).
void appendExtraRows(std::vector<PartRows>& rows, const StatsImage& img, const StatsExtras& extras);
/// Writes those parts (after the four) through the C++ API; throws on failure.
void writeExtraParts(Imf::MultiPartOutputFile& out, const StatsImage& img,
                     const StatsExtras& extras);

}  // namespace mcstat::detail
