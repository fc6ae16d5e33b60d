#include "stats_header_check.h"

#include <OpenEXR/openexr.h>
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <vector>

#include "mcstat/core/params.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-codec/core_io.h"
#include "mcstat/exr-codec/exr_headers.h"
#include "mcstat/exr-codec/fd_stream.h"
#include "stats_layout.h"

namespace mcstat::detail {

namespace {

/// exr_context_t closed on scope exit.
struct CoreContext {
    exr_context_t ctxt = nullptr;
    ~CoreContext() {
        if (ctxt != nullptr) exr_finish(&ctxt);
    }
};

/// Opens the headers of `io.fd` with OpenEXR's Core reader into `ctx` (the chunk table is not
/// reconstructed: the checks judge it). `io` must outlive `ctx`. False with a one-line `err`.
bool startCoreRead(CoreFile& io, CoreContext& ctx, const std::string& path, std::string& err) {
    exr_context_initializer_t init = coreFileReader(io);
    init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
    const exr_result_t rv = exr_start_read(&ctx.ctxt, path.c_str(), &init);
    if (rv == EXR_ERR_SUCCESS) return true;
    const std::string what = coreMessage(rv, io.firstError);
    err = fmt::format("{}: truncated or corrupt (header: {})", path, libraryMessage(what));
    return false;
}

const char* storageName(exr_storage_t s) {
    switch (s) {
        case EXR_STORAGE_SCANLINE:
            return "a scanline image";
        case EXR_STORAGE_TILED:
            return "a tiled image";
        case EXR_STORAGE_DEEP_SCANLINE:
            return "a deep scanline image";
        case EXR_STORAGE_DEEP_TILED:
            return "a deep tiled image";
        default:
            return "of unknown storage";
    }
}

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

std::string windowText(const exr_attr_box2i_t& b) {
    return fmt::format("({},{})-({},{})", b.min.x, b.min.y, b.max.x, b.max.y);
}

bool sameBox(const exr_attr_box2i_t& a, const exr_attr_box2i_t& b) {
    return a.min.x == b.min.x && a.min.y == b.min.y && a.max.x == b.max.x && a.max.y == b.max.y;
}

/// Whether `name` has the form bNNN.count.
bool isBufferCountChannel(const char* name) {
    return std::strlen(name) == 10 && name[0] == 'b' && std::isdigit((unsigned char)name[1]) &&
           std::isdigit((unsigned char)name[2]) && std::isdigit((unsigned char)name[3]) &&
           std::strcmp(name + 4, ".count") == 0;
}

class Checker {
  public:
    Checker(exr_const_context_t ctxt, std::string path) : c_(ctxt), path_(std::move(path)) {}

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
    bool checkAttributes(StatsHeader& hdr);
    /// The channels of part `part` (0..3) for `hdr`'s M; a compact file's part moments adds the
    /// spread channels, and the deep part of version 6 the AOV channels.
    bool checkChannels(int part, const StatsHeader& hdr);
    /// Version 5: the AOV attributes of part `aovs` into hdr.aovs (hasAovs_).
    bool checkAovAttributes(StatsHeader& hdr);
    /// Part `aovs` has exactly the channels bNNN.<name> of hdr's M and AOVs.
    bool checkAovChannels(const StatsHeader& hdr);

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

bool Checker::declaresAdaptive() const {
    if (nparts_ < 1) return false;
    const exr_attribute_t* v = attr(0, layout::kAttrFormatVersion);
    const exr_attribute_t* a = attr(0, layout::kAttrAdaptiveM);
    return v != nullptr && v->type == EXR_ATTR_INT && v->i >= kStatsFormatVersionAdaptive &&
           a != nullptr && a->type == EXR_ATTR_INT && a->i == 1;
}

// A newer writer may change anything after the version, so the version is looked at first.
bool Checker::checkVersionFirst() {
    for (int part = 0; part < nparts_; ++part) {
        const exr_attribute_t* a = attr(part, layout::kAttrFormatVersion);
        if (a != nullptr && a->type == EXR_ATTR_INT && a->i > kStatsFormatVersion)
            return fail(fmt::format("written by a newer mcstat (format {}); this reader knows {}",
                                    a->i, kStatsFormatVersion));
    }
    return true;
}

bool Checker::isStatePart(int part) const {
    const exr_attribute_t* owner = attr(part, layout::kAttrStateOwner);
    if (owner != nullptr) return true;
    const exr_attribute_t* legacy = attr(part, ("mcstat:" + partName(part)).c_str());
    return legacy != nullptr && legacy->type == EXR_ATTR_STRING;
}

bool Checker::checkStateParts(int part, int n) {
    StateOwner s;
    s.flatPart = partName(part);
    if (part + 1 >= n || partName(part + 1) == layout::kPartRecords)
        return fail(fmt::format("state part '{}' at index {} is not followed by its deep part",
                                printable(s.flatPart), part));
    s.deepPart = partName(part + 1);
    if (!layout::validStatePartName(s.flatPart) || !layout::validStatePartName(s.deepPart) ||
        s.flatPart == s.deepPart)
        return fail(fmt::format("state parts '{}' and '{}': not names an operation may choose",
                                printable(s.flatPart), printable(s.deepPart)));
    if (attr(part, layout::kAttrStateOwner) != nullptr) {
        std::string deepOwner;
        if (!stringAttr(part, layout::kAttrStateOwner, s.operation) ||
            !stringAttr(part, layout::kAttrStateParams, s.params) ||
            !stringAttr(part + 1, layout::kAttrStateOwner, deepOwner))
            return false;
        if (deepOwner != s.operation)
            return fail(fmt::format("state parts '{}' and '{}' name different owners ('{}', '{}')",
                                    printable(s.flatPart), printable(s.deepPart),
                                    printable(s.operation, 40), printable(deepOwner, 40)));
    } else {  // written before the owner was recorded: the flat part's name is the owner
        s.operation = s.flatPart;
        if (!stringAttr(part, ("mcstat:" + s.flatPart).c_str(), s.params)) return false;
        s.params = layout::legacyStateParams(s.params);
    }
    if (s.operation.empty() || s.operation.size() > layout::kMaxStateOwner ||
        s.operation.find('\0') != std::string::npos)
        return fail(fmt::format("part '{}': attribute '{}' is not an operation's name ('{}')",
                                printable(s.flatPart), layout::kAttrStateOwner,
                                printable(s.operation, 40)));
    std::map<std::string, std::string> kv;
    std::string problem;
    if (s.params.size() > layout::kMaxStateParams)
        return fail(fmt::format("part '{}': parameter text of {} bytes, beyond {}",
                                printable(s.flatPart), s.params.size(), layout::kMaxStateParams));
    if (!parseParamText(s.params, kv, problem))
        return fail(fmt::format("part '{}': parameters '{}': {}", printable(s.flatPart),
                                printable(s.params, 80), printable(problem, 120)));
    state_ = std::move(s);
    return true;
}

bool Checker::checkParts() {
    const int n = nparts_;
    std::string found;
    for (int part = 0; part < n && part < 8; ++part)
        found += (part ? ", '" : "'") + printable(partName(part), 40) + "'";
    if (n > 8) found += ", ...";
    for (int part = 0; part < n && part < layout::kPartCount; ++part) {
        const std::string name = partName(part);
        if (name != names_[part]) {
            // A part of another name at this place: either misnamed or something missing before it.
            return fail(fmt::format("part {} is named '{}', expected '{}' (parts found: {})", part,
                                    printable(name), names_[part], found));
        }
    }
    const std::string expected =
        fmt::format("{}, {}, {}, {}", names_[0], names_[1], names_[2], names_[3]);
    if (n < layout::kPartCount)
        return fail(fmt::format("missing part '{}' (parts found: {}; expected {})", names_[n],
                                found, expected));
    // Version 5: part aovs right after the four (fixed M only). Version 4: optional parts after
    // those, in this order: the state parts of one owner (flat, then deep), then records. Older
    // versions have exactly four parts.
    int extra = layout::kPartCount;
    const exr_attribute_t* v0 = attr(0, layout::kAttrFormatVersion);
    const int version0 = v0 != nullptr && v0->type == EXR_ATTR_INT ? v0->i : 0;
    if (version0 >= kStatsFormatVersionAovs && extra < n && partName(extra) == layout::kPartAovs) {
        if (adaptive_)
            return fail(fmt::format(
                "part '{}' in a file with adaptive M (AOVs need a fixed M and part '{}')",
                layout::kPartAovs, layout::kPartNames[layout::kBuffers]));
        hasAovs_ = true;
        ++extra;
    }
    if (version0 >= kStatsFormatVersionSamples) {
        if (extra < n && partName(extra) != layout::kPartRecords && isStatePart(extra)) {
            if (!checkStateParts(extra, n)) return false;
            stateFlat_ = extra;
            extra += 2;
        }
        if (extra < n && partName(extra) == layout::kPartRecords) {
            hasRecords_ = true;
            ++extra;
        }
    }
    if (n > extra)
        return fail(fmt::format(
            "extra part '{}' at index {} (the file has the 4 parts {}{})",
            printable(partName(extra)), extra, expected,
            version0 >= kStatsFormatVersionAovs
                ? ", then optionally aovs, then optionally an operation's state parts, then records"
            : version0 >= kStatsFormatVersionSamples
                ? ", then optionally an operation's state parts, then records"
                : ""));
    exr_attr_box2i_t dw0{}, disp0{};
    for (int part = 0; part < n; ++part) {
        exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
        const std::string raw = part < layout::kPartCount ? names_[part] : partName(part);
        const std::string pname = printable(raw);  // for the messages
        const bool deep = (adaptive_ && part == layout::kBuffers) ||
                          (stateFlat_ >= 0 && part == stateFlat_ + 1) ||
                          raw == layout::kPartRecords;
        const exr_storage_t want = deep ? EXR_STORAGE_DEEP_SCANLINE : EXR_STORAGE_SCANLINE;
        if (exr_get_storage(c_, part, &storage) != EXR_ERR_SUCCESS || storage != want)
            return fail(fmt::format("part '{}' is {}, expected {}", pname, storageName(storage),
                                    deep ? "a deep scanline image" : "a flat scanline image"));
        exr_attr_box2i_t dw{}, disp{};
        if (exr_get_data_window(c_, part, &dw) != EXR_ERR_SUCCESS ||
            exr_get_display_window(c_, part, &disp) != EXR_ERR_SUCCESS)
            return fail(fmt::format("part '{}' has no data or display window", pname));
        if (part == 0) {
            dw0 = dw;
            disp0 = disp;
        } else if (!sameBox(dw, dw0)) {
            return fail(
                fmt::format("dimension mismatch: part '{}' has data window {}, part '{}' has {}",
                            pname, windowText(dw), names_[0], windowText(dw0)));
        } else if (!sameBox(disp, disp0)) {
            return fail(
                fmt::format("dimension mismatch: part '{}' has display window {}, part '{}' has {}",
                            pname, windowText(disp), names_[0], windowText(disp0)));
        }
    }
    return true;
}

bool Checker::checkAttributes(StatsHeader& hdr) {
    StatsHeader h0;
    // The four parts and part aovs carry every attribute (the version-4 parts are read by name).
    const int checked = hasAovs_ ? layout::kAovs + 1 : layout::kPartCount;
    for (int part = 0; part < checked; ++part) {
        int32_t version = 0, M = 0, spp = 0, adaptive = 0;
        StatsHeader h;
        const std::string pn = label(part);
        if (!intAttr(part, layout::kAttrFormatVersion, version)) return false;
        // Version 2 on: every part says whether M is adaptive (version 1 has no such attribute).
        if (version >= kStatsFormatVersionAdaptive &&
            !intAttr(part, layout::kAttrAdaptiveM, adaptive))
            return false;
        if (adaptive != 0 && adaptive != 1)
            return fail(fmt::format("part '{}': {} = {}, expected 0 or 1", pn,
                                    layout::kAttrAdaptiveM, adaptive));
        h.adaptiveM = adaptive == 1;
        if (!intAttr(part, layout::kAttrM, M) || !intAttr(part, layout::kAttrSpp, spp) ||
            !stringAttr(part, layout::kAttrAssignment, h.assignment) ||
            !stringAttr(part, layout::kAttrRenderer, h.renderer) ||
            !stringAttr(part, layout::kAttrColorSpace, h.colorSpace) ||
            !stringAttr(part, layout::kAttrSeeds, h.seeds))
            return false;
        // Optional in every version: the scene's identity (absent: unknown).
        if (attr(part, layout::kAttrScene) != nullptr &&
            !stringAttr(part, layout::kAttrScene, h.scene))
            return false;
        // Version 3 on: provenance, on every part (versions 1 and 2 imply the defaults).
        if (version >= kStatsFormatVersionProvenance) {
            std::string features;
            if (!stringAttr(part, layout::kAttrVariance, h.variance) ||
                !stringAttr(part, layout::kAttrFeatures, features) ||
                !stringAttr(part, layout::kAttrSources, h.sources))
                return false;
            std::string problem;
            if (!parseFeatureList(features, h.features, problem))
                return fail(fmt::format("part '{}': {}: {}", pn, layout::kAttrFeatures, problem));
        }
        // Version 5 on: the input's beauty channel names and part, on every part.
        if (version >= kStatsFormatVersionAovs) {
            std::vector<std::string> beauty;
            if (!stringVectorAttr(part, layout::kAttrBeautyChannels, beauty) ||
                !stringAttr(part, layout::kAttrBeautyPart, h.beautyPart))
                return false;
            if (beauty.size() != 3)
                return fail(fmt::format("part '{}': {} has {} names, expected 3 (R, G, B)", pn,
                                        layout::kAttrBeautyChannels, beauty.size()));
            for (size_t c = 0; c < 3; ++c) h.beautyNames[c] = beauty[c];
        }
        // Version 6 on: a compact file says so, with its rule, on every part.
        if (version >= kStatsFormatVersionCompact && attr(part, layout::kAttrCompact) != nullptr) {
            if (!stringAttr(part, layout::kAttrCompact, h.compactRule)) return false;
            if (h.compactRule.empty())
                return fail(
                    fmt::format("part '{}': {} is empty (it names the rule that chose "
                                "the pixels keeping their buffers)",
                                pn, layout::kAttrCompact));
            h.compact = true;
        }
        h.formatVersion = version;
        h.M = M;
        h.spp = spp;
        if (part == 0) {
            h0 = h;
            continue;
        }
        if (h.M != h0.M)
            return fail(fmt::format("M mismatch: part '{}' has {} = {}, part 'beauty' has {}", pn,
                                    layout::kAttrM, h.M, h0.M));
        const auto differs = [&](const char* attrName, const std::string& v,
                                 const std::string& v0) {
            return fail(fmt::format("part '{}' has {} = '{}', part 'beauty' has '{}'", pn, attrName,
                                    printable(v), printable(v0)));
        };
        if (h.formatVersion != h0.formatVersion)
            return differs(layout::kAttrFormatVersion, std::to_string(h.formatVersion),
                           std::to_string(h0.formatVersion));
        if (h.adaptiveM != h0.adaptiveM)
            return differs(layout::kAttrAdaptiveM, h.adaptiveM ? "1" : "0",
                           h0.adaptiveM ? "1" : "0");
        if (h.spp != h0.spp)
            return differs(layout::kAttrSpp, std::to_string(h.spp), std::to_string(h0.spp));
        if (h.assignment != h0.assignment)
            return differs(layout::kAttrAssignment, h.assignment, h0.assignment);
        if (h.renderer != h0.renderer)
            return differs(layout::kAttrRenderer, h.renderer, h0.renderer);
        if (h.colorSpace != h0.colorSpace)
            return differs(layout::kAttrColorSpace, h.colorSpace, h0.colorSpace);
        if (h.seeds != h0.seeds) return differs(layout::kAttrSeeds, h.seeds, h0.seeds);
        if (h.scene != h0.scene) return differs(layout::kAttrScene, h.scene, h0.scene);
        if (h.variance != h0.variance)
            return differs(layout::kAttrVariance, h.variance, h0.variance);
        if (h.features != h0.features)
            return differs(layout::kAttrFeatures, featureListText(h.features),
                           featureListText(h0.features));
        if (h.sources != h0.sources) return differs(layout::kAttrSources, h.sources, h0.sources);
        for (size_t c = 0; c < 3; ++c)
            if (h.beautyNames[c] != h0.beautyNames[c])
                return differs(layout::kAttrBeautyChannels, h.beautyNames[c], h0.beautyNames[c]);
        if (h.beautyPart != h0.beautyPart)
            return differs(layout::kAttrBeautyPart, h.beautyPart, h0.beautyPart);
        if (h.compactRule != h0.compactRule)
            return differs(layout::kAttrCompact, h.compactRule, h0.compactRule);
    }
    // Version 5: part 0 carries the source metadata (opaque text), part aovs the AOV list.
    if (h0.formatVersion >= kStatsFormatVersionAovs &&
        !stringAttr(0, layout::kAttrSourceMetadata, h0.sourceMetadata))
        return false;
    // Version 6: AOVs of a file with the adaptive layout are channels of part vbuffers, which
    // then carries the AOV list.
    if (adaptive_ && h0.formatVersion >= kStatsFormatVersionCompact &&
        attr(layout::kBuffers, layout::kAttrAovNames) != nullptr) {
        aovPart_ = layout::kBuffers;
        if (!checkAovAttributes(h0)) return false;
    }
    if (h0.compact && !adaptive_)
        return fail(fmt::format("{} in a file without part 'vbuffers'", layout::kAttrCompact));
    if (hasAovs_ && !checkAovAttributes(h0)) return false;
    if (h0.formatVersion < 1 || h0.formatVersion > kStatsFormatVersion)
        return fail(fmt::format("unsupported {} {} (this reader knows 1..{})",
                                layout::kAttrFormatVersion, h0.formatVersion, kStatsFormatVersion));
    if (h0.adaptiveM != adaptive_)  // part 0 decided the part names; cannot differ, but be sure
        return fail(fmt::format("{} disagrees with the parts", layout::kAttrAdaptiveM));
    if (h0.spp < 0) return fail(fmt::format("negative {} {}", layout::kAttrSpp, h0.spp));
    if (std::string problem;
        !layout::knownAssignment(h0.assignment, h0.adaptiveM, problem, h0.compact))
        return fail(fmt::format("{}: {}", layout::kAttrAssignment, problem));
    if (std::string problem; !layout::knownVariance(h0.variance, problem))
        return fail(fmt::format("{}: {}", layout::kAttrVariance, problem));
    if (std::string problem; !layout::checkAovFields(h0, problem)) return fail(problem);
    // A version-1 or -2 file cannot claim what only version 3 can say (e.g. "perfile"); what only
    // version 5 can say is read from version 5 on only.
    if (h0.formatVersion < requiredFormatVersion(h0))
        return fail(fmt::format("{} = '{}' needs {} >= {} (the file has {})",
                                layout::kAttrAssignment, printable(h0.assignment),
                                layout::kAttrFormatVersion, requiredFormatVersion(h0),
                                h0.formatVersion));
    hdr = h0;
    return true;
}

bool Checker::checkAovAttributes(StatsHeader& hdr) {
    const int part = aovPart_;
    const std::string pn = label(part);
    std::vector<std::string> names, classes, parts;
    if (!stringVectorAttr(part, layout::kAttrAovNames, names) ||
        !stringVectorAttr(part, layout::kAttrAovClasses, classes) ||
        !stringVectorAttr(part, layout::kAttrAovParts, parts))
        return false;
    if (names.size() != classes.size() || names.size() != parts.size())
        return fail(
            fmt::format("part '{}': {} has {} entries, {} {} and {} {} (expected one each "
                        "per AOV)",
                        pn, layout::kAttrAovNames, names.size(), layout::kAttrAovClasses,
                        classes.size(), layout::kAttrAovParts, parts.size()));
    if (names.empty())
        return fail(fmt::format("part '{}': {} is empty (a file without AOVs has no part '{}')", pn,
                                layout::kAttrAovNames, pn));
    if (names.size() > size_t(kMaxAovs))
        return fail(
            fmt::format("part '{}': {} AOV channels, more than {}", pn, names.size(), kMaxAovs));
    std::vector<AovChannel> aovs(names.size());
    for (size_t a = 0; a < names.size(); ++a) {
        aovs[a].name = std::move(names[a]);
        aovs[a].part = std::move(parts[a]);
        if (!parseAovClass(classes[a], aovs[a].cls))
            return fail(fmt::format(
                "part '{}': {}: unknown class '{}' of AOV '{}' (known: alpha, light, data, id)", pn,
                layout::kAttrAovClasses, printable(classes[a], 40), printable(aovs[a].name, 40)));
    }
    hdr.aovs = std::move(aovs);
    return true;
}

bool Checker::checkAovChannels(const StatsHeader& hdr) {
    const std::string pn = layout::kPartAovs;
    const exr_attr_chlist_t* chlist = nullptr;
    if (exr_get_channels(c_, layout::kAovs, &chlist) != EXR_ERR_SUCCESS || chlist == nullptr)
        return fail(fmt::format("part '{}' has no channel list", pn));
    std::map<std::string, const exr_attr_chlist_entry_t*> inFile;
    for (int i = 0; i < chlist->num_channels; ++i) {
        const exr_attr_chlist_entry_t& e = chlist->entries[i];
        inFile[std::string(e.name.str != nullptr ? e.name.str : "", size_t(e.name.length))] = &e;
    }
    // Expected channels in order (buffer by buffer, AOVs in list order): the first missing one is
    // named; then the first extra one in the file's (sorted) order.
    for (const layout::ChannelPlace& c : layout::aovChannels(hdr)) {
        const auto it = inFile.find(c.name);
        if (it == inFile.end())
            return fail(fmt::format("part '{}': missing channel '{}' ({} AOVs x M = {})", pn,
                                    c.name, hdr.aovs.size(), hdr.M));
        const exr_attr_chlist_entry_t& e = *it->second;
        if (e.pixel_type != EXR_PIXEL_FLOAT)
            return fail(fmt::format("part '{}': channel '{}' has wrong type {} (expected FLOAT)",
                                    pn, c.name, pixelTypeName(e.pixel_type)));
        if (e.x_sampling != 1 || e.y_sampling != 1)
            return fail(fmt::format("part '{}': channel '{}' has sampling {}x{} (expected 1x1)", pn,
                                    c.name, e.x_sampling, e.y_sampling));
        inFile.erase(it);
    }
    if (!inFile.empty())
        return fail(fmt::format("part '{}': unexpected channel '{}' (not one of {} AOVs x M = {})",
                                pn, inFile.begin()->first, hdr.aovs.size(), hdr.M));
    return true;
}

bool Checker::checkChannels(int part, const StatsHeader& hdr) {
    const int M = hdr.M;
    const char* pn = names_[part];
    const exr_attr_chlist_t* chlist = nullptr;
    if (exr_get_channels(c_, part, &chlist) != EXR_ERR_SUCCESS || chlist == nullptr)
        return fail(fmt::format("part '{}' has no channel list", pn));
    std::map<std::string, const exr_attr_chlist_entry_t*> inFile;
    int groups = 0;
    for (int i = 0; i < chlist->num_channels; ++i) {
        const exr_attr_chlist_entry_t& e = chlist->entries[i];
        const std::string name(e.name.str != nullptr ? e.name.str : "", size_t(e.name.length));
        inFile[name] = &e;
        if (isBufferCountChannel(name.c_str())) ++groups;
    }
    if (adaptive_ && part == layout::kBuffers) {
        std::vector<std::string> names(std::begin(layout::kDeepChannels),
                                       std::end(layout::kDeepChannels));
        for (const AovChannel& a : hdr.aovs) names.push_back(layout::aovDeepChannel(a.name));
        for (const std::string& name : names) {
            const auto it = inFile.find(name);
            if (it == inFile.end())
                return fail(fmt::format("part '{}': missing channel '{}'", pn, printable(name)));
            const exr_attr_chlist_entry_t& e = *it->second;
            if (e.pixel_type != EXR_PIXEL_FLOAT)
                return fail(
                    fmt::format("part '{}': channel '{}' has wrong type {} (expected FLOAT)", pn,
                                printable(name), pixelTypeName(e.pixel_type)));
            if (e.x_sampling != 1 || e.y_sampling != 1)
                return fail(fmt::format("part '{}': channel '{}' has sampling {}x{} (expected 1x1)",
                                        pn, printable(name), e.x_sampling, e.y_sampling));
            inFile.erase(it);
        }
        if (!inFile.empty())
            return fail(fmt::format("part '{}': unexpected channel '{}'", pn,
                                    printable(inFile.begin()->first)));
        return true;
    }
    if (part == layout::kBuffers && groups != M)
        return fail(fmt::format("part '{}' has {} buffer channel groups (bNNN.count) but {} = {}",
                                pn, groups, layout::kAttrM, M));
    const std::vector<layout::ChannelPlace> expected =
        layout::partChannels(part, M, false, layout::momentsOf(hdr));
    for (const layout::ChannelPlace& c : expected) {
        const auto it = inFile.find(c.name);
        if (it == inFile.end())
            return fail(fmt::format("part '{}': missing channel '{}'", pn, c.name));
        const exr_attr_chlist_entry_t& e = *it->second;
        if (e.pixel_type != EXR_PIXEL_FLOAT)
            return fail(fmt::format("part '{}': channel '{}' has wrong type {} (expected FLOAT)",
                                    pn, c.name, pixelTypeName(e.pixel_type)));
        if (e.x_sampling != 1 || e.y_sampling != 1)
            return fail(fmt::format("part '{}': channel '{}' has sampling {}x{} (expected 1x1)", pn,
                                    c.name, e.x_sampling, e.y_sampling));
        inFile.erase(it);
    }
    if (!inFile.empty())
        return fail(fmt::format("part '{}': unexpected channel '{}'", pn,
                                printable(inFile.begin()->first)));
    return true;
}

bool Checker::run(const ReadLimits& limits, StatsHeader& hdr) {
    if (exr_get_count(c_, &nparts_) != EXR_ERR_SUCCESS) return fail("cannot count the parts");
    if (!checkVersionFirst()) return false;
    adaptive_ = declaresAdaptive();
    names_ = layout::partNames(adaptive_);
    if (!checkParts() || !checkAttributes(hdr)) return false;

    const int maxM = std::min(limits.maxBuffers, kMaxBuffers);
    if (hdr.M < 1 || hdr.M > maxM)
        return fail(fmt::format("{} = {} out of range 1..{}", layout::kAttrM, hdr.M, maxM));

    exr_attr_box2i_t dw{};
    exr_get_data_window(c_, 0, &dw);
    const int64_t w = int64_t(dw.max.x) - dw.min.x + 1, h = int64_t(dw.max.y) - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w > std::numeric_limits<int>::max() ||
        h > std::numeric_limits<int>::max())
        return fail(fmt::format("invalid data window {}", windowText(dw)));
    const int64_t pixels = w * h;  // both < 2^31
    if (pixels > limits.maxPixels)
        return fail(fmt::format("image size {}x{} ({} pixels) exceeds the limit of {} pixels", w, h,
                                pixels, limits.maxPixels));
    // Adaptive M: the least a pixel needs (one buffer and its offset); the sample counts are
    // checked against the limits once read, before the buffers are allocated. Fixed M: every
    // part, part aovs' M * A floats included. A reader holds what one read asks for (a block of
    // rows when streamed, every row when read whole: StatsFileReader::read checks that), so here
    // the limit only refuses an image whose single row cannot be read.
    const int64_t bytesPerPixel =
        hdr.adaptiveM ? int64_t(layout::floatsPerPixel(1, hdr.aovs.size(), layout::momentsOf(hdr)) *
                                    sizeof(float) +
                                sizeof(uint64_t))
                      : int64_t(layout::floatsPerPixel(hdr.M, hdr.aovs.size()) * sizeof(float));
    if (w > limits.maxBytes / bytesPerPixel)
        return fail(fmt::format(
            "a row of image {}x{} with {} = {}{} needs {}{} bytes, exceeding the limit of {} bytes",
            w, h, hdr.adaptiveM ? "adaptive M, M_max" : "M", hdr.M,
            hdr.aovs.empty() ? std::string() : fmt::format(" and {} AOVs", hdr.aovs.size()),
            hdr.adaptiveM ? "at least " : "", double(w) * double(bytesPerPixel), limits.maxBytes));
    for (int part = 0; part < layout::kPartCount; ++part)
        if (!checkChannels(part, hdr)) return false;
    if (hasAovs_ && !checkAovChannels(hdr)) return false;

