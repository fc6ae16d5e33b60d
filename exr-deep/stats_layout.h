// Internal: names of the parts, channels and attributes of the statistics file v1 (FORMAT.md), and
// where each channel lives in a StatsImage. Shared by the writer and the reader so they cannot
// drift.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "mcstat/stats_file.h"

namespace mcstat::layout {

inline constexpr int kPartCount = 4;
inline constexpr int kBeauty = 0, kBuffers = 1, kMoments = 2, kFeatures = 3;
/// Part names in file order.
inline constexpr const char* kPartNames[kPartCount] = {"beauty", "buffers", "moments", "features"};

// Attributes present on every part.
inline constexpr const char* kAttrFormatVersion = "mcstat:formatVersion";  // int
inline constexpr const char* kAttrM = "mcstat:M";                          // int
inline constexpr const char* kAttrSpp = "mcstat:spp";                      // int
inline constexpr const char* kAttrAssignment = "mcstat:assignment";        // string
inline constexpr const char* kAttrRenderer = "mcstat:renderer";            // string
inline constexpr const char* kAttrColorSpace = "mcstat:colorSpace";        // string
inline constexpr const char* kAttrSeeds = "mcstat:seeds";                  // string
/// OpenEXR's part version attribute (int, 1): the Core API wants it on every part once deep parts
/// exist.
inline constexpr const char* kAttrPartVersion = "version";

/// The only assignment rule of format version 1.
inline constexpr const char* kAssignmentRoundRobin = "roundrobin";

/// Which StatsImage array a channel is stored in.
enum class Array {
    Beauty,
    BufferMean,
    BufferCount,
    Count,
    Mean,
    Variance,
    Normal,
    Position,
    Albedo,
    Depth,
    Coverage
};

/// One FLOAT channel: its name and its place in the pixel-interleaved array
/// (element of pixel p is array[p * stride + offset]).
struct ChannelPlace {
    std::string name;
    Array array;
    size_t offset;  ///< in floats, within one pixel
    size_t stride;  ///< floats per pixel in that array
};

/// Channel name of buffer j's component, e.g. bufferChannel(7, "R") == "b007.R".
std::string bufferChannel(int j, const char* component);

/// Every channel of part `part` for a file with M sub-buffers, in a fixed order.
std::vector<ChannelPlace> partChannels(int part, int M);

/// Number of floats per pixel over all parts (3 + 4M + 7 + 11).
size_t floatsPerPixel(int M);

/// The array of `img` a channel refers to.
std::vector<float>& arrayOf(StatsImage& img, Array a);
const std::vector<float>& arrayOf(const StatsImage& img, Array a);

}  // namespace mcstat::layout

namespace mcstat::detail {
/// `s` with line breaks replaced by spaces (library messages must stay on one line).
std::string oneLine(std::string s);
}  // namespace mcstat::detail
