// What --info says of a statistics file's headers, as lines of printable text: every string the
// file supplies (renderer, colour space, seeds, sources, channel, part and AOV names) goes
// through printable() (core/untrusted_text.h), so no line holds a byte a terminal acts on. A
// library function so that the CLI and the fuzz targets share it.
#include <fmt/format.h>

#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/stats_file.h"
#include "stats_layout.h"

namespace mcstat {

namespace {

/// Format version 5 (docs/aovs.md): the beauty's names, the windows and every AOV, grouped by
/// layer (the channel name before its last dot) with its class and input part.
void describeAovs(const StatsHeader& h, std::vector<std::string>& lines) {
    lines.push_back(fmt::format("  beauty channels {}, {}, {}{}", printable(h.beautyNames[0]),
                                printable(h.beautyNames[1]), printable(h.beautyNames[2]),
                                h.beautyPart.empty()
                                    ? std::string()
                                    : fmt::format(" (part '{}')", printable(h.beautyPart))));
    if (h.displayWidth > 0)
        lines.push_back(fmt::format("  display window {},{} {} x {} (data window {},{} {} x {})",
                                    h.displayX, h.displayY, h.displayWidth, h.displayHeight,
                                    h.originX, h.originY, h.width, h.height));
    if (!h.sourceMetadata.empty())
        lines.push_back(fmt::format("  source metadata: {} bytes (written back into every result)",
                                    h.sourceMetadata.size()));
    if (h.aovs.empty()) {
        lines.push_back("  aovs: none");
        return;
    }
    lines.push_back(fmt::format("  aovs ({} channels x {} sub-buffers):", h.aovs.size(), h.M));
    size_t i = 0;
    while (i < h.aovs.size()) {
        const AovChannel& a = h.aovs[i];
        const size_t dot = a.name.rfind('.');
        const std::string layer = dot == std::string::npos ? a.name : a.name.substr(0, dot);
        std::string chans = dot == std::string::npos ? a.name : a.name.substr(dot + 1);
        size_t j = i + 1;
        for (; j < h.aovs.size(); ++j) {
            const AovChannel& b = h.aovs[j];
            const size_t d = b.name.rfind('.');
            if (d == std::string::npos || dot == std::string::npos ||
                b.name.substr(0, d) != layer || b.cls != a.cls || b.part != a.part)
                break;
            chans += "," + b.name.substr(d + 1);
        }
        const std::string what = dot == std::string::npos
                                     ? printable(a.name)
                                     : printable(layer) + " (" + printable(chans) + ")";
        std::string line = fmt::format("    {:<32} {:<6} {}", what, aovClassName(a.cls),
                                       a.part.empty() ? "" : "part " + printable(a.part));
        while (!line.empty() && line.back() == ' ') line.pop_back();
        lines.push_back(std::move(line));
        i = j;
    }
}

}  // namespace

std::vector<std::string> describeStatsHeader(const StatsHeader& h) {
    std::vector<std::string> lines;
    lines.push_back(
        fmt::format("  size {} x {} (origin {},{}), {} = {} sub-buffers, spp = {}, assignment {}",
                    h.width, h.height, h.originX, h.originY,
                    h.adaptiveM ? "adaptive M, M_max" : "M", h.M, h.spp, printable(h.assignment)));
    if (h.compact)
        lines.push_back(
            fmt::format("  compact: a pixel keeps its buffers by the rule \"{}\", "
                        "else their mean",
                        printable(h.compactRule)));
    lines.push_back(fmt::format("  renderer \"{}\", colour space {}, seeds {}",
                                printable(h.renderer), printable(h.colorSpace),
                                h.seeds.empty() ? std::string("(none)") : printable(h.seeds, 0)));
    if (!h.scene.empty()) lines.push_back("  scene " + printable(h.scene, 0));
    const bool slim = layout::momentsOf(h) == layout::Moments::Slim;
    if (slim)
        lines.push_back(
            "  variance: not kept (a compact file of version 7 or later keeps the spread of the "
            "buffers --compare needs)");
    if (h.formatVersion >= kStatsFormatVersionProvenance && !slim) {
        // What version 3 says about where the data came from (FORMAT.md, "Version 3").
        const char* variance = h.variance == kVarianceSamples ? "from every sample (Welford)"
                               : h.variance == kVarianceBuffers
                                   ? "estimated from the spread of the buffer means"
                                   : "unknown (stored as NaN)";
        lines.push_back(fmt::format("  variance {}: {}", printable(h.variance), variance));
        if (!h.sources.empty()) lines.push_back("  sources " + printable(h.sources, 0));
    }
    const std::string present = featureListText(h.features);
    const std::string absent = featureListText(kAllFeatures & ~h.features);
    const std::string features =
        absent.empty()
            ? present
            : (present.empty() ? std::string("none") : present) + "; absent, NaN: " + absent;
    if (h.compact)
        lines.push_back(fmt::format(
            "  parts: beauty (R,G,B)  vbuffers (deep: {} or 1 samples R,G,B,count,Z,A{})  "
            "moments (count, {}spread)  features ({})",
            h.M, h.aovs.empty() ? "" : ", aov.*", slim ? "" : "mean.RGB, variance.RGB, ",
            features));
    else if (h.adaptiveM)
        lines.push_back(fmt::format(
            "  parts: beauty (R,G,B)  vbuffers (deep: m_p in 1..{} samples R,G,B,count,Z,A{})  "
            "moments (count, mean.RGB, variance.RGB)  features ({})",
            h.M, h.aovs.empty() ? "" : ", aov.*", features));
    else
        lines.push_back(fmt::format(
            "  parts: beauty (R,G,B)  buffers ({} x b###.R,G,B,count)  moments (count, mean.RGB, "
            "variance.RGB)  features ({})",
            h.M, features));
    if (h.formatVersion >= kStatsFormatVersionAovs) describeAovs(h, lines);
    return lines;
}

}  // namespace mcstat