    hdr.state = state_;
    hdr.hasRecords = hasRecords_;
    if ((hdr.hasState() || hasRecords_) && hdr.formatVersion < kStatsFormatVersionSamples)
        return fail("optional parts need format version 4");
    hdr.width = int(w);
    hdr.height = int(h);
    hdr.originX = dw.min.x;
    hdr.originY = dw.min.y;
    // The display window (the same in every part, checkParts): kept when it differs from the data
    // window, so that equal headers round-trip equal.
    exr_attr_box2i_t disp{};
    exr_get_display_window(c_, 0, &disp);
    hdr.displayX = hdr.displayY = hdr.displayWidth = hdr.displayHeight = 0;
    if (!sameBox(disp, dw)) {
        const int64_t dispW = int64_t(disp.max.x) - disp.min.x + 1,
                      dispH = int64_t(disp.max.y) - disp.min.y + 1;
        if (dispW <= 0 || dispH <= 0 || dispW > std::numeric_limits<int>::max() ||
            dispH > std::numeric_limits<int>::max())
            return fail(fmt::format("invalid display window {}", windowText(disp)));
        hdr.displayX = disp.min.x;
        hdr.displayY = disp.min.y;
        hdr.displayWidth = int(dispW);
        hdr.displayHeight = int(dispH);
    }
    return true;
}

/// The most bytes one packed byte of `c` can unpack to, plus slack for the codec's fixed
/// overhead; 0 when no simple bound holds (PIZ's Huffman runs, B44's and DWA's blocks), which
/// leaves those files to the ReadLimits alone. Deflate stores at most 258 bytes of a match in
/// 2 bits and a bit more, about 1032:1; PXR24 deflates 24 of every 32 bits of a float (x 4/3);
/// OpenEXR's RLE codes at most 128 equal bytes in 2 (64:1).
double maxUnpackRatio(exr_compression_t c) {
    switch (c) {
        case EXR_COMPRESSION_NONE:
            return 1.0;
        case EXR_COMPRESSION_RLE:
            return 64.0;
        case EXR_COMPRESSION_ZIPS:
        case EXR_COMPRESSION_ZIP:
            return 1040.0;
        case EXR_COMPRESSION_PXR24:
            return 1040.0 * 4.0 / 3.0;
        default:
            return 0.0;
    }
}

const char* compressionName(exr_compression_t c) {
    static const char* const kNames[] = {"NONE",  "RLE", "ZIPS", "ZIP",  "PIZ",
                                         "PXR24", "B44", "B44A", "DWAA", "DWAB"};
    return c >= 0 && c < EXR_COMPRESSION_LAST_TYPE ? kNames[c] : "unknown";
}

bool Checker::checkChunks(uint64_t fileSize) {
    for (int part = 0; part < nparts_; ++part) {
        const std::string pn = printable(partName(part));
        exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
        exr_attr_box2i_t dw{};
        int32_t lines = 0;
        if (exr_get_storage(c_, part, &storage) != EXR_ERR_SUCCESS ||
            exr_get_data_window(c_, part, &dw) != EXR_ERR_SUCCESS ||
            exr_get_scanlines_per_chunk(c_, part, &lines) != EXR_ERR_SUCCESS || lines < 1)
            return fail(fmt::format("truncated or corrupt (part '{}': no chunk layout)", pn));
        if (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_DEEP_SCANLINE) continue;
        exr_compression_t comp = EXR_COMPRESSION_LAST_TYPE;
        if (exr_get_compression(c_, part, &comp) != EXR_ERR_SUCCESS)
            return fail(fmt::format("truncated or corrupt (part '{}': no compression)", pn));
        const double ratio = maxUnpackRatio(comp);
        // What a header claims is checked against what the file holds: a chunk cannot unpack to
        // more than its codec allows, so a small file cannot claim a large image (for ZIP, an
        // image at most about 1000 times the file's size reaches the allocations).
        auto tooDense = [&](uint64_t packed, uint64_t unpacked) {
            return ratio > 0.0 && packed != unpacked &&
                   double(unpacked) > ratio * double(packed) + 64.0;
        };
        const uint64_t width = uint64_t(int64_t(dw.max.x) - dw.min.x + 1);
        for (int64_t y = dw.min.y; y <= dw.max.y; y += lines) {
            exr_chunk_info_t ci{};
            const exr_result_t rv = exr_read_scanline_chunk_info(c_, part, int(y), &ci);
            uint64_t end = ci.data_offset + ci.packed_size;
            bool inside = rv == EXR_ERR_SUCCESS && ci.data_offset <= fileSize &&
                          ci.packed_size <= fileSize - ci.data_offset;
            if (inside && storage == EXR_STORAGE_DEEP_SCANLINE) {
                end = ci.sample_count_data_offset + ci.sample_count_table_size;
                inside = ci.sample_count_data_offset <= fileSize &&
                         ci.sample_count_table_size <= fileSize - ci.sample_count_data_offset;
            }
            if (!inside)
                return fail(fmt::format(
                    "truncated or corrupt (part '{}': the chunk of row {} {} the file's {} bytes)",
                    pn, y,
                    rv == EXR_ERR_SUCCESS ? fmt::format("ends at byte {}, beyond", end)
                                          : std::string("has no valid offset within"),
                    fileSize));
            const uint64_t rows = uint64_t(std::min<int64_t>(lines, int64_t(dw.max.y) - y + 1));
            const uint64_t countTable = width * rows * sizeof(int32_t);
            const bool countsTooDense = storage == EXR_STORAGE_DEEP_SCANLINE &&
                                        tooDense(ci.sample_count_table_size, countTable);
            if (tooDense(ci.packed_size, ci.unpacked_size) || countsTooDense)
                return fail(fmt::format(
                    "truncated or corrupt (part '{}': the chunk of row {} claims {} bytes from "
                    "{}, more than {} compression gives ({:.0f}:1))",
                    pn, y, countsTooDense ? countTable : ci.unpacked_size,
                    countsTooDense ? ci.sample_count_table_size : ci.packed_size,
                    compressionName(comp), ratio));
        }
    }
    return true;
}

}  // namespace

bool readExrPartNames(int fd, uint64_t size, const std::string& path,
                      std::vector<std::string>& names, bool& newerStats, std::string& err) {
    if (!checkAttributeSizes(fd, size, path, err)) return false;
    CoreFile io{fd, int64_t(size), {}};
    CoreContext ctx;
    if (!startCoreRead(io, ctx, path, err)) return false;
    int n = 0;
    if (exr_get_count(ctx.ctxt, &n) != EXR_ERR_SUCCESS) {
        err = fmt::format("{}: truncated or corrupt (header: no part count)", path);
        return false;
    }
    Checker checker(ctx.ctxt, path);
    names.clear();
    newerStats = false;
    for (int part = 0; part < n; ++part) {
        names.push_back(checker.partName(part));
        const exr_attribute_t* v = checker.attr(part, layout::kAttrFormatVersion);
        if (v != nullptr && v->type == EXR_ATTR_INT && v->i > kStatsFormatVersion)
            newerStats = true;
    }
    return true;
}

bool checkStatsHeaders(int fd, uint64_t size, const std::string& path, const ReadLimits& limits,
                       StatsHeader& hdr, std::string& err) {
    unsigned char magic[4] = {};
    if (size == 0) {
        err = path + ": not an OpenEXR file (empty file)";
        return false;
    }
    const int64_t got = preadFull(fd, magic, 4, 0);
    if (got < 0) {
        err = fmt::format("{}: cannot read ({})", path, std::strerror(errno));
        return false;
    }
    if (got < 4 || std::memcmp(magic, kExrMagic, 4) != 0) {
        err = path + ": not an OpenEXR file";
        return false;
    }

    if (!checkAttributeSizes(fd, size, path, err)) return false;

    CoreFile io{fd, int64_t(size), {}};
    CoreContext ctx;
    if (!startCoreRead(io, ctx, path, err)) return false;
    Checker checker(ctx.ctxt, path);
    if (!checker.run(limits, hdr) || !checker.checkChunks(size)) {
        err = checker.err;
        return false;
    }
    return true;
}

}  // namespace mcstat::detail
