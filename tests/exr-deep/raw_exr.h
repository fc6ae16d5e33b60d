// Test helper: writes arbitrary (also invalid) statistics files directly with the OpenEXR C++ API,
// from a layout written out independently of the library's, so a slip in the library's layout
// table shows up as a failing test.
#pragma once

#include <OpenEXR/ImfHeader.h>

#include <map>
#include <string>
#include <vector>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::test {

struct RawPart {
    Imf::Header header;  ///< name, type, channels, windows, attributes
    /// Values per channel, row-major over the part's data window; missing channels are zero.
    /// Deep parts: every pixel's samples one after the other, in pixel order (deepCounts[p] each).
    std::map<std::string, std::vector<float>> values;
    /// Deep parts: samples per pixel, row-major (empty: zero samples everywhere).
    std::vector<unsigned> deepCounts;
};

/// The four valid parts of `img`, as FORMAT.md describes them.
std::vector<RawPart> rawPartsFrom(const StatsImage& img);

/// The four valid parts of an adaptive-M `img` (format 2): part 1 is the deep part "vbuffers" with
/// R, G, B, count, Z (= buffer index) and A (= 1).
std::vector<RawPart> rawAdaptivePartsFrom(const StatsImage& img);

/// Writes the parts as a multi-part file (scanline, tiled or deep scanline by header type; deep
/// parts have deepCounts samples per pixel, or none). Throws on OpenEXR errors.
void writeRaw(const std::string& path, const std::vector<RawPart>& parts);

/// The parts of a flat multi-part file as they are (headers with every attribute, values of every
/// channel as FLOAT), e.g. a file the library wrote, to damage and write again with writeRaw.
/// Throws on OpenEXR errors and on deep or tiled parts.
std::vector<RawPart> readRaw(const std::string& path);

/// Sets int attribute `name` = v on every part.
void setIntOnAll(std::vector<RawPart>& parts, const char* name, int v);

}  // namespace mcstat::test
