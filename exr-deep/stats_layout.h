// Internal: names of the parts, channels and attributes of the statistics file (FORMAT.md), and
// where each channel lives in a StatsImage. Shared by the writer and the reader so they cannot
// drift.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/detail/exr_headers.h"
#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::layout {

inline constexpr int kPartCount = 4;
inline constexpr int kBeauty = 0, kBuffers = 1, kMoments = 2, kFeatures = 3;
/// Part names in file order.
inline constexpr const char* kPartNames[kPartCount] = {"beauty", "buffers", "moments", "features"};
/// Part names in file order of an adaptive-M file (version 2): part 1 is the deep part "vbuffers".
inline constexpr const char* kPartNamesAdaptive[kPartCount] = {"beauty", "vbuffers", "moments",
                                                               "features"};
/// The part names for fixed or adaptive M.
inline const char* const* partNames(bool adaptiveM) {
    return adaptiveM ? kPartNamesAdaptive : kPartNames;
}

/// Version 5: the optional flat part `aovs` directly after the four (fixed M only), present iff
/// StatsHeader::aovs is non-empty and M is fixed (version 6 keeps the AOVs of a file with the
/// adaptive layout in the deep part `vbuffers`, hasAovPart). Its StatsParts bit (kStatsPartAovs) is
/// 1 << kAovs, and in a file that has it, it is part number kAovs.
inline constexpr int kAovs = 4;
inline constexpr const char* kPartAovs = "aovs";
/// Whether a file of `h` has the flat part `aovs`: AOVs with a fixed M.
inline bool hasAovPart(const StatsHeader& h) { return !h.aovs.empty() && !h.adaptiveM; }
/// Version 6: the deep channel of AOV `name` in part `vbuffers` ("aov.<name>": the prefix keeps
/// an AOV called `A`, `Z` or `count` apart from the part's own channels).
std::string aovDeepChannel(const std::string& name);
/// Number of StatsParts bits: the four parts and `aovs` (bit `part` is kStatsPart* of that part).
inline constexpr int kPartBits = 5;
/// Index in the file of the first version-4 part (a state part, or records): after the four and
/// `aovs`.
inline int firstExtraPart(const StatsHeader& h) { return kPartCount + (hasAovPart(h) ? 1 : 0); }

/// Version 4: the optional parts after the four (and `aovs`), in this order when present: the
/// state parts of one owner (a flat and a deep part, named by their owner), then records.
inline constexpr const char* kPartRecords = "records";
/// Version 4 on, parts records: the fields present (kRecordFieldsBase and later optional ones).
inline constexpr const char* kAttrRecordFields = "mcstat:recordFields";
/// State parts (FORMAT.md "State parts with an owner"): the owning operation's registry name and
/// its parameter text ("key=value:key=value"), on both parts.
inline constexpr const char* kAttrStateOwner = "mcstat:stateOwner";
inline constexpr const char* kAttrStateParams = "mcstat:stateParams";
/// Files written before the owner was recorded name no owner: the flat part's name is the owner,
/// its parameters the attribute "mcstat:" + that name, written with ',' between the items and ':'
/// within a list. legacyStateParams turns that into the one grammar (the two separators swapped).
std::string legacyStateParams(const std::string& text);
/// The longest owner name and parameter text a reader takes (the header walk bounds every
/// attribute; these keep messages and --info short).
inline constexpr size_t kMaxStateOwner = 200;
inline constexpr size_t kMaxStateParams = 4096;
/// Whether `name` can name a state part: not empty, at most 255 bytes, and not the name of a
/// part of the format's own (the four, aovs, records).
bool validStatePartName(const std::string& name);

/// Channels of the deep part "vbuffers", one deep sample per sub-buffer: the buffer's mean and
/// count, and Z = buffer index j, A = 1 for generic deep tools (readers ignore Z and A).
inline constexpr int kDeepChannelCount = 6;
inline constexpr const char* kDeepChannels[kDeepChannelCount] = {"R", "G", "B", "count", "Z", "A"};

