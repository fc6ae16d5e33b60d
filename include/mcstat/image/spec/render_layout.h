// A robust result as a drop-in replacement for one input render (docs/aovs.md): the render's
// channel names, parts, windows and metadata, plus provenance under names that survive stock
// OIIO tools. OIIO-facing; the statistics file stores what it needs as plain text
// (StatsHeader::beautyNames, aovs, beautyPart, sourceMetadata, display window).
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <map>
#include <string>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat {

/// The header attributes of `spec` that belong to the render and go to every output made from it
/// (camera matrices, frame, fps, time code, the renderer's own attributes), as JSON text for
/// StatsHeader::sourceMetadata: OIIO's names and types. Left out: OIIO's bookkeeping ("oiio:*"),
/// the file's encoding (compression, tiles, line order, chunk counts, "openexr:*"), and mcstat's
/// own ("mcstat:*", "mcstat.*"), which each output sets afresh.
std::string sourceMetadataJson(const OIIO::ImageSpec& spec);

/// Sets the attributes of sourceMetadataJson's text on `spec`. False with a one-line `err` on text
/// that is not such JSON (nothing is set then).
bool applySourceMetadata(OIIO::ImageSpec& spec, const std::string& json, std::string& err);

/// Attribute name prefix of provenance. Not "mcstat:": OIIO's writers drop attributes whose prefix
/// before ':' names another image format, and with the mcstat plugin loaded "mcstat" is one, so
/// `oiiotool f.mcstat -o x.exr` would lose them.
inline constexpr const char* kProvenancePrefix = "mcstat.";

/// Describes a result computed from `h` on its spec: the source's metadata (StatsHeader::
/// sourceMetadata) and provenance mcstat.M, mcstat.spp, mcstat.sources, mcstat.renderer. The
/// renderers' own sample counts among the source's metadata (samplesPerPixel,
/// cycles.<ViewLayer>.samples) are set to the result's samples per pixel (h.spp, every render
/// together). A bad metadata text is skipped with a warning in `warning`. describeResult
/// (imageops.h) adds the operation.
void describeSource(OIIO::ImageSpec& spec, const StatsHeader& h, std::string* warning = nullptr);

/// How an image is encoded when written, as oiiotool's -d, --compression and -o:type= set it.
struct ImageWriteOptions {
    OIIO::TypeDesc type = OIIO::TypeDesc::FLOAT;         ///< every channel's, unless named below
    std::map<std::string, OIIO::TypeDesc> channelTypes;  ///< by the channel's name in the file
    std::string compression;  ///< e.g. "zip", "dwaa:45"; "": the writer's default
};

/// Parses oiiotool's data type names mcstat writes: "half", "float". False otherwise.
bool parseWriteType(const std::string& text, OIIO::TypeDesc& out);

/// Applies `opt` to the spec of a file about to be written: its format, per-channel formats (by
/// the names in `spec`) and compression. False with `err` for a channel type naming no channel
/// of the image or a compression checkCompression refuses.
/// Checks a compression "NAME[:LEVEL]" for files of extension `ext` ("" when not known yet, as for
/// --compression before -o: the syntax only). LEVEL is a whole number: for EXR, zip and zips take
/// 1..9 (zlib's levels), dwaa and dwab 1..1000000 (the DWA quantisation level, 45 by default),
/// the other OpenEXR codecs none; for other formats 0..100 (PNG and TIFF zip levels, JPEG
/// quality), the name left to the format's writer. False with `err` saying what is wrong.
bool checkCompression(const std::string& text, const std::string& ext, std::string& err);

bool applyWriteOptions(OIIO::ImageSpec& spec, const ImageWriteOptions& opt, const std::string& ext,
                       std::string& err);

/// The finite values of `img`'s channels that `spec` (applyWriteOptions' result, the same channels
/// in the same order) stores as half and that exceed half's largest value, 65504: written, they
/// become Inf. Counted so that the writer can say so.
size_t halfOverflow(const OIIO::ImageBuf& img, const OIIO::ImageSpec& spec);

/// Whether writing an operation's result over `h` as a render needs writeRenderLike (beauty
/// names other than R, G, B, AOVs, or a part name).
bool needsRenderLayout(const StatsHeader& h);

/// Writes `img` (an operation's result over a statistics file with header `layout`: R, G, B
/// first, then any channels the operation adds, then the AOVs under their input names) as the
/// input render was laid out: R, G, B renamed to layout.beautyNames, each AOV in the part it came
/// from (AovChannel::part; the beauty, alpha and the operation's own channels in
/// layout.beautyPart), one part when they all came from one. Atomic (a temporary file renamed on
/// success). A format that holds one image cannot hold several parts: refused, naming the format.
/// `opt` encodes it (channel types by the written names); `overflow` receives halfOverflow's count.
bool writeRenderLike(const OIIO::ImageBuf& img, const StatsHeader& layout, const std::string& path,
                     const ImageWriteOptions& opt, std::string& err, size_t* overflow = nullptr);

}  // namespace mcstat
