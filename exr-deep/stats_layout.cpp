#include "stats_layout.h"

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <set>

namespace mcstat::layout {

std::string bufferChannel(int j, const char* component) {
    return fmt::format("b{:03d}.{}", j, component);
}

std::string aovDeepChannel(const std::string& name) { return "aov." + name; }

std::string legacyStateParams(const std::string& text) {
    std::string out = text;
    for (char& c : out) c = c == ',' ? ':' : c == ':' ? ',' : c;
    return out;
}

bool validStatePartName(const std::string& name) {
    if (name.empty() || name.size() > 255 || name == kPartAovs || name == kPartRecords)
        return false;
    for (const char* own :
         {kPartNames[0], kPartNames[1], kPartNames[2], kPartNames[3], kPartNamesAdaptive[kBuffers]})
        if (name == own) return false;
    return true;
}

bool knownAssignment(const std::string& assignment, bool adaptiveM, std::string& problem,
                     bool compact) {
    if (assignment == kAssignmentRoundRobin) return true;
    if (assignment == kAssignmentLeastCount) {
        if (adaptiveM) return true;
        problem = fmt::format("sample assignment '{}' needs adaptive M", printable(assignment));
        return false;
    }
    if (assignment == kAssignmentPerFile) {
        if (!adaptiveM || compact) return true;
        problem = fmt::format("sample assignment '{}' needs a fixed M", printable(assignment));
        return false;
    }
    problem = fmt::format(
        "unknown sample assignment '{}' (this reader knows '{}', '{}' and, with adaptive "
        "M, '{}')",
        printable(assignment), kAssignmentRoundRobin, kAssignmentPerFile, kAssignmentLeastCount);
    return false;
}

bool knownVariance(const std::string& variance, std::string& problem) {
    if (variance == kVarianceSamples || variance == kVarianceBuffers ||
        variance == kVarianceUnknown)
        return true;
    problem =
        fmt::format("unknown variance source '{}' (this reader knows '{}', '{}', '{}')",
                    printable(variance), kVarianceSamples, kVarianceBuffers, kVarianceUnknown);
    return false;
}

}  // namespace mcstat::layout

namespace mcstat {

namespace {
constexpr const char* kFeatureNames[] = {"N", "P", "Albedo", "Z", "A"};
}

std::string featureListText(unsigned bits) {
    std::string s;
    for (int i = 0; i < 5; ++i)
        if (bits & (1u << i)) s += (s.empty() ? "" : ",") + std::string(kFeatureNames[i]);
    return s;
}

bool parseFeatureList(const std::string& text, unsigned& bits, std::string& problem) {
    unsigned out = 0;
    size_t start = 0;
    while (start < text.size()) {
        size_t end = text.find(',', start);
        if (end == std::string::npos) end = text.size();
        const std::string item = text.substr(start, end - start);
        int found = -1;
        for (int i = 0; i < 5; ++i)
            if (item == kFeatureNames[i]) found = i;
        if (found < 0) {
            problem =
                fmt::format("unknown feature '{}' (known: N, P, Albedo, Z, A)", printable(item));
            return false;
        }
        if (out & (1u << found)) {
            problem = fmt::format("feature '{}' listed twice", printable(item));
            return false;
        }
        out |= 1u << found;
        start = end + 1;
        if (end + 1 == text.size()) {  // a trailing comma
            problem = "empty feature name";
            return false;
        }
    }
    bits = out;
    return true;
}

std::string optionalPartsText(const StatsHeader& h) {
    std::vector<std::string> names;
    if (h.hasState()) names = {h.state.flatPart, h.state.deepPart};
    if (h.hasRecords) names.emplace_back(layout::kPartRecords);
    std::string out;
    for (size_t i = 0; i < names.size(); ++i)
        out += (i == 0 ? "" : i + 1 == names.size() ? " and " : ", ") + printable(names[i]);
    return names.empty() ? out : (names.size() == 1 ? "part " : "parts ") + out;
}

int requiredFormatVersion(const StatsHeader& h) {
    // A compact file of version 6 (moments with mean and variance) stays valid; --compact writes 7.
    if (h.compact || (h.adaptiveM && !h.aovs.empty())) return kStatsFormatVersionCompact;
    if (!h.aovs.empty() || h.beautyNames != std::array<std::string, 3>{"R", "G", "B"} ||
        !h.beautyPart.empty() || !h.sourceMetadata.empty())
        return kStatsFormatVersionAovs;
    if (h.hasState() || h.hasRecords) return kStatsFormatVersionSamples;
    if (h.assignment == kAssignmentPerFile || h.variance != kVarianceSamples ||
        h.features != kAllFeatures || !h.sources.empty())
        return kStatsFormatVersionProvenance;
    if (h.adaptiveM) return kStatsFormatVersionAdaptive;
    return kStatsFormatVersionFixed;
}

}  // namespace mcstat