// Attributes present on every part.
inline constexpr const char* kAttrFormatVersion = "mcstat:formatVersion";  // int
inline constexpr const char* kAttrM = "mcstat:M";                          // int
inline constexpr const char* kAttrSpp = "mcstat:spp";                      // int
inline constexpr const char* kAttrAssignment = "mcstat:assignment";        // string
inline constexpr const char* kAttrRenderer = "mcstat:renderer";            // string
inline constexpr const char* kAttrColorSpace = "mcstat:colorSpace";        // string
inline constexpr const char* kAttrColorInteropID =
    "colorInteropID";                                      // string, part 0 (OpenEXR 3.4)
inline constexpr const char* kAttrSeeds = "mcstat:seeds";  // string
/// Version 2 on: int 0 (fixed M, part "buffers") or 1 (adaptive M, part "vbuffers").
inline constexpr const char* kAttrAdaptiveM = "mcstat:adaptiveM";
/// Version 6 on: string, present exactly in compact files: the rule that chose the pixels keeping
/// their buffers (StatsHeader::compactRule), never empty.
inline constexpr const char* kAttrCompact = "mcstat:compact";
/// Version 6, part moments of a compact file: StatsImage::spread's channels, in its order.
inline constexpr const char* kSpreadChannels[kSpreadFloats] = {
    "spread.buffers", "spread.RR", "spread.GG", "spread.BB", "spread.RG", "spread.RB", "spread.GB"};
/// OpenEXR's part version attribute (int, 1): the Core API wants it on every part once deep parts
/// exist.
inline constexpr const char* kAttrPartVersion = "version";

/// Version 3 on: provenance (FORMAT.md "Version 3").
inline constexpr const char* kAttrVariance = "mcstat:variance";  // string
inline constexpr const char* kAttrFeatures = "mcstat:features";  // string
inline constexpr const char* kAttrSources = "mcstat:sources";    // string
inline constexpr const char* kAttrScene = "mcstat:scene";        // string, optional (any version)

/// Version 5 on, every part: the input's names of the beauty's R, G, B (string vector of 3) and the
/// input part that held it (string); part 0 only: the input's metadata (string, opaque text).
inline constexpr const char* kAttrBeautyChannels = "mcstat:beautyChannels";
inline constexpr const char* kAttrBeautyPart = "mcstat:beautyPart";
inline constexpr const char* kAttrSourceMetadata = "mcstat:sourceMetadata";
/// Version 5, part `aovs` only: string vectors of one entry per AOV channel, in StatsHeader::aovs
/// order: its name, its class (aovClassName) and its input part.
inline constexpr const char* kAttrAovNames = "mcstat:aovNames";
inline constexpr const char* kAttrAovClasses = "mcstat:aovClasses";
inline constexpr const char* kAttrAovParts = "mcstat:aovParts";
/// Longest part name (mcstat:beautyPart, an entry of mcstat:aovParts) a file may hold: OpenEXR's
/// limit for names.
inline constexpr size_t kMaxPartNameBytes = 255;
/// Largest channel list, string vector or other structured attribute value a reader accepts
/// (bytes); the writer refuses an `aovs` part whose channel list would be larger.
inline constexpr uint32_t kMaxStructuredBytes = detail::kMaxStructuredAttributeBytes;
/// Bytes of the channel list of part `aovs` for `h` (OpenEXR's layout: name, NUL, 16 bytes per
/// channel, a final NUL).
uint64_t aovChannelListBytes(const StatsHeader& h);
/// Whether the version-5 fields of `h` are valid (names non-empty, at most kMaxAovNameBytes,
/// unique, none a beauty name; at most kMaxAovs; known classes; fixed M; beauty names distinct;
/// part names at most kMaxPartNameBytes; display window); if not, `problem` says why.
bool checkAovFields(const StatsHeader& h, std::string& problem);

