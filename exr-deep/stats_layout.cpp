#include "stats_layout.h"

#include <fmt/format.h>

namespace mcstat::layout {

std::string bufferChannel(int j, const char* component) {
    return fmt::format("b{:03d}.{}", j, component);
}

bool knownAssignment(const std::string& assignment, bool adaptiveM, std::string& problem) {
    if (assignment == kAssignmentRoundRobin) return true;
    if (assignment == kAssignmentLeastCount) {
        if (adaptiveM) return true;
        problem = fmt::format("sample assignment '{}' needs adaptive M", assignment);
        return false;
    }
    if (assignment == kAssignmentPerFile) {
        if (!adaptiveM) return true;
        problem = fmt::format("sample assignment '{}' needs a fixed M", assignment);
        return false;
    }
    problem = fmt::format(
        "unknown sample assignment '{}' (this reader knows '{}', '{}' and, with adaptive "
        "M, '{}')",
        assignment, kAssignmentRoundRobin, kAssignmentPerFile, kAssignmentLeastCount);
    return false;
}

bool knownVariance(const std::string& variance, std::string& problem) {
    if (variance == kVarianceSamples || variance == kVarianceBuffers ||
        variance == kVarianceUnknown)
        return true;
    problem = fmt::format("unknown variance source '{}' (this reader knows '{}', '{}', '{}')",
                          variance, kVarianceSamples, kVarianceBuffers, kVarianceUnknown);
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
            problem = fmt::format("unknown feature '{}' (known: N, P, Albedo, Z, A)", item);
            return false;
        }
        if (out & (1u << found)) {
            problem = fmt::format("feature '{}' listed twice", item);
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

int requiredFormatVersion(const StatsHeader& h) {
    if (h.hasPajot || h.hasRecords) return kStatsFormatVersionSamples;
    if (h.assignment == kAssignmentPerFile || h.variance != kVarianceSamples ||
        h.features != kAllFeatures || !h.sources.empty())
        return kStatsFormatVersionProvenance;
    if (h.adaptiveM) return kStatsFormatVersionAdaptive;
    return kStatsFormatVersionFixed;
}

}  // namespace mcstat

namespace mcstat::layout {

std::vector<ChannelPlace> partChannels(int part, int M, bool adaptiveM) {
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
        case kMoments:
            return {{"count", Array::Count, 0, 1},         {"mean.R", Array::Mean, 0, 3},
                    {"mean.G", Array::Mean, 1, 3},         {"mean.B", Array::Mean, 2, 3},
                    {"variance.R", Array::Variance, 0, 3}, {"variance.G", Array::Variance, 1, 3},
                    {"variance.B", Array::Variance, 2, 3}};
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

size_t floatsPerPixel(int M) { return 3 + 4 * size_t(M) + 7 + 11; }

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
        case Array::Coverage:
            break;
    }
    return img.coverage;
}
}  // namespace

std::vector<float>& arrayOf(StatsImage& img, Array a) { return arrayOfImpl(img, a); }
const std::vector<float>& arrayOf(const StatsImage& img, Array a) { return arrayOfImpl(img, a); }

}  // namespace mcstat::layout

namespace mcstat::detail {
std::string oneLine(std::string s) {
    for (char& c : s)
        if (c == '\n' || c == '\r') c = ' ';
    while (!s.empty() && s.back() == ' ') s.pop_back();
    return s;
}
}  // namespace mcstat::detail
