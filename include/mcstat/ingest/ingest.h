// Ingest: renders of one image by a real renderer (one EXR per seed: Blender/Cycles multilayer,
// pbrt-v4, Arnold/Karma/RenderMan AOV layers, or any plain RGB EXR) become one statistics file,
// one sub-buffer per file (format version 3, assignment "perfile"; exr-deep/FORMAT.md).
// docs/ingest.md is the user-facing description; channel_naming.h finds channels by name.
//
// Nothing here throws: each function returns false with a one-line message naming the file.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "mcstat/core/params.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/ingest/channel_naming.h"

namespace mcstat {

/// Expands what `mcstat --ingest` was given into file names: a comma-separated list whose items
/// are file names or glob patterns (`*`, `?`, `[...]`). Each pattern must match at least one
/// file; the result is sorted by name in natural order (s2 before s10) and must not name a file
/// twice. An item that names an existing file is taken as it is, commas and all.
bool expandInputs(const std::string& pattern, std::vector<std::string>& paths, std::string& err);

/// What an image's metadata says about its colour space (docs/color.md), read in this order:
/// the string `colorInteropID` (OpenEXR 3.4), the `chromaticities` (float[8]), OIIO's
/// `oiio:ColorSpace` (OIIO's "Linear" of any float EXR says nothing). `space` is the working
/// space's name (findWorkingSpace), empty when the file is untagged; `source` says which
/// attribute decided ("colorInteropID lin_ap1_scene"). False with `problem` when the tag names
/// no space mcstat knows, or a display encoding (sRGB PNG/JPEG), which is not scene-linear (with
/// linearizeCommand's conversion of `path`, "IN" when empty), or when the tags contradict each
/// other: colorInteropID against the chromaticities, or either against an oiio:ColorSpace that
/// names another space (a copy converted by `oiiotool --colorconvert linear sRGB` keeps its
/// source's colorInteropID beside its own oiio:ColorSpace sRGB).
bool colorSpaceOf(const OIIO::ImageSpec& spec, std::string& space, std::string& source,
                  std::string& problem, const std::string& path = {});

/// `text` as one word of a POSIX shell: as it is when it holds only characters no shell treats
/// specially (letters, digits, `_-+.,/:=@%`), else in single quotes.
std::string shellWord(const std::string& text);
/// A stock oiiotool command making display-encoded image `path` ("IN" when empty) scene-linear,
/// written beside it as STEM_linear.exr: `--colorconvert FROM linear` when $OCIO is unset (OIIO's
/// own config knows linear, sRGB and Rec709, not lin_rec709), else to the $OCIO config's
/// scene-linear space (sceneLinearName, color.h). Runs as printed.
std::string linearizeCommand(const std::string& path, const std::string& from);
/// A stock oiiotool command converting the scene-linear image `path` ("IN" when empty) from
/// working space `from` to `to` (color_space.h names) that needs no OCIO config: the matrix
/// rgbToRgb gives (--ccmatrix), the chromaticities erased and colorInteropID set to `to`'s, into
/// STEM_<to>.exr. "" when either space is unknown.
std::string convertSpaceCommand(const std::string& path, const std::string& from,
                                const std::string& to);

struct IngestOptions {
    /// The working space of untagged inputs (`--ingest:colorspace=`), a name findWorkingSpace
    /// knows; empty: lin_rec709. Tagged inputs keep their own.
    std::string colorSpace;
    /// The beauty layer (e.g. "ViewLayer.Combined"); empty: the rules of findBeauty.
    std::string layer;
    /// Samples per pixel of every file; 0: read from each file's metadata (mcstat:spp,
    /// samplesPerPixel of pbrt-v4, cycles.<ViewLayer>.samples of Blender), an error if absent.
    int64_t spp = 0;
    /// Refuses inputs whose statistics file would exceed these (pixels, bytes, M <= 999).
    ReadLimits limits;
    /// Rows decoded per read: memory per file is rows x width x the channels read.
    int rowsPerBlock = 128;
    /// Called after each block of rows of every file with (blocks done, blocks in a pass over
    /// the image); may be empty.
    std::function<void(int64_t, int64_t)> progress;
    /// Called with each warning that the pixels give (NaN/Inf counts per file), once per set of
    /// renders: the RGB's when the first pass over every row completes, the AOVs' when the first
    /// pass over every row's AOVs does (a pass may read RGB only); may be empty. The warnings
    /// also go to the report (IngestSource::report).
    std::function<void(const std::string&)> warning;
    /// Keep every channel that is not the beauty's R, G, B as an AOV (docs/aovs.md). false drops
    /// them, on request only (`--ingest:aovs=0`), and the report says so.
    bool aovs = true;
    /// --ingest:seed=PATTERN: each file's seed read from its name, where `{seed}` stands for the
    /// seed's digits and `*`, `?`, `[...]` match as in a glob (checkSeedPattern); matched against
    /// the path's last components (one per '/' in the pattern, plus one). Empty: the names say
    /// nothing; seeds then come from the files' Note stamps only (docs/ingest.md, "Seeds").
    std::string seedPattern;
    /// Class overrides, applied in order, the last match winning: a glob (fnmatch) matched
    /// against a channel's full name and against its layer (e.g. "*.IndexOB" or "mask_*"), and
    /// the class it gets instead of classifyAov's.
    std::vector<std::pair<std::string, AovClass>> classOverrides;
};

/// Whether `pattern` can be a seed pattern (IngestOptions::seedPattern): `{seed}` exactly once, no
/// leading '/'. False with a one-line `problem`.
bool checkSeedPattern(const std::string& pattern, std::string& problem);
/// The seed the name of `path` gives through `pattern` (checked by checkSeedPattern), in decimal
/// without leading zeros: `{seed}` matches a whole run of digits, the rest of the pattern (a
/// glob) the text around it. False with `problem` when the name does not match, matches with two
/// different seeds, or its seed does not fit 64 bits.
bool seedFromName(const std::string& path, const std::string& pattern, std::string& seed,
                  std::string& problem);

/// `mcstat --ingest`'s modifiers (and Python's mcstat.ingest keyword arguments): layer, spp,
/// colorspace, aovs, and the class overrides alpha, light, data, id (GLOB,...).
const std::vector<ParamSpec>& ingestParams();
/// Parses key=value modifiers (ingestParams()) into `opt`, each through the one parser
/// (parseParamValue, `context` naming the command); an unknown key or colour space is a one-line
/// error. Keys not given leave `opt` as it is.
bool parseIngestOptions(const std::map<std::string, std::string>& kv, IngestOptions& opt,
                        std::string& err, const std::string& context = "--ingest");

/// What ingest found and warns about (the caller prints the warnings).
struct IngestReport {
    BeautyChannels beauty;              ///< of the first file (every file uses the same channels)
    FeatureChannels features;           ///< likewise
    std::vector<int64_t> spp;           ///< per file
    int64_t nonFiniteValues = 0;        ///< NaN/Inf RGB values over every file
    std::vector<AovChannel> aovs;       ///< every AOV kept, with its class and part
    int64_t nonFiniteAovValues = 0;     ///< NaN/Inf AOV values over every file
    std::vector<std::string> warnings;  ///< one line each, naming the file where there is one
};

/// Builds the statistics image of `paths` (one sub-buffer per file, in the order given). Every
/// other channel of the files (alpha, light groups, light-path passes, data passes, ID mattes, in
/// every part) is kept per sub-buffer as an AOV (format version 5, part `aovs`) with its class
/// (classifyAov, IngestOptions::classOverrides), together with the beauty's channel names and
/// part, the display window (overscan) and the first file's metadata, so that an operation's
/// result can replace one input render:
/// buffer j of a pixel is file j's RGB with count = file j's spp; moments count, mean (= beauty)
/// are the count-weighted combination in double; the variance is estimated from the buffers
/// (mcstat:variance "buffers"; "unknown" and NaN with one file); features found by name are
/// count-weighted means over the files, the others absent (NaN, not in mcstat:features); coverage
/// is always absent. Every file must have the same data and display windows and channel names.
/// NaN/Inf RGB values are kept (estimators leave such buffers out; the plain mean is non-finite
/// there) and counted. Two files with identical RGB are refused (the same render twice), and so
/// are two files of one seed (their Note stamps or names, IngestOptions::seedPattern), and a
/// beauty of integer pixels (8-bit PNGs: a renderer's output is float). The whole image in
/// memory: IngestSource streams the same rows.
bool ingestRenders(const std::vector<std::string>& paths, const IngestOptions& opt, StatsImage& out,
                   IngestReport& report, std::string& err);

/// The renders of one image as a statistics image read by blocks of rows (StatsBlockSource), so
/// that `mcstat --ingest ... -o f.mcstat` and the estimators over an ingest hold a block of rows
/// of each file and of the result, never the images (memory flat in the image's height).
/// init() reads and checks every header as ingestRenders does, allocating no pixels; read()
/// decodes the rows asked for from every file, one file per task on `nthreads` threads (files
/// are kept open up to 64 of them, else opened per block), and computes the block's moments. The
/// RGB is read whatever the parts asked; features and AOVs only when asked.
///
/// Provenance: mcstat:seeds holds each file's seed in decimal when the file says it (its Note
/// stamp, or its name through IngestOptions::seedPattern: known from the headers), else its RGB
/// hash ("h<16 hex digits>"; the same render twice is refused), known only once a pass has read
/// every row, in order from row 0 (a window filter's overlapping blocks count). Until then
/// header().seeds holds a placeholder of the final length for each hash; the block that completes
/// the pass carries the final seeds, which the statistics file writer puts in place at commit. A
/// later pass must find the same hashes.
class IngestSource final : public StatsBlockSource {
  public:
    IngestSource();
    ~IngestSource() override;
    IngestSource(const IngestSource&) = delete;
    IngestSource& operator=(const IngestSource&) = delete;

