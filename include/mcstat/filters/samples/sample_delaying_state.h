// Pajot's online state as a statistics file stores it: the Pajot operation's format extension.
// exr-deep stores any operation's per-pixel state as two parts of named channels
// (PixelStateParts: flat part `pajot`, deep part `modes`); this file says which channels Pajot's
// state is made of and what they mean (FORMAT.md "Version 4: samples and modes"), so that a
// render resumed from the file continues bit for bit. The flat part holds the estimate and each
// pixel's scalars, its doubles as their exact 64-bit patterns in two UINT channels; the deep part
// one record per mode, ROT single, delayed sample or learning sample.
#pragma once

#include <string>
#include <vector>

#include "mcstat/filters/samples/pajot_kde.h"
#include "mcstat/sample_records.h"

namespace mcstat {

/// Pajot's online state of every pixel (parts `pajot` and `modes`).
struct PajotImage {
    PajotParams params;              ///< recorded as attribute mcstat:pajot
    std::vector<PajotState> pixels;  ///< [p]
    std::vector<float> estimate;     ///< [p*3 + c], PajotPixel::estimate()
};

/// The parts that store `pj`. False with a one-line `err` when a value does not fit the format
/// (a pixel that took more than 2^24 samples: counts are float32 in the file).
bool encodePajotState(const PajotImage& pj, PixelStateParts& out, std::string& err);
/// `pj` from the parts of an image `width` pixels wide, every value checked (counts, phases,
/// record kinds, the delayed count of both parts): `err` is one line without the file name.
bool decodePajotState(const PixelStateParts& parts, int width, PajotImage& pj, std::string& err);

/// Reads and decodes parts `pajot` and `modes` of statistics file `path` (errors name it).
bool readPajotParts(const std::string& path, PajotImage& out, std::string& err,
                    const ReadLimits& limits = ReadLimits());
/// The same through an opened SampleSource.
bool readPajotState(SampleSource& src, PajotImage& out, std::string& err);

}  // namespace mcstat
