// What the files of an ingest (ingest.h) settle before any pixel is read, shared by its rooms:
// inputs.cpp (the names given: globs, lists, frames), headers.cpp (each file's header: layout,
// channels, samples, colour space, metadata; the result's header), seeds.cpp (each file's seed,
// from its Note stamp or its name) and pixel_source.cpp (the pixels, by blocks of rows). Private
// to ingest/.
#pragma once

#include <OpenImageIO/imageio.h>

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "mcstat/ingest/ingest.h"

namespace mcstat::ingest_detail {

using OIIO::ImageInput;
using OIIO::ImageSpec;

constexpr uint64_t kFnvBasis = 14695981039346656037ull;
constexpr double kMaxCount = 16777216.0;  // counts are float32 integers (FORMAT.md)

/// One input file, opened, with the channels mcstat reads from it.
struct InputFile {
    std::string path;
    std::unique_ptr<ImageInput> in;
    ImageSpec spec;  ///< subimage 0
    std::vector<std::string> names;
    std::vector<std::pair<int, int>> where;
    std::vector<std::string> rawNames;  ///< each channel's name in its part (names qualify some)
    /// Per subimage: its part name when the file has several parts ("" for a one-part file).
    std::vector<std::string> partNames;
    BeautyChannels beauty;
    FeatureChannels features;
    int64_t spp = 0;
    std::string sppKey;
    std::string space;        ///< its working space (colorSpaceOf, or the assumed one)
    std::string spaceSource;  ///< what said so: "colorInteropID lin_ap1_scene", "untagged: ..."
    std::string seed;         ///< its seed in decimal (seeds.cpp), "" when nothing says it
    std::string seedSource;   ///< what said so: "Note stamp" or "name"
};

/// What every source over the same renders shares: the files and what their headers settled
/// (phase 1), and once a pass has read every row, each file's RGB hash (the provenance in
/// mcstat:seeds) and what its pixels showed.
struct Ingest {
    IngestOptions opt;
    IngestReport report;
    std::vector<InputFile> files;  ///< headers only: no file is held open
    // Every channel but the beauty, kept per sub-buffer (docs/aovs.md).
    std::vector<AovChannel> aovs;
    std::vector<int> aovIndex;  ///< the channel index in every file of each of `aovs`
    double totalSpp = 0.0;      ///< samples per pixel over every file
    StatsHeader header;         ///< mcstat:seeds a placeholder of the final length until hashed
    bool hashed = false;        ///< a pass read every row: `hashes` and header.seeds are final
    bool aovsTallied = false;   ///< a pass read every row's AOVs: their NaN/Inf warnings given
    std::vector<uint64_t> hashes;

    const InputFile& first() const { return files[0]; }
    /// A warning the pixels give: into the report and to the caller's callback.
    void warnOfPixels(const std::string& w) {
        report.warnings.push_back(w);
        if (opt.warning) opt.warning(w);
    }
    int width() const { return files[0].spec.width; }
    int height() const { return files[0].spec.height; }
    int buffers() const { return int(files.size()); }  ///< M: one sub-buffer per file
};

// ---- inputs.cpp

/// Renders of one image are one frame: a glob that matched several frames (by name or by
/// metadata) would merge them into one image. Refused, naming the frames found.
bool checkOneFrame(const Ingest& s, std::string& err);

// ---- headers.cpp

/// Opens a render with the reader its name says and no other (headers.cpp says why).
std::unique_ptr<ImageInput> openRender(const std::string& path, int64_t maxPixels,
                                       std::string& err);
/// Refuses a request no file can satisfy: no files, more than a statistics file's sub-buffers,
/// samples per file out of range.
bool checkRequest(const std::vector<std::string>& paths, const IngestOptions& opt,
                  std::string& err);
/// Opens `path` and reads its header into `f` (channels, beauty, features, spp).
bool openInput(const std::string& path, int64_t maxPixels, InputFile& f, std::string& err);
/// Every header first: layouts, channels, spp; nothing is allocated before they agree.
bool readHeaders(const std::vector<std::string>& paths, Ingest& s, std::string& err);
/// mcstat:seeds: per file its seed when it says one (seeds.cpp), else the hash of its RGB
/// (`hashes` null: a placeholder of the same length).
std::string seedsText(const std::vector<uint64_t>* hashes, const std::vector<InputFile>& files);
/// The result's header: its size and buffers, where its samples came from and what the render
/// looked like.
void fillHeader(Ingest& s);

// ---- seeds.cpp

/// The seed `f` says it was rendered with (docs/ingest.md, "Seeds"): a `seed=N` token of its
/// `Note` (Blender's metadata stamp) and, with --ingest:seed=PATTERN, its name; the two must
/// agree. Sets f.seed ("" when neither says one) and f.seedSource. False with `err` naming the
/// file.
bool seedOf(InputFile& f, const IngestOptions& opt, std::string& err);
/// Two inputs of one seed are refused: their samples are the same, not independent.
bool checkSeeds(const Ingest& s, std::string& err);

}  // namespace mcstat::ingest_detail