    /// Reads and checks every header (phase 1 of ingestRenders); false with `err`. The report's
    /// header-phase warnings are in report() at once; the pixels' ones after a complete pass.
    bool init(const std::vector<std::string>& paths, const IngestOptions& opt, std::string& err,
              int nthreads = 0);
    /// Another source over the same renders, sharing what init() found and, once known, the
    /// hashes; its own files, threads and pass.
    std::unique_ptr<IngestSource> clone(int nthreads) const;
    const IngestReport& report() const;
    /// Whether a pass over every row has completed: header().seeds holds the hashes.
    bool hashed() const;

    const StatsHeader& header() const override;
    const std::string& name() const override;
    int chunkRows() const override;
    int decodeThreads() const override;
    int blocksHeld() const override;
    bool read(int firstRow, int rows, unsigned parts, StatsImage& block, std::string& err) override;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// Channel names of an image file over all its subimages (parts). Subimage 0's names are kept as
/// they are; in later parts a name without a layer is qualified by the part's name ("N" in part
/// "normals" becomes "normals.N"). `where` gives (subimage, channel) of each name.
bool listChannels(const std::string& path, std::vector<std::string>& names,
                  std::vector<std::pair<int, int>>& where, std::string& err);

/// Reads the R, G, B of an image file chosen by name (findBeauty with `layer`) as a 3-channel
/// float image named R, G, B; `found` (may be null) tells which layer and rule.
bool readRenderRGB(const std::string& path, const std::string& layer, OIIO::ImageBuf& out,
                   BeautyChannels* found, std::string& err);

}  // namespace mcstat
