// The parts of a statistics file (header_checker.h): the format version first, then the parts'
// names and order, an operation's state parts, and every part's storage and windows.
#include "header_checker.h"
#include "mcstat/core/params.h"

namespace mcstat::detail {

namespace {

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

}  // namespace

bool HeaderChecker::declaresAdaptive() const {
    if (nparts_ < 1) return false;
    const exr_attribute_t* v = attr(0, layout::kAttrFormatVersion);
    const exr_attribute_t* a = attr(0, layout::kAttrAdaptiveM);
    return v != nullptr && v->type == EXR_ATTR_INT && v->i >= kStatsFormatVersionAdaptive &&
           a != nullptr && a->type == EXR_ATTR_INT && a->i == 1;
}

// A newer writer may change anything after the version, so the version is looked at first.
bool HeaderChecker::checkVersionFirst() {
    for (int part = 0; part < nparts_; ++part) {
        const exr_attribute_t* a = attr(part, layout::kAttrFormatVersion);
        if (a != nullptr && a->type == EXR_ATTR_INT && a->i > kStatsFormatVersion)
            return fail(fmt::format("written by a newer mcstat (format {}); this reader knows {}",
                                    a->i, kStatsFormatVersion));
    }
    return true;
}

bool HeaderChecker::isStatePart(int part) const {
    const exr_attribute_t* owner = attr(part, layout::kAttrStateOwner);
    if (owner != nullptr) return true;
    const exr_attribute_t* legacy = attr(part, ("mcstat:" + partName(part)).c_str());
    return legacy != nullptr && legacy->type == EXR_ATTR_STRING;
}

bool HeaderChecker::checkStateParts(int part, int n) {
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

bool HeaderChecker::checkParts() {
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

}  // namespace mcstat::detail
