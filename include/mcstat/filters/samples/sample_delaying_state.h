// Density-based sample delaying's online state (Pajot, Barthe and Paulin, GI 2011, Algorithm 1
// and section 4.1) as a statistics file stores it. exr-deep stores any operation's per-pixel
// state as state parts with an owner (PixelStateParts); this file names the parts (flat `pajot`,
// deep `modes`, as every file since format 4 has them), says which channels the state is made of
// and what they mean (FORMAT.md "State parts with an owner", docs/pajot.md), so that a render
// resumed from the file continues bit for bit, and gives the registry entry its hooks. The flat
// part holds the estimate and each pixel's scalars, its doubles as their exact 64-bit patterns in
// two UINT channels; the deep part one record per mode, ROT single, delayed sample or learning
// sample.
#pragma once

#include <string>
#include <vector>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/filters/operation.h"
#include "mcstat/filters/samples/sample_delaying_kde.h"

namespace mcstat {

/// Pajot's online state of every pixel (its state parts).
struct PajotImage {
    PajotParams params;              ///< recorded as the parts' parameter text (pajotParamText)
    std::vector<PajotState> pixels;  ///< [p]
    std::vector<float> estimate;     ///< [p*3 + c], PajotPixel::estimate()
};

/// The parts that store `pj`. False with a one-line `err` when a value does not fit the format
/// (a pixel that took more than 2^24 samples: counts are float32 in the file).
bool encodePajotState(const PajotImage& pj, PixelStateParts& out, std::string& err);
/// `pj` from the parts of an image `width` pixels wide, every value checked (counts, phases,
/// record kinds, the delayed count of both parts): `err` is one line without the file name.
bool decodePajotState(const PixelStateParts& parts, int width, PajotImage& pj, std::string& err);

/// The registry name of the operation, which its state parts carry as their owner.
inline constexpr const char* kPajotName = "pajot";
/// The registry entry's state hooks: the parts' names, --info's description, the online run.
OperationState pajotStateHooks();

/// Reads and decodes the Pajot state parts of statistics file `path` (errors name it).
bool readPajotParts(const std::string& path, PajotImage& out, std::string& err,
                    const ReadLimits& limits = ReadLimits());
/// The same through an opened SampleSource.
bool readPajotState(SampleSource& src, PajotImage& out, std::string& err);

}  // namespace mcstat
