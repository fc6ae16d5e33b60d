// The channel lists of a statistics file's parts (header_checker.h): the four parts' channels for
// the file's M (the deep part's with adaptive M), part aovs' bNNN.<name>, each checked by one rule
// (checkChannelList).
#include <cctype>
#include <cstring>
#include <iterator>

#include "header_checker.h"

namespace mcstat::detail {

namespace {

const char* pixelTypeName(exr_pixel_type_t t) {
    switch (t) {
        case EXR_PIXEL_UINT:
            return "UINT";
        case EXR_PIXEL_HALF:
            return "HALF";
        case EXR_PIXEL_FLOAT:
            return "FLOAT";
        default:
            return "unknown";
    }
}

/// Whether `name` has the form bNNN.count.
bool isBufferCountChannel(const char* name) {
    return std::strlen(name) == 10 && name[0] == 'b' && std::isdigit((unsigned char)name[1]) &&
           std::isdigit((unsigned char)name[2]) && std::isdigit((unsigned char)name[3]) &&
           std::strcmp(name + 4, ".count") == 0;
}

/// The names of `places`, in order.
std::vector<std::string> channelNames(const std::vector<layout::ChannelPlace>& places) {
    std::vector<std::string> names;
    names.reserve(places.size());
    for (const layout::ChannelPlace& c : places) names.push_back(c.name);
    return names;
}

}  // namespace

bool HeaderChecker::channelsOf(int part, const std::string& pn, ChannelMap& inFile,
                               int* bufferGroups) {
    const exr_attr_chlist_t* chlist = nullptr;
    if (exr_get_channels(c_, part, &chlist) != EXR_ERR_SUCCESS || chlist == nullptr)
        return fail(fmt::format("part '{}' has no channel list", pn));
    for (int i = 0; i < chlist->num_channels; ++i) {
        const exr_attr_chlist_entry_t& e = chlist->entries[i];
        const std::string name(e.name.str != nullptr ? e.name.str : "", size_t(e.name.length));
        inFile[name] = &e;
        if (bufferGroups != nullptr && isBufferCountChannel(name.c_str())) ++*bufferGroups;
    }
    return true;
}

bool HeaderChecker::checkChannelList(const std::string& pn, ChannelMap& inFile,
                                     const std::vector<std::string>& expected, bool printableNames,
                                     const std::string& missingNote,
                                     const std::string& unexpectedNote) {
    const auto shown = [&](const std::string& name) {
        return printableNames ? printable(name) : name;
    };
    for (const std::string& name : expected) {
        const auto it = inFile.find(name);
        if (it == inFile.end())
            return fail(
                fmt::format("part '{}': missing channel '{}'{}", pn, shown(name), missingNote));
        const exr_attr_chlist_entry_t& e = *it->second;
        if (e.pixel_type != EXR_PIXEL_FLOAT)
            return fail(fmt::format("part '{}': channel '{}' has wrong type {} (expected FLOAT)",
                                    pn, shown(name), pixelTypeName(e.pixel_type)));
        if (e.x_sampling != 1 || e.y_sampling != 1)
            return fail(fmt::format("part '{}': channel '{}' has sampling {}x{} (expected 1x1)", pn,
                                    shown(name), e.x_sampling, e.y_sampling));
        inFile.erase(it);
    }
    if (!inFile.empty())
        return fail(fmt::format("part '{}': unexpected channel '{}'{}", pn,
                                shown(inFile.begin()->first), unexpectedNote));
    return true;
}

bool HeaderChecker::checkAovChannels(const StatsHeader& hdr) {
    const std::string pn = layout::kPartAovs;
    ChannelMap inFile;
    if (!channelsOf(layout::kAovs, pn, inFile)) return false;
    // Expected channels in order (buffer by buffer, AOVs in list order): the first missing one is
    // named; then the first extra one in the file's (sorted) order.
    const std::string counts = fmt::format("{} AOVs x M = {}", hdr.aovs.size(), hdr.M);
    return checkChannelList(pn, inFile, channelNames(layout::aovChannels(hdr)), false,
                            " (" + counts + ")", " (not one of " + counts + ")");
}

bool HeaderChecker::checkChannels(int part, const StatsHeader& hdr) {
    const int M = hdr.M;
    const std::string pn = names_[part];
    ChannelMap inFile;
    int groups = 0;
    if (!channelsOf(part, pn, inFile, &groups)) return false;
    if (adaptive_ && part == layout::kBuffers) {
        std::vector<std::string> names(std::begin(layout::kDeepChannels),
                                       std::end(layout::kDeepChannels));
        for (const AovChannel& a : hdr.aovs) names.push_back(layout::aovDeepChannel(a.name));
        return checkChannelList(pn, inFile, names, true, "", "");
    }
    if (part == layout::kBuffers && groups != M)
        return fail(fmt::format("part '{}' has {} buffer channel groups (bNNN.count) but {} = {}",
                                pn, groups, layout::kAttrM, M));
    // The names of partChannels are the format's own (no file's text): printable() keeps them.
    return checkChannelList(
        pn, inFile, channelNames(layout::partChannels(part, M, false, layout::momentsOf(hdr))),
        true, "", "");
}

}  // namespace mcstat::detail
