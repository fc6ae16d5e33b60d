#pragma once
// The renderer's plain reference image (--reference): a float RGB scanline EXR written through
// OpenEXR's own API, not OIIO's ImageOutput. The renderer then needs nothing from
// libOpenImageIO (only its utility library): Debian's libOpenImageIO loads some 260 shared
// libraries (FFmpeg, GDAL, OpenCV, ...), and resolving their symbols was 0.2 s of every
// mcstat-render process's start, ten times the rest of a small render's start-up.

#include <cstdint>
#include <string>
#include <vector>

namespace mcstat::render {

/// Writes `rgb` (interleaved R, G, B floats, `width` x `height`, rows top to bottom) as a ZIP
/// compressed scanline EXR at `path`: to a temporary name in the same directory, renamed when
/// complete, so a crash never leaves a truncated reference behind. The header is what OIIO's
/// writer gave before: Software, capDate, the colour space's chromaticities and colorInteropID,
/// mcstat:seeds and mcstat:spp. False with a one-line `err` naming `path`.
bool writeReferenceExr(const std::string& path, int width, int height,
                       const std::vector<float>& rgb, const std::string& colorSpace, uint64_t seed,
                       int64_t spp, std::string& err);

}  // namespace mcstat::render
