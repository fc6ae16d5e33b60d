// The specs of the images mcstat makes (image_spec.h).
#include "mcstat/image/spec/image_spec.h"

#include <OpenImageIO/strutil.h>

#include "mcstat/core/color_space.h"

namespace mcstat {

using OIIO::ImageSpec;
using OIIO::ROI;
using OIIO::TypeDesc;

OIIO::ROI displayWindowROI(const StatsHeader& h) {
    if (h.displayWidth <= 0 || h.displayHeight <= 0) return dataWindowROI(h);
    return OIIO::ROI(h.displayX, h.displayX + h.displayWidth, h.displayY,
                     h.displayY + h.displayHeight);
}

void labelColorSpace(ImageSpec& spec, const std::string& colorSpace) {
    const WorkingSpace* ws = findWorkingSpace(colorSpace);
    if (!ws) return;
    const Chromaticities& c = ws->xy;
    const float xy[8] = {float(c.rx), float(c.ry), float(c.gx), float(c.gy),
                         float(c.bx), float(c.by), float(c.wx), float(c.wy)};
    spec.attribute("chromaticities", TypeDesc(TypeDesc::FLOAT, 8), xy);
    spec.attribute("colorInteropID", ws->interopID);
}

ImageSpec floatSpec(ROI data, const std::vector<std::string>& channels, ROI display,
                    const std::string& colorSpace) {
    if (!display.defined()) display = data;
    ImageSpec spec(data.width(), data.height(), int(channels.size()), TypeDesc::FLOAT);
    spec.x = data.xbegin;
    spec.y = data.ybegin;
    spec.full_x = display.xbegin;
    spec.full_y = display.ybegin;
    spec.full_width = display.width();
    spec.full_height = display.height();
    spec.channelnames = channels;
    spec.alpha_channel = -1;
    spec.z_channel = -1;
    if (!colorSpace.empty()) spec.attribute("oiio:ColorSpace", colorSpace);
    labelColorSpace(spec, colorSpace);
    return spec;
}

ImageSpec floatSpec(ROI data, const std::vector<std::string>& channels, const StatsHeader& h) {
    return floatSpec(data, channels, displayWindowROI(h), h.colorSpace);
}

std::vector<std::string> aovOutputChannels(const StatsHeader& h) {
    std::vector<std::string> names;
    for (const AovChannel& c : h.aovs) names.push_back(c.name);
    return names;
}

int aovDepthChannel(const StatsHeader& h, size_t firstAov) {
    for (size_t a = 0; a < h.aovs.size(); ++a)
        if (h.aovs[a].name == "Z" || h.aovs[a].name == "z") return int(firstAov + a);
    return -1;
}

int aovAlphaChannel(const StatsHeader& h, size_t firstAov) {
    for (size_t a = 0; a < h.aovs.size(); ++a)
        if (h.aovs[a].cls == AovClass::Alpha) return int(firstAov + a);
    return -1;
}

void setAovAttributes(ImageSpec& spec, const StatsHeader& h, size_t firstAov) {
    if (h.aovs.empty()) return;
    std::string classes;
    for (const AovChannel& a : h.aovs)
        classes += (classes.empty() ? "" : ",") + std::string(aovClassName(a.cls));
    spec.attribute(kAttrFirstAov, int(firstAov));
    spec.attribute(kAttrAovClasses, classes);
}

}  // namespace mcstat
