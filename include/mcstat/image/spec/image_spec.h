// The specs of the images mcstat makes, apart from the operations that fill them: windows, float
// channels, the working space's labels, the AOV attributes. A small library (mcstat::image_spec)
// below the image layer, so that ingest and the renderer set up images without linking every
// operation.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <string>
#include <vector>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat {

/// The data window of a statistics image as an OIIO region.
inline OIIO::ROI dataWindowROI(const StatsHeader& h) {
    return OIIO::ROI(h.originX, h.originX + h.width, h.originY, h.originY + h.height);
}

/// The region an operation works on, as OIIO's IBAprep sets it up: `roi` clipped to `full` (the
/// data window), all of `full` when `roi` is undefined.
inline OIIO::ROI prepareRoi(OIIO::ROI roi, OIIO::ROI full) {
    return roi.defined() ? OIIO::roi_intersection(roi, full) : full;
}

/// Labels `spec` with working space `colorSpace` (color_space.h) as an EXR carries it: the
/// `chromaticities` and the `colorInteropID`; a space mcstat does not know gets neither.
void labelColorSpace(OIIO::ImageSpec& spec, const std::string& colorSpace);

/// The display window of a statistics image (the data window unless the header says otherwise,
/// e.g. an ingested render with overscan).
OIIO::ROI displayWindowROI(const StatsHeader& h);
/// The spec of every float image mcstat makes: data window `data`, full (display) window `display`
/// (undefined: the data window), `channels` by name, no alpha or depth channel (ImageSpec would
/// make a fourth channel the alpha; callers that have one say so), and the colour space when given.
OIIO::ImageSpec floatSpec(OIIO::ROI data, const std::vector<std::string>& channels,
                          OIIO::ROI display = {}, const std::string& colorSpace = "");
/// floatSpec for a region of a statistics file's result: its display window and colour space.
OIIO::ImageSpec floatSpec(OIIO::ROI data, const std::vector<std::string>& channels,
                          const StatsHeader& h);

/// The AOV channels an operation's result carries after its own: the input's names, in the
/// header's order (docs/aovs.md).
std::vector<std::string> aovOutputChannels(const StatsHeader& h);
/// The channel index of the AOV of class alpha in a result whose AOVs start at `firstAov`, or -1.
int aovAlphaChannel(const StatsHeader& h, size_t firstAov);
/// Likewise the AOV named Z (a depth pass), OIIO's z_channel, or -1.
int aovDepthChannel(const StatsHeader& h, size_t firstAov);
/// Spec attributes by which an image says which of its channels are AOVs and of what class, so
/// that a later image filter (MIF/WMIF over an estimator's result) carries them too: the first
/// AOV channel (int) and the classes (comma-separated aovClassName), AOVs running to the last
/// channel.
inline constexpr const char* kAttrFirstAov = "mcstat:firstAov";
inline constexpr const char* kAttrAovClasses = "mcstat:aovClasses";
void setAovAttributes(OIIO::ImageSpec& spec, const StatsHeader& h, size_t firstAov);

}  // namespace mcstat