/// The sample-to-buffer rules (FORMAT.md, "Sample assignment"). Round robin is the only rule of
/// format version 1; least count exists only in adaptive files (format version 2); per file only
/// in fixed-M files of version 3.
using mcstat::kAssignmentLeastCount;
using mcstat::kAssignmentPerFile;
using mcstat::kAssignmentRoundRobin;
/// Whether `assignment` is a rule this reader knows for a file with fixed or adaptive M; if not,
/// `problem` says why in a phrase.
/// A compact file (version 6) keeps its full file's rule: round robin or per file.
bool knownAssignment(const std::string& assignment, bool adaptiveM, std::string& problem,
                     bool compact = false);
/// Whether `variance` is a known mcstat:variance value; if not, `problem` says why.
bool knownVariance(const std::string& variance, std::string& problem);

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
    Coverage,
    Aov,
    Spread
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

/// What part moments holds: version 1's count, mean and variance (Full); in a compact file of
/// version 6 also kSpreadChannels (WithSpread); in one of version 7 the count and kSpreadChannels
/// only (Slim: the mean is part beauty's, FORMAT.md "Version 7").
enum class Moments { Full, WithSpread, Slim };
inline Moments momentsOf(const StatsHeader& h) {
    if (!h.compact) return Moments::Full;
    return h.formatVersion >= kStatsFormatVersionSlimMoments ? Moments::Slim : Moments::WithSpread;
}

/// Every channel of part `part` for a file with M sub-buffers, in a fixed order. For the deep part
/// "vbuffers" use kDeepChannels (its flat channel list is empty).
std::vector<ChannelPlace> partChannels(int part, int M, bool adaptiveM = false,
                                       Moments moments = Moments::Full);

/// The channels of part `aovs` for `h` (fixed M): bNNN.<name> of buffer j and AOV a, element
/// offset j * A + a of the M * A floats per pixel; buffers in order, AOVs in header order. Empty
/// without AOVs.
std::vector<ChannelPlace> aovChannels(const StatsHeader& h);

/// Number of floats per pixel over all parts (3 + 4M + 7 + 11, plus M * A for `aovs` AOVs). For
/// adaptive M (no AOVs), the floats of the flat parts plus 4 per buffer is floatsPerPixel(0) + 4 *
/// sum(m_p) / pixels.
/// A compact file adds kSpreadFloats, and from version 7 leaves out the 6 of mean and variance.
size_t floatsPerPixel(int M, size_t aovs = 0, Moments moments = Moments::Full);

/// The array of `img` a channel refers to.
std::vector<float>& arrayOf(StatsImage& img, Array a);
const std::vector<float>& arrayOf(const StatsImage& img, Array a);

}  // namespace mcstat::layout

namespace mcstat::detail {
/// The parts a read of `parts` reads: with the adaptive layout the AOVs live in the deep part
/// `vbuffers`, so asking for them reads the buffers too.
/// A compact file of version 8 keeps the mean of a pixel with one buffer in part beauty, so asking
/// for the buffers reads beauty too.
inline unsigned partsToRead(const StatsHeader& h, unsigned parts) {
    if (h.adaptiveM && !h.aovs.empty() && (parts & kStatsPartAovs)) parts |= kStatsPartBuffers;
    if (compactMeansInBeauty(h) && (parts & kStatsPartBuffers)) parts |= kStatsPartBeauty;
    return parts;
}
/// Sizes the arrays of the parts in `parts` (StatsParts) for img.header's pixels and `buffers`
/// sub-buffers in total, keeping their storage; `offsets` (adaptive M) moves into bufferOffset.
/// The arrays of other parts are emptied. Contents are unspecified: the caller overwrites them.
bool resizeParts(StatsImage& img, unsigned parts, size_t buffers, std::vector<uint64_t>&& offsets,
                 std::string& err);
}  // namespace mcstat::detail