namespace mcstat::layout {

std::vector<ChannelPlace> partChannels(int part, int M, bool adaptiveM, Moments moments) {
    if (adaptiveM && part == kBuffers) return {};
    const size_t m = size_t(M);
    switch (part) {
        case kBeauty:
            return {
                {"R", Array::Beauty, 0, 3}, {"G", Array::Beauty, 1, 3}, {"B", Array::Beauty, 2, 3}};
        case kBuffers: {
            std::vector<ChannelPlace> ch;
            ch.reserve(4 * m);
            for (size_t j = 0; j < m; ++j) {
                ch.push_back({bufferChannel(int(j), "R"), Array::BufferMean, j * 3 + 0, 3 * m});
                ch.push_back({bufferChannel(int(j), "G"), Array::BufferMean, j * 3 + 1, 3 * m});
                ch.push_back({bufferChannel(int(j), "B"), Array::BufferMean, j * 3 + 2, 3 * m});
                ch.push_back({bufferChannel(int(j), "count"), Array::BufferCount, j, m});
            }
            return ch;
        }
        case kMoments: {
            std::vector<ChannelPlace> ch = {{"count", Array::Count, 0, 1}};
            if (moments != Moments::Slim)
                ch.insert(ch.end(), {{"mean.R", Array::Mean, 0, 3},
                                     {"mean.G", Array::Mean, 1, 3},
                                     {"mean.B", Array::Mean, 2, 3},
                                     {"variance.R", Array::Variance, 0, 3},
                                     {"variance.G", Array::Variance, 1, 3},
                                     {"variance.B", Array::Variance, 2, 3}});
            if (moments != Moments::Full)
                for (size_t i = 0; i < size_t(kSpreadFloats); ++i)
                    ch.push_back({kSpreadChannels[i], Array::Spread, i, size_t(kSpreadFloats)});
            return ch;
        }
        case kFeatures:
            return {{"N.X", Array::Normal, 0, 3},      {"N.Y", Array::Normal, 1, 3},
                    {"N.Z", Array::Normal, 2, 3},      {"P.X", Array::Position, 0, 3},
                    {"P.Y", Array::Position, 1, 3},    {"P.Z", Array::Position, 2, 3},
                    {"Albedo.R", Array::Albedo, 0, 3}, {"Albedo.G", Array::Albedo, 1, 3},
                    {"Albedo.B", Array::Albedo, 2, 3}, {"Z", Array::Depth, 0, 1},
                    {"A", Array::Coverage, 0, 1}};
        default:
            return {};
    }
}

std::vector<ChannelPlace> aovChannels(const StatsHeader& h) {
    std::vector<ChannelPlace> ch;
    if (h.aovs.empty() || h.adaptiveM) return ch;
    const size_t m = size_t(h.M), A = h.aovs.size();
    ch.reserve(m * A);
    for (size_t j = 0; j < m; ++j)
        for (size_t a = 0; a < A; ++a)
            ch.push_back(
                {bufferChannel(int(j), h.aovs[a].name.c_str()), Array::Aov, j * A + a, m * A});
    return ch;
}

size_t floatsPerPixel(int M, size_t aovs, Moments moments) {
    return 3 + 4 * size_t(M) + (moments == Moments::Slim ? 1 : 7) + 11 + size_t(M) * aovs +
           (moments != Moments::Full ? size_t(kSpreadFloats) : 0);
}

uint64_t aovChannelListBytes(const StatsHeader& h) {
    if (h.aovs.empty()) return 0;
    if (h.adaptiveM) {  // part vbuffers: its six channels and "aov." + name per AOV, once
        uint64_t bytes = 6 * 24 + 1;
        for (const AovChannel& a : h.aovs) bytes += 4 + uint64_t(a.name.size()) + 1 + 16;
        return bytes;
    }
    uint64_t names = 0;  // "bNNN." + name + NUL + 16 bytes, per AOV and buffer
    for (const AovChannel& a : h.aovs) names += 5 + uint64_t(a.name.size()) + 1 + 16;
    return names * uint64_t(std::max(h.M, 0)) + 1;
}

bool checkAovFields(const StatsHeader& h, std::string& problem) {
    const auto shortName = [](const std::string& s) { return printable(s, 40); };
    const auto badName = [&](const std::string& name, size_t maxBytes, const char* what) {
        if (name.empty()) {
            problem = fmt::format("{} is empty", what);
            return true;
        }
        if (name.size() > maxBytes) {
            problem = fmt::format("{} '{}' has {} bytes, more than {}", what, shortName(name),
                                  name.size(), maxBytes);
            return true;
        }
        if (name.find('\0') != std::string::npos) {
            problem = fmt::format("{} '{}' holds a NUL byte", what, shortName(name));
            return true;
        }
        return false;
    };
    for (size_t c = 0; c < 3; ++c) {
        if (badName(h.beautyNames[c], kMaxAovNameBytes,
                    c == 0   ? "beauty channel name R"
                    : c == 1 ? "beauty channel name G"
                             : "beauty channel name B"))
            return false;
        for (size_t d = 0; d < c; ++d)
            if (h.beautyNames[c] == h.beautyNames[d]) {
                problem = fmt::format("beauty channel name '{}' given twice",
                                      shortName(h.beautyNames[c]));
                return false;
            }
    }
    if (h.beautyPart.size() > kMaxPartNameBytes || h.beautyPart.find('\0') != std::string::npos) {
        problem = fmt::format("beauty part name '{}' is longer than {} bytes or holds a NUL byte",
                              shortName(h.beautyPart), kMaxPartNameBytes);
        return false;
    }
    if (h.displayWidth < 0 || h.displayHeight < 0 ||
        (h.displayWidth == 0) != (h.displayHeight == 0) ||
        int64_t(h.displayX) + h.displayWidth - 1 > std::numeric_limits<int>::max() ||
        int64_t(h.displayY) + h.displayHeight - 1 > std::numeric_limits<int>::max()) {
        problem = fmt::format("invalid display window {}x{} at ({}, {})", h.displayWidth,
                              h.displayHeight, h.displayX, h.displayY);
        return false;
    }
    if (h.aovs.empty()) return true;
    if (h.aovs.size() > size_t(kMaxAovs)) {
        problem = fmt::format("{} AOV channels, more than {}", h.aovs.size(), kMaxAovs);
        return false;
    }
    std::set<std::string> seen;
    for (const AovChannel& a : h.aovs) {
        if (badName(a.name, kMaxAovNameBytes, "AOV name")) return false;
        if (!seen.insert(a.name).second) {
            problem = fmt::format("AOV '{}' listed twice", shortName(a.name));
            return false;
        }
        for (const std::string& b : h.beautyNames)
            if (a.name == b) {
                problem = fmt::format("AOV '{}' is also a beauty channel name", shortName(a.name));
                return false;
            }
        if (int(a.cls) < int(AovClass::Alpha) || int(a.cls) > int(AovClass::Id)) {
            problem = fmt::format("AOV '{}' has unknown class {}", shortName(a.name), int(a.cls));
            return false;
        }
        if (a.part.size() > kMaxPartNameBytes || a.part.find('\0') != std::string::npos) {
            problem = fmt::format(
                "AOV '{}': part name '{}' is longer than {} bytes or holds a NUL "
                "byte",
                shortName(a.name), shortName(a.part), kMaxPartNameBytes);
            return false;
        }
    }
    if (const uint64_t bytes = aovChannelListBytes(h); bytes > kMaxStructuredBytes) {
        problem = fmt::format(
            "{} AOV channels x M = {} need a channel list of {} bytes in part '{}', more than "
            "readers accept ({})",
            h.aovs.size(), h.M, bytes, h.adaptiveM ? "vbuffers" : "aovs", kMaxStructuredBytes);
        return false;
    }
    return true;
}

namespace {
template <class Img>
auto& arrayOfImpl(Img& img, Array a) {
    switch (a) {
        case Array::Beauty:
            return img.beauty;
        case Array::BufferMean:
            return img.bufferMean;
        case Array::BufferCount:
            return img.bufferCount;
        case Array::Count:
            return img.count;
        case Array::Mean:
            return img.mean;
        case Array::Variance:
            return img.variance;
        case Array::Normal:
            return img.normal;
        case Array::Position:
            return img.position;
        case Array::Albedo:
            return img.albedo;
        case Array::Depth:
            return img.depth;
        case Array::Aov:
            return img.aov;
        case Array::Spread:
            return img.spread;
        case Array::Coverage:
            break;
    }
    return img.coverage;
}
}  // namespace

std::vector<float>& arrayOf(StatsImage& img, Array a) { return arrayOfImpl(img, a); }
const std::vector<float>& arrayOf(const StatsImage& img, Array a) { return arrayOfImpl(img, a); }

}  // namespace mcstat::layout
