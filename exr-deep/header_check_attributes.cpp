// The attributes of a statistics file's parts (header_checker.h): each part's, by the rules of its
// version, the same on every part, and what they must satisfy together (FORMAT.md "Validation").
#include "header_checker.h"
#include "mcstat/core/params.h"

namespace mcstat::detail {

bool HeaderChecker::checkAttributes(StatsHeader& hdr) {
    StatsHeader h0;
    // The four parts and part aovs carry every attribute (the version-4 parts are read by name).
    const int checked = hasAovs_ ? layout::kAovs + 1 : layout::kPartCount;
    for (int part = 0; part < checked; ++part) {
        StatsHeader h;
        if (!readPartAttributes(part, h)) return false;
        if (part == 0) {
            h0 = h;
            continue;
        }
        if (!sameAsFirstPart(part, h, h0)) return false;
    }
    if (!checkFileAttributes(h0)) return false;
    hdr = h0;
    return true;
}

bool HeaderChecker::readPartAttributes(int part, StatsHeader& h) {
    int32_t version = 0, M = 0, spp = 0, adaptive = 0;
    const std::string pn = label(part);
    if (!intAttr(part, layout::kAttrFormatVersion, version)) return false;
    // Version 2 on: every part says whether M is adaptive (version 1 has no such attribute).
    if (version >= kStatsFormatVersionAdaptive && !intAttr(part, layout::kAttrAdaptiveM, adaptive))
        return false;
    if (adaptive != 0 && adaptive != 1)
        return fail(fmt::format("part '{}': {} = {}, expected 0 or 1", pn, layout::kAttrAdaptiveM,
                                adaptive));
    h.adaptiveM = adaptive == 1;
    if (!intAttr(part, layout::kAttrM, M) || !intAttr(part, layout::kAttrSpp, spp) ||
        !stringAttr(part, layout::kAttrAssignment, h.assignment) ||
        !stringAttr(part, layout::kAttrRenderer, h.renderer) ||
        !stringAttr(part, layout::kAttrColorSpace, h.colorSpace) ||
        !stringAttr(part, layout::kAttrSeeds, h.seeds))
        return false;
    // Optional in every version: the scene's identity (absent: unknown).
    if (attr(part, layout::kAttrScene) != nullptr && !stringAttr(part, layout::kAttrScene, h.scene))
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
    return true;
}

bool HeaderChecker::sameAsFirstPart(int part, const StatsHeader& h, const StatsHeader& h0) {
    const std::string pn = label(part);
    if (h.M != h0.M)
        return fail(fmt::format("M mismatch: part '{}' has {} = {}, part 'beauty' has {}", pn,
                                layout::kAttrM, h.M, h0.M));
    const auto differs = [&](const char* attrName, const std::string& v, const std::string& v0) {
        return fail(fmt::format("part '{}' has {} = '{}', part 'beauty' has '{}'", pn, attrName,
                                printable(v), printable(v0)));
    };
    if (h.formatVersion != h0.formatVersion)
        return differs(layout::kAttrFormatVersion, std::to_string(h.formatVersion),
                       std::to_string(h0.formatVersion));
    if (h.adaptiveM != h0.adaptiveM)
        return differs(layout::kAttrAdaptiveM, h.adaptiveM ? "1" : "0", h0.adaptiveM ? "1" : "0");
    if (h.spp != h0.spp)
        return differs(layout::kAttrSpp, std::to_string(h.spp), std::to_string(h0.spp));
    if (h.assignment != h0.assignment)
        return differs(layout::kAttrAssignment, h.assignment, h0.assignment);
    if (h.renderer != h0.renderer) return differs(layout::kAttrRenderer, h.renderer, h0.renderer);
    if (h.colorSpace != h0.colorSpace)
        return differs(layout::kAttrColorSpace, h.colorSpace, h0.colorSpace);
    if (h.seeds != h0.seeds) return differs(layout::kAttrSeeds, h.seeds, h0.seeds);
    if (h.scene != h0.scene) return differs(layout::kAttrScene, h.scene, h0.scene);
    if (h.variance != h0.variance) return differs(layout::kAttrVariance, h.variance, h0.variance);
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
    return true;
}

bool HeaderChecker::checkFileAttributes(StatsHeader& h0) {
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
    return true;
}

bool HeaderChecker::checkAovAttributes(StatsHeader& hdr) {
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

}  // namespace mcstat::detail
