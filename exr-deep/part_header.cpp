// The attributes every part of a statistics file carries (part_header.h), called by the writer of
// the four parts (stats_write.cpp) and of the optional ones (sample_records.cpp).
#include "part_header.h"

#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfStringVectorAttribute.h>

#include "stats_layout.h"
#include "window.h"

namespace mcstat::detail {

Imf::Header commonHeader(const StatsHeader& h, const std::string& name, bool deep) {
    const Imath::Box2i window = windowOf(h);
    // Deep parts cannot use ZIP (16 lines); ZIPS (one line) is the deflate they allow.
    Imf::Header hdr(displayWindowOf(h), window, 1.f, Imath::V2f(0.f, 0.f), 1.f, Imf::INCREASING_Y,
                    deep ? Imf::ZIPS_COMPRESSION : Imf::ZIP_COMPRESSION);
    hdr.zipCompressionLevel() = 4;  // fixed, so equal images give equal bytes
    hdr.setName(name);
    hdr.setType(deep ? Imf::DEEPSCANLINE : Imf::SCANLINEIMAGE);
    hdr.insert(layout::kAttrPartVersion, Imf::IntAttribute(1));
    hdr.insert(layout::kAttrFormatVersion, Imf::IntAttribute(h.formatVersion));
    if (h.formatVersion >= kStatsFormatVersionAdaptive)
        hdr.insert(layout::kAttrAdaptiveM, Imf::IntAttribute(h.adaptiveM ? 1 : 0));
    hdr.insert(layout::kAttrM, Imf::IntAttribute(h.M));
    hdr.insert(layout::kAttrSpp, Imf::IntAttribute(int(h.spp)));
    hdr.insert(layout::kAttrAssignment, Imf::StringAttribute(h.assignment));
    hdr.insert(layout::kAttrRenderer, Imf::StringAttribute(h.renderer));
    hdr.insert(layout::kAttrColorSpace, Imf::StringAttribute(h.colorSpace));
    hdr.insert(layout::kAttrSeeds, Imf::StringAttribute(h.seeds));
    if (!h.scene.empty()) hdr.insert(layout::kAttrScene, Imf::StringAttribute(h.scene));
    if (h.formatVersion >= kStatsFormatVersionProvenance) {
        hdr.insert(layout::kAttrVariance, Imf::StringAttribute(h.variance));
        hdr.insert(layout::kAttrFeatures, Imf::StringAttribute(featureListText(h.features)));
        hdr.insert(layout::kAttrSources, Imf::StringAttribute(h.sources));
    }
    if (h.compact) hdr.insert(layout::kAttrCompact, Imf::StringAttribute(h.compactRule));
    if (h.formatVersion >= kStatsFormatVersionAovs) {
        hdr.insert(layout::kAttrBeautyChannels, Imf::StringVectorAttribute(std::vector<std::string>(
                                                    h.beautyNames.begin(), h.beautyNames.end())));
        hdr.insert(layout::kAttrBeautyPart, Imf::StringAttribute(h.beautyPart));
    }
    return hdr;
}

}  // namespace mcstat::detail
