// Private to exr-deep/: the checks of a statistics file's headers (stats_header_check.h), one
// theme per file: the order of the checks and the image's size (stats_header_check.cpp), the parts
// and their windows (header_check_parts.cpp), the attributes (header_check_attributes.cpp), the
// channel lists (header_check_channels.cpp) and the chunks against the file's size
// (header_check_chunks.cpp). Through OpenEXR's Core C API, which parses headers without sizing
// anything by the declared image size.
#pragma once

#include <OpenEXR/openexr.h>
#include <fmt/format.h>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/stats_file.h"
#include "stats_layout.h"

namespace mcstat::detail {

/// A data or display window for a message: (xmin,ymin)-(xmax,ymax).
inline std::string windowText(const exr_attr_box2i_t& b) {
    return fmt::format("({},{})-({},{})", b.min.x, b.min.y, b.max.x, b.max.y);
}

inline bool sameBox(const exr_attr_box2i_t& a, const exr_attr_box2i_t& b) {
    return a.min.x == b.min.x && a.min.y == b.min.y && a.max.x == b.max.x && a.max.y == b.max.y;
}

/// The checks of one open file's headers, in the order run() makes them; `err` holds the first
/// failure as "<path>: <problem>".
class HeaderChecker {
  public:
    HeaderChecker(exr_const_context_t ctxt, std::string path) : c_(ctxt), path_(std::move(path)) {}

    bool fail(const std::string& problem) {
        err = path_ + ": " + libraryMessage(problem);
        return false;
    }

    std::string partName(int part) const {
        const char* name = nullptr;
        if (exr_get_name(c_, part, &name) != EXR_ERR_SUCCESS || name == nullptr) return {};
        return name;
    }

    /// Looks up attribute `name` of `part`; nullptr if absent.
    const exr_attribute_t* attr(int part, const char* name) const {
        const exr_attribute_t* a = nullptr;
        if (exr_get_attribute_by_name(c_, part, name, &a) != EXR_ERR_SUCCESS) return nullptr;
        return a;
    }

    bool intAttr(int part, const char* name, int32_t& out) {
        const exr_attribute_t* a = attr(part, name);
        if (a == nullptr)
            return fail(fmt::format("part '{}': missing attribute '{}' (int)", label(part), name));
        if (a->type != EXR_ATTR_INT)
            return fail(fmt::format("part '{}': attribute '{}' has type {}, expected int",
                                    label(part), name, a->type_name));
        out = a->i;
        return true;
    }

    bool stringAttr(int part, const char* name, std::string& out) {
        const exr_attribute_t* a = attr(part, name);
        if (a == nullptr)
            return fail(
                fmt::format("part '{}': missing attribute '{}' (string)", label(part), name));
        if (a->type != EXR_ATTR_STRING || a->string == nullptr)
            return fail(fmt::format("part '{}': attribute '{}' has type {}, expected string",
                                    label(part), name, a->type_name));
        out.assign(a->string->str != nullptr ? a->string->str : "", size_t(a->string->length));
        return true;
    }

    /// A string vector attribute (OpenEXR's stringvector).
    bool stringVectorAttr(int part, const char* name, std::vector<std::string>& out) {
        const exr_attribute_t* a = attr(part, name);
        if (a == nullptr)
            return fail(fmt::format("part '{}': missing attribute '{}' (string vector)",
                                    label(part), name));
        if (a->type != EXR_ATTR_STRING_VECTOR || a->stringvector == nullptr ||
            a->stringvector->n_strings < 0)
            return fail(fmt::format("part '{}': attribute '{}' has type {}, expected string vector",
                                    label(part), name, a->type_name));
        out.clear();
        const exr_attr_string_vector_t& v = *a->stringvector;
        out.reserve(size_t(v.n_strings));
        for (int32_t i = 0; i < v.n_strings; ++i) {
            const exr_attr_string_t& e = v.strings[i];
            out.emplace_back(e.str != nullptr ? e.str : "",
                             e.str != nullptr && e.length > 0 ? size_t(e.length) : size_t(0));
        }
        return true;
    }

    /// What messages call part `part`: its expected name among the first parts, else its own.
    std::string label(int part) const {
        if (part < layout::kPartCount) return names_[part];
        if (part == layout::kAovs && hasAovs_) return layout::kPartAovs;
        return printable(partName(part));
    }

    bool run(const ReadLimits& limits, StatsHeader& hdr);

    std::string err;

  private:
    /// Whether part 0 declares adaptive M (version >= 2 and mcstat:adaptiveM = 1): decides the
    /// expected part names before the attributes are checked in full.
    bool declaresAdaptive() const;
    bool checkVersionFirst();
    bool checkParts();
    /// Whether part `part` is the flat part of state parts with an owner: it carries
    /// mcstat:stateOwner, or (files written before the owner was recorded) "mcstat:" + its name.
    bool isStatePart(int part) const;
    /// The state parts at `part` and `part + 1` into state_: the owner, its parameter text (in the
    /// one grammar, core/params.h) and the parts' names, each checked.
    bool checkStateParts(int part, int n);
    /// Every part's attributes, equal across the parts, and what they must satisfy together.
    bool checkAttributes(StatsHeader& hdr);
    /// One part's attributes into `h`, by the rules of the version it declares.
    bool readPartAttributes(int part, StatsHeader& h);
    /// Part `part`'s attributes `h` equal part 0's `h0` (every part carries them all).
    bool sameAsFirstPart(int part, const StatsHeader& h, const StatsHeader& h0);
    /// Part 0's attributes `h0`, now the file's: the version's own attributes (source metadata,
    /// AOV list) and the rules that join several of them.
    bool checkFileAttributes(StatsHeader& h0);
    /// The channels of part `part` (0..3) for `hdr`'s M; a compact file's part moments adds the
    /// spread channels, and the deep part of version 6 the AOV channels.
    bool checkChannels(int part, const StatsHeader& hdr);
    /// Version 5: the AOV attributes of part `aovs` into hdr.aovs (hasAovs_).
    bool checkAovAttributes(StatsHeader& hdr);
    /// Part `aovs` has exactly the channels bNNN.<name> of hdr's M and AOVs.
    bool checkAovChannels(const StatsHeader& hdr);
    /// The channels of part `part` by name, or false (part `pn` has no channel list); with
    /// `bufferGroups`, the count of its bNNN.count channels.
    using ChannelMap = std::map<std::string, const exr_attr_chlist_entry_t*>;
    bool channelsOf(int part, const std::string& pn, ChannelMap& inFile,
                    int* bufferGroups = nullptr);
    /// The one check of a channel list: each of `expected`, in order, is in `inFile`, FLOAT and
    /// sampled 1x1 (the first that is not is named), and `inFile` holds no other (the first extra
    /// one in the file's sorted order is named). A name appears in the messages through
    /// printable() when `printableNames`, as it is otherwise (part aovs' messages, which never
    /// passed its names through printable(); fail()'s libraryMessage escapes them still);
    /// `missingNote` and `unexpectedNote` end those two messages.
    bool checkChannelList(const std::string& pn, ChannelMap& inFile,
                          const std::vector<std::string>& expected, bool printableNames,
                          const std::string& missingNote, const std::string& unexpectedNote);

  public:
    /// Every chunk of every part lies inside the file: its offset table entry, its packed size
    /// and (deep parts) its sample-count table end within `fileSize` bytes. OpenEXR's readers
    /// would otherwise find a truncated file only while decoding, after pixels are allocated.
    bool checkChunks(uint64_t fileSize);

  private:
    exr_const_context_t c_;
    std::string path_;
    int nparts_ = 0;
    bool adaptive_ = false;
    bool hasRecords_ = false, hasAovs_ = false;
    /// State parts with an owner (FORMAT.md): the owner read by checkStateParts; the flat part's
    /// index (the deep one follows), -1 without.
    StateOwner state_;
    int stateFlat_ = -1;
    /// The part carrying the AOV attributes: `aovs`, or (version 6, adaptive layout) `vbuffers`.
    int aovPart_ = layout::kAovs;
    const char* const* names_ = layout::kPartNames;
};

}  // namespace mcstat::detail
