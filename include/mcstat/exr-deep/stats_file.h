// The mcstat statistics file, versions 1 to 6: in-memory form, writer, reader, validator and
// merge. The on-disk layout is specified in exr-deep/FORMAT.md; this header is its C++ face. No
// function here throws: each returns false and fills `err` with a one-line message that names the
// file (when there is one) and the problem.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "mcstat/core/pixel_buffers.h"

namespace mcstat {

/// File extension of statistics files (a single extension: OIIO picks readers by the last one).
inline constexpr const char* kStatsExtension = "mcstat";
/// Newest layout this library reads and writes (header attribute "mcstat:formatVersion").
/// Version 1: fixed M (part "buffers"). Version 2 adds adaptive M (deep part "vbuffers" instead of
/// "buffers", attribute "mcstat:adaptiveM"). Version 3 adds provenance (files built from renderer
/// output by `mcstat --ingest`): the assignment "perfile", where the moments' variance comes from
/// ("mcstat:variance") and which features hold data ("mcstat:features"); see FORMAT.md. The
/// writer writes header.formatVersion as given, which must be at least requiredFormatVersion():
/// a rendered fixed-M image keeps version 1 (what every reader knows).
/// Version 4 adds optional parts after the four: per-sample records (`records`) and the state parts
/// an operation owns (a flat and a deep part, StateOwner); include/mcstat/exr-deep/sample_records.h
/// reads and writes them. Version 5 adds the input render's own layout (files made by `mcstat
/// --ingest` from production renders): the part `aovs` (every AOV, alpha, light group, data pass
/// and ID matte per sub-buffer), the input's channel names of the beauty and its metadata
/// (FORMAT.md "Version 5"). Version 6 adds compact files (`mcstat --compact`, FORMAT.md "Version
/// 6"): the layout of adaptive M decided after the samples are in, each pixel holding its M
/// sub-buffers or one (their mean), AOVs in the deep part, and the between-buffer spread of every
/// pixel in part moments. Version 7 slims a compact file's part moments to the count and the
/// spread: its mean was part beauty's and its per-sample variance nothing of a compact file's used
/// (FORMAT.md "Version 7"). Version 8 stores a compact file's one-buffer pixels' means once, in
/// part beauty, and zeros in their deep sample (FORMAT.md "Version 8").
inline constexpr int kStatsFormatVersion = 8;
/// The version a fixed-M file is written with by default (readable by version-1 readers).
inline constexpr int kStatsFormatVersionFixed = 1;
/// The first version that can hold adaptive M.
inline constexpr int kStatsFormatVersionAdaptive = 2;
/// The first version that can hold provenance: assignment "perfile", mcstat:variance other than
/// "samples", features absent (mcstat:features), mcstat:sources.
inline constexpr int kStatsFormatVersionProvenance = 3;
/// The first version that can hold the optional parts: records and state parts with an owner.
inline constexpr int kStatsFormatVersionSamples = 4;
/// The first version that can hold AOVs (part `aovs`), beauty channel names and source metadata.
inline constexpr int kStatsFormatVersionAovs = 5;
/// The first version that can hold compact files and AOVs with the deep part `vbuffers`.
inline constexpr int kStatsFormatVersionCompact = 6;
/// A compact file whose part moments holds the count and the spread only (a version-6 compact
/// file also holds mean.* and variance.*, and still reads).
inline constexpr int kStatsFormatVersionSlimMoments = 7;
/// The version `--compact` writes: version 7's layout, and a pixel that keeps one buffer (of M > 1)
/// holds its mean in part beauty only, R = G = B = 0 in its deep sample (compactMeansInBeauty).
inline constexpr int kStatsFormatVersionMeansInBeauty = 8;

/// What an AOV channel holds, which decides how an operation combines its sub-buffers
/// (docs/aovs.md). Every operation computes weights from the beauty once per output pixel; the
/// classes say what those weights do to a channel.
enum class AovClass {
    Alpha,  ///< coverage / opacity of the beauty (`A`, `RGBA.A`, `Combined.A`): beauty's weights
    Light,  ///< additive light (light groups, light-path passes, emission): beauty's weights, so
            ///< AOVs that summed to the beauty in every input still sum to it
    Data,   ///< normals, positions, depth, albedo, UV, motion: beauty's weights too (a weighted
            ///< average of per-buffer data, which is what the mean of a data pass is)
    Id,     ///< labels (object / material index, Cryptomatte rank and coverage): never averaged;
            ///< the value of the buffer of largest weight
};
/// "alpha", "light", "data", "id".
const char* aovClassName(AovClass c);
/// Parses aovClassName's names; false for anything else.
bool parseAovClass(const std::string& text, AovClass& out);

/// One AOV channel of part `aovs`, as the input render named it.
struct AovChannel {
    std::string name;  ///< the input's channel name, e.g. "ViewLayer.Combined_key.R", "diffuse.R"
    AovClass cls = AovClass::Light;
    /// The input part it came from ("" for the part that holds the beauty): an output rebuilt as
    /// a drop-in replacement writes it back into a part of that name.
    std::string part;
    bool operator==(const AovChannel& o) const {
        return name == o.name && cls == o.cls && part == o.part;
    }
};
/// Longest AOV channel name a file may hold (bytes), and most AOV channels.
inline constexpr size_t kMaxAovNameBytes = 200;
inline constexpr int kMaxAovs = 4096;

/// Floats per pixel of StatsImage::spread: buffers, then RR, GG, BB, RG, RB, GB.
inline constexpr int kSpreadFloats = 7;
/// Index of the covariance of channels c and d (0..2) in a pixel's spread values.
inline constexpr int spreadIndex(int c, int d) {
    return c == d ? 1 + c : (c + d == 1 ? 4 : (c + d == 2 ? 5 : 6));
}

/// Sample-to-buffer rules (FORMAT.md "Sample-to-buffer assignment").
inline constexpr const char* kAssignmentRoundRobin = "roundrobin";  ///< sample i -> buffer i mod M
inline constexpr const char* kAssignmentLeastCount = "leastcount";  ///< adaptive M, grown buffers
/// Version 3: buffer j holds every sample of input file j (one render per seed, ingested).
inline constexpr const char* kAssignmentPerFile = "perfile";

/// Where the moments part's variance comes from (attribute mcstat:variance, version 3).
inline constexpr const char* kVarianceSamples = "samples";  ///< Welford over every sample
/// Estimated from the spread of the buffer means: sum_j n_j (m_j - mean)^2 / (M - 1), the
/// between-group mean square of a one-way ANOVA (unbiased for independent buffers).
inline constexpr const char* kVarianceBuffers = "buffers";
inline constexpr const char* kVarianceUnknown = "unknown";  ///< stored as NaN (M = 1 ingest)

/// The first-hit features a statistics file can hold (part "features"); absent ones are NaN.
enum Feature : unsigned {
    kFeatureNormal = 1u << 0,    ///< "N": shading normal
    kFeaturePosition = 1u << 1,  ///< "P": world position
    kFeatureAlbedo = 1u << 2,    ///< "Albedo"
    kFeatureDepth = 1u << 3,     ///< "Z": first-hit distance
    kFeatureCoverage = 1u << 4,  ///< "A": fraction of samples whose camera ray hit geometry
    kAllFeatures = 31u
};
/// "N,P,Albedo,Z,A"-style text of Feature bits, always in that order ("" for none).
std::string featureListText(unsigned bits);
/// Parses such a list (any order; only those five names, each at most once); false with
/// `problem` (a phrase) otherwise.
bool parseFeatureList(const std::string& text, unsigned& bits, std::string& problem);
/// Largest number of sub-buffers a file may declare (channel names use three digits).
inline constexpr int kMaxBuffers = 999;

/// Version 4 on: the per-pixel state an operation keeps in the file (FORMAT.md "State parts with an
/// owner"): a flat and a deep part after the four (and `aovs`), before `records`, both carrying the
/// owning operation's registry name and its parameter text. The format stores them and checks
/// their shapes; the operation (found by name in the registry) gives them meaning.
struct StateOwner {
    std::string operation;           ///< mcstat:stateOwner, a registry name; empty: no state parts
    std::string params;              ///< mcstat:stateParams, "key=value:key=value" (core/params.h)
    std::string flatPart, deepPart;  ///< the parts' names, the operation's choice
    bool operator==(const StateOwner& o) const {
        return operation == o.operation && params == o.params && flatPart == o.flatPart &&
               deepPart == o.deepPart;
    }
    bool operator!=(const StateOwner& o) const { return !(*this == o); }
};

/// Header data shared by every part of a statistics file.
struct StatsHeader {
    int formatVersion = kStatsFormatVersionFixed;  ///< 1, or 2 (required for adaptiveM)
    int width = 0, height = 0;                     ///< data window size (pixels)
    int originX = 0, originY = 0;                  ///< data window origin (OpenEXR dataWindow.min)
    int M = 1;  ///< number of sub-buffers; with adaptiveM the largest m_p allowed (M_max)
    /// Variable buffer count (Jung's adaptive M, FORMAT.md version 2): pixel p holds m_p in 1..M
    /// buffers, stored in the deep part "vbuffers" instead of the flat part "buffers".
    bool adaptiveM = false;
    int64_t spp = 0;  ///< samples per pixel the producer aimed at (counts hold what was taken)
    /// Version 6 (mcstat:compact): a compact file, made from a fixed-M file after its samples
    /// were in (include/mcstat/compact/compact.h). The layout is adaptive M's (adaptiveM is set),
    /// every pixel holding either its M buffers or one, the mean G-MoN returns for it; part
    /// moments adds the between-buffer spread (StatsImage::spread); from version 7 it holds only
    /// the count and the spread (StatsImage::mean and ::variance stay empty). `compactRule` is the
    /// rule that decided, as text (e.g. "gmon luma=0.2126,0.7152,0.0722 margin=0 z=0").
    bool compact = false;
    std::string compactRule;
    std::string assignment = "roundrobin";  ///< sample-to-buffer rule, see FORMAT.md
    std::string renderer;                   ///< producer name and version
    std::string colorSpace = "lin_rec709";  ///< OCIO colour space name of every RGB value
    std::string seeds;  ///< comma-separated seeds of the renders merged into this file
    /// mcstat:scene (optional, any version): what identifies the scene rendered, e.g. the
    /// renderer's scene name and a hash of its scene file ("default h0123..."); "" when the
    /// producer does not know it (ingest). A merge joins different ones with " + "; mcstat
    /// --merge refuses inputs whose scenes differ unless :force=1.
    std::string scene;
    // Version 3 (provenance); versions 1 and 2 imply the defaults.
    std::string variance = kVarianceSamples;  ///< mcstat:variance: kVariance*
    unsigned features = kAllFeatures;         ///< mcstat:features: Feature bits holding data
    std::string sources;  ///< mcstat:sources: comma-separated input file names (ingest)
    // Version 4: which optional parts follow the four (set by the reader; the writer writes what
    // it is given, see sample_records.h).
    StateOwner state;  ///< state parts with an owner (state.operation empty: none)
    bool hasState() const { return !state.operation.empty(); }
    bool hasRecords = false;  ///< part `records`: every sample
    // Version 5: what the input render looked like, so that an output can replace one input.
    /// Part `aovs`: these channels per sub-buffer, in this order (fixed M only). Empty: no part.
    std::vector<AovChannel> aovs;
    /// mcstat:beautyChannels: the input's names of the beauty's R, G, B (e.g.
    /// "ViewLayer.Combined.R"); the default R, G, B needs no version 5.
    std::array<std::string, 3> beautyNames{"R", "G", "B"};
    /// mcstat:beautyPart: the name of the input part that held the beauty ("" single-part).
    std::string beautyPart;
    /// mcstat:sourceMetadata: the first input's own header attributes (camera matrices, frame,
    /// renderer's attributes), as JSON text written and read by the ingest and output code
    /// (OIIO types); this library stores it and never interprets it. "" for none.
    std::string sourceMetadata;
    /// The display window (OpenEXR displayWindow), e.g. smaller than the data window with
    /// overscan. displayWidth 0: equal to the data window (what mcstat-render writes). Any
    /// version may hold another one.
    int displayX = 0, displayY = 0, displayWidth = 0, displayHeight = 0;
    /// The AOV channel index of `name`, or -1.
    int aovIndex(const std::string& name) const;
};

/// Version 8 (FORMAT.md "Version 8"): whether a file of `h` keeps the mean of each pixel that has
/// one buffer of M > 1 in part beauty alone, its deep sample holding R = G = B = 0 (a compact
/// file of version 8 or later). In memory nothing changes: the reader puts beauty's mean in the
/// buffer, the writer requires them to be the same floats.
inline bool compactMeansInBeauty(const StatsHeader& h) {
    return h.compact && h.M > 1 && h.formatVersion >= kStatsFormatVersionMeansInBeauty;
}

/// The lowest format version that can hold what `h` describes: 5 for AOVs, beauty names other
/// than R, G, B, a beauty part name or source metadata; 4 for the optional parts, 3 for
/// provenance (assignment perfile, variance not "samples", absent features, sources), 2 for
/// adaptive M, else 1.
int requiredFormatVersion(const StatsHeader& h);
/// The version-4 parts `h` declares, for messages: "parts flat, deep and records", "part
/// records"; empty when none.
std::string optionalPartsText(const StatsHeader& h);

/// Whole statistics file in memory. Pixel (x, y) of the data window has index p = y * width + x.
/// Every array is float32 as on disk; the producer accumulates in double and rounds once when
/// storing.
struct StatsImage {
    StatsHeader header;
    // part "beauty": the plain mean of every sample
    std::vector<float> beauty;  ///< [p*3 + c]
    // part "buffers" (fixed M) or "vbuffers" (adaptive M): sub-buffer means and sample counts.
    // Buffer j of pixel p is element k = bufferBegin(p) + j, j < buffersOf(p); prefer
    // pixelBuffers(p), which works for both.
    std::vector<float> bufferMean;   ///< [k*3 + c]; fixed M: k = p*M + j
    std::vector<float> bufferCount;  ///< [k]
    /// Adaptive M only (empty for fixed M): pixels + 1 entries, bufferOffset[0] = 0, pixel p's
    /// buffers are k in [bufferOffset[p], bufferOffset[p+1]), m_p = bufferOffset[p+1] -
    /// bufferOffset[p] in 1..header.M.
    std::vector<uint64_t> bufferOffset;
    // part "moments": Welford statistics over all samples
    std::vector<float> count;  ///< [p]   number of samples
    std::vector<float> mean;   ///< [p*3 + c]
    std::vector<float>
        variance;  ///< [p*3 + c] unbiased sample variance (n-1 denominator; 0 if n<2)
    // part "features": first-hit G-buffer features
    std::vector<float> normal;    ///< [p*3 + c] mean first-hit shading normal over hits
    std::vector<float> position;  ///< [p*3 + c] mean first-hit world position over hits
    std::vector<float> albedo;    ///< [p*3 + c] mean first-hit albedo over all samples (miss = 0)
    std::vector<float> depth;     ///< [p] mean first-hit distance over hits (+inf if none)
    std::vector<float> coverage;  ///< [p] fraction of samples whose camera ray hit geometry
    // part "aovs" (version 5, fixed M), or the deep part "vbuffers" (version 6, adaptive layout):
    // AOV channel a of buffer j of pixel p, k = bufferBegin(p) + j.
    std::vector<float> aov;  ///< [k * A + a], A = header.aovs.size()
    /// Compact files only (read with part moments): per pixel the number of valid buffers M' of
    /// the full file and the between-buffer covariance of R, G, B, each sum_j n_j (x_j - mean_x)
    /// (y_j - mean_y) / (M' - 1) over the valid buffers with mean_x their count-weighted mean
    /// (NaN when M' < 2), in the order kSpreadNames gives; what --compare needs of a pixel whose
    /// buffers are not kept.
    std::vector<float> spread;  ///< [p * kSpreadFloats + i]

    size_t pixelCount() const { return size_t(header.width) * size_t(header.height); }
    /// Index k of pixel p's first buffer in bufferCount (times 3 in bufferMean).
    size_t bufferBegin(size_t p) const {
        return header.adaptiveM ? size_t(bufferOffset[p]) : p * size_t(header.M);
    }
    /// Number of buffers of pixel p: header.M, or m_p with adaptive M.
    int buffersOf(size_t p) const {
        return header.adaptiveM ? int(bufferOffset[p + 1] - bufferOffset[p]) : header.M;
    }
    /// Pixel p's kSpreadFloats values of `spread` when it is a compact file's pixel that kept only
    /// its mean (one buffer where the file has M > 1) and the spread was read, else null.
    const float* meanOnlySpread(size_t p) const {
        if (!header.compact || header.M < 2 || buffersOf(p) != 1 ||
            spread.size() != pixelCount() * size_t(kSpreadFloats))
            return nullptr;
        return spread.data() + p * size_t(kSpreadFloats);
    }
    /// Pixel p's buffers as the estimators take them, for fixed and adaptive M alike. The image
    /// must be valid (validateStats); p < pixelCount().
    PixelBuffers pixelBuffers(size_t p) const {
        const size_t k = bufferBegin(p);
        return {bufferMean.data() + k * 3, bufferCount.data() + k, buffersOf(p)};
    }
    /// Whether the sub-buffer arrays (and bufferOffset for adaptive M) have the sizes the header
    /// implies, so that pixelBuffers(p) is safe for every p, and `aov` is empty (part not read) or
    /// holds one value per buffer and AOV; cheap, values are not looked at. `why` names the
    /// problem. validateStats checks this and more.
    bool checkBufferLayout(std::string& why) const;
    /// Allocates every array for header.width x header.height x header.M, zero-filled
    /// (depth filled with +inf; aov with pixels * M * header.aovs.size() values). Fixed M only
    /// (header.adaptiveM false). Returns false (and leaves *this untouched) on absurd sizes.
    bool allocate(std::string& err);
    /// Adaptive M: sets header.adaptiveM, builds bufferOffset from `buffersPerPixel` (pixelCount()
    /// values, each in 1..header.M) and allocates every array as allocate() does. Returns false
    /// (and leaves *this untouched) on a bad count or absurd size; header.formatVersion must be >=
    /// 2.
    bool allocateAdaptive(const std::vector<uint32_t>& buffersPerPixel, std::string& err);
};

/// Limits for reading untrusted files, passed in (never global). The defaults are what a desktop
/// with 16 GB can afford: 8 GiB of decoded pixel data in one read (a whole 3840 x 2160 file with
/// M = 59, or 7680 x 4320 with M = 10; a streamed read holds a block of rows), 2^28 pixels and
/// 2^30 deep samples. Before any of it is allocated the reader also checks the claims against the
/// file itself (FORMAT.md, validation step 10), so a small file cannot claim a large image.
struct ReadLimits {
    int64_t maxPixels = int64_t(1) << 28;  ///< width * height
    int maxBuffers = kMaxBuffers;          ///< M
    /// Bytes of decoded pixel data one read may hold (StatsFileReader::read): the whole image for
    /// a whole read, a block of rows for a streamed one, so a file streamed a block at a time is
    /// not refused for its whole size. The headers are refused when one row exceeds it.
    int64_t maxBytes = int64_t(8) << 30;
    /// Adaptive M: total deep samples (sum of m_p) of part "vbuffers"; also bounded by maxBytes.
    int64_t maxDeepSamples = int64_t(1) << 30;
};

/// Writes `img` to `path` atomically: a temporary file in the same directory, renamed on success.
bool writeStatsFile(const std::string& path, const StatsImage& img, std::string& err);

/// Reads and validates a statistics file; allocation happens only after the headers pass
/// validation.
bool readStatsFile(const std::string& path, StatsImage& img, std::string& err,
                   const ReadLimits& limits = ReadLimits());

/// The four parts of a statistics file and (version 5) part "aovs" as bits, for reading only some
/// of them (StatsFileReader::read). The sub-buffers are part "buffers" or, with adaptive M,
/// "vbuffers".
enum StatsParts : unsigned {
    kStatsPartBeauty = 1u << 0,    ///< StatsImage::beauty
    kStatsPartBuffers = 1u << 1,   ///< bufferMean, bufferCount (and bufferOffset)
    kStatsPartMoments = 1u << 2,   ///< count, mean, variance
    kStatsPartFeatures = 1u << 3,  ///< normal, position, albedo, depth, coverage
    kStatsPartAovs = 1u << 4,      ///< aov (version 5; empty when the file has no AOVs)
    kStatsAllParts = 31u
};

/// Anything that hands out a statistics image by blocks of rows: a file (StatsFileReader), the
/// merge of two sources (MergedStatsSource), an image in memory (MemoryStatsSource). The streamed
/// operations (imageops.h) and the streaming writer (StatsFileWriter) take any of them, so memory
/// follows the rows in flight and not the image height.
class StatsBlockSource {
  public:
    virtual ~StatsBlockSource() = default;
    /// The whole image's header (width 0 until the source is ready).
    virtual const StatsHeader& header() const = 0;
    /// What messages call the source (a path, "merge(a, b)").
    virtual const std::string& name() const = 0;
    /// Rows per compressed chunk of the sub-buffer part (1 when not a file): blocks that start
    /// on a multiple of it never decode a chunk twice.
    virtual int chunkRows() const { return 1; }
    /// Threads that decode one block's chunks in parallel (1 when not a file): blockRows gives
    /// each of them at least one chunk, or wide rows would leave all but one idle.
    virtual int decodeThreads() const { return 1; }
    /// Reads rows [firstRow, firstRow + rows) of the data window (0-based) of the parts in
    /// `parts` (StatsParts) into `block`: its header is the image's with height = rows and
    /// originY moved to the first row; the arrays of parts not read are empty. `block`'s
    /// storage is reused from one call to the next. False with `err` ("<name>: <problem>") on a
    /// bad range, a bad value or a damaged file.
    virtual bool read(int firstRow, int rows, unsigned parts, StatsImage& block,
                      std::string& err) = 0;
    /// Blocks of the rows asked for that a read holds in memory at once: 1, or for a merge its own
    /// and every input's (blockRows divides its budget by it).
    virtual int blocksHeld() const { return 1; }
    /// Whether header() describes an image (the source opened or initialised).
    bool ready() const { return header().width > 0 && header().height > 0; }
    /// A block height for about `budgetBytes` of decoded parts `parts` in all the blocks a read
    /// holds (blocksHeld()): a multiple of
    /// chunkRows(), at least one chunk per decoding thread (decodeThreads()), at most the image
    /// height.
    int blockRows(unsigned parts = kStatsAllParts, size_t budgetBytes = size_t(64) << 20) const;
};

/// Streams a statistics file by blocks of rows. The headers are validated once by open() (as
/// readStatsFile does, including that every chunk lies inside the file); each read() validates
/// what it decoded (counts, and with buffers and moments both read, that buffer counts sum to the
/// moments count). OpenEXR decodes each block's chunks on `nthreads` threads. Not thread-safe:
/// one reader per thread.
class StatsFileReader final : public StatsBlockSource {
  public:
    StatsFileReader();
    ~StatsFileReader() override;
    StatsFileReader(const StatsFileReader&) = delete;
    StatsFileReader& operator=(const StatsFileReader&) = delete;

    /// Opens `path` and checks its headers; no pixel memory is allocated. `nthreads` 0: all
    /// cores. When OpenEXR's global thread pool is empty (a process that never set it, like
    /// `mcstat`) it is sized to `nthreads`; a pool the host application sized (OIIO) is left as it
    /// is.
    bool open(const std::string& path, std::string& err, const ReadLimits& limits = ReadLimits(),
              int nthreads = 0);
    bool isOpen() const;
    const std::string& path() const;
    const StatsHeader& header() const override;
    const std::string& name() const override { return path(); }
    int chunkRows() const override;
    int decodeThreads() const override;
    bool read(int firstRow, int rows, unsigned parts, StatsImage& block, std::string& err) override;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// Hands out the rows of an image in memory (e.g. the result of `mcstat --ingest`).
class MemoryStatsSource final : public StatsBlockSource {
  public:
    MemoryStatsSource(std::shared_ptr<const StatsImage> img, std::string name);
    const StatsHeader& header() const override { return img_->header; }
    const std::string& name() const override { return name_; }
    bool read(int firstRow, int rows, unsigned parts, StatsImage& block, std::string& err) override;

  private:
    std::shared_ptr<const StatsImage> img_;
    std::string name_;
};

/// The merge of sources (mergeStats) in one pass, block by block: each block of the result equals
/// the same rows of mergeStats over the whole images, since the merge is per pixel. Reads every
/// part of every input whatever `parts` asks (the merge of one part needs the others' counts).
/// The inputs are merged in the order given (mergeOrder gives the canonical one) and must outlive
/// this source. A tree of merges is a MergedStatsSource over MergedStatsSources.
class MergedStatsSource final : public StatsBlockSource {
  public:
    /// Checks that the inputs can merge (mergeHeaders, named by their name()); false with `err`.
    /// `nthreads` merge each block (0: all cores).
    bool init(const std::vector<StatsBlockSource*>& inputs, std::string& err, int nthreads = 1);
    /// init of two inputs.
    bool init(StatsBlockSource& a, StatsBlockSource& b, std::string& err);
    const StatsHeader& header() const override { return header_; }
    const std::string& name() const override { return name_; }
    int chunkRows() const override;
    int decodeThreads() const override;
    int blocksHeld() const override;
    bool read(int firstRow, int rows, unsigned parts, StatsImage& block, std::string& err) override;

  private:
    std::vector<StatsBlockSource*> inputs_;
    StatsHeader header_;
    std::string name_;
    std::vector<StatsImage> blocks_;
    int nthreads_ = 1;
};

/// Writes a statistics file by blocks of rows, in order: open(), write() each block (all four
/// parts, rows following the previous block's), commit(). The file grows under a temporary name in
/// the target's folder and is renamed onto the target by commit(); a writer destroyed before
/// commit() (an error, an interruption) removes the temporary file and leaves the target as it
/// was. OpenEXR compresses each block's chunks on `nthreads` threads. A whole image written as one
/// block gives the same bytes as writeStatsFile.
class StatsFileWriter {
  public:
    StatsFileWriter();
    ~StatsFileWriter();
    StatsFileWriter(const StatsFileWriter&) = delete;
    StatsFileWriter& operator=(const StatsFileWriter&) = delete;
    /// Creates the temporary file for an image described by `header` (checked as validateStats
    /// checks headers); `nthreads` 0: all cores.
    bool open(const std::string& path, const StatsHeader& header, std::string& err,
              int nthreads = 0);
    /// Appends `block` (a valid image of whole rows: header.originY the next row to write, every
    /// part present, part aovs too when the header has AOVs, the same AOVs as open()'s header).
    bool write(const StatsImage& block, std::string& err);
    /// Before commit(): mcstat:seeds as known only once every row was read (an ingest's RGB
    /// hashes, IngestSource), of the same length as open()'s placeholder; commit() puts it in
    /// place in every part's header before the rename. False with `err` on another length.
    bool replaceSeeds(const std::string& seeds, std::string& err);
    /// After the last row: completes the file and renames it onto the target.
    bool commit(std::string& err);

  private:
    friend struct StatsFileWriterAccess;
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// Streams every row of `src` into the statistics file `path` (StatsFileWriter) by blocks of
/// about `budgetBytes` decoded bytes: e.g. `mcstat a.mcstat b.mcstat --merge -o m.mcstat` holds
/// a block of each input and of the result, never the images.
bool writeStatsFile(const std::string& path, StatsBlockSource& src, std::string& err,
                    int nthreads = 0, size_t budgetBytes = size_t(64) << 20);

/// Reads every row and part of `src` into memory, validated.
bool readAll(StatsBlockSource& src, StatsImage& img, std::string& err);

/// Reads only the headers (cheap): what `mcstat --info` shows before loading pixels.
bool readStatsHeader(const std::string& path, StatsHeader& hdr, std::string& err,
                     const ReadLimits& limits = ReadLimits());

/// What checkStatsFile looked at.
struct StatsCheckReport {
    StatsHeader header;
    int64_t pixels = 0;
    int64_t subBuffers = 0;       ///< pixels * M, or with adaptive M the deep samples of vbuffers
    int64_t nonFinite = 0;        ///< NaN or Inf sub-buffer means (allowed: FORMAT.md)
    int64_t records = 0;          ///< samples of part records (0 without it)
    bool state = false;           ///< the state parts (header.state) were read
    bool openexrChecked = false;  ///< OpenEXR's own checker (exrcheck's) ran and passed
};

/// Any OpenEXR file (a renderer's render as well as a statistics file): every header attribute's
/// claimed size against the bytes left in the file, and the structure of the attributes OpenEXR
/// reads by structure. OpenEXR's C++ reader allocates what a header claims before reading it
/// (gigabytes for a file of a few KB), so readers of untrusted EXRs call this first. True for a
/// file that is not OpenEXR (not its business); false with "<path>: <problem>" otherwise. With
/// maxPixels > 0, a part whose data window holds more pixels is refused too: OpenEXR's C++ reader
/// allocates its line buffers by the data window's width when the file is opened (a 1.4 KB file
/// claiming 4259846 x 770 pixels cost 8 s of page faults under the fuzzer).
bool checkExrAttributeSizes(const std::string& path, std::string& err, int64_t maxPixels = 0);

/// What a file holds, judged by its content and never by its name: a statistics file may be named
/// x.exr (OIIO's plugin needs .mcstat, nothing else does) and a plain EXR may be named x.mcstat.
struct FileContent {
    enum Kind {
        Missing,    ///< no such file
        Directory,  ///< a directory
        Special,    ///< neither a regular file nor a directory (a pipe, a device)
        NotExr,     ///< a regular file without OpenEXR's magic number (another format, or none)
        PlainExr,   ///< an OpenEXR file without the sub-buffers: an image
        Stats,      ///< an OpenEXR file with part `buffers` or `vbuffers`, or one that declares a
                    ///< newer mcstat:formatVersion: a statistics file (readStatsHeader checks it)
    } kind = Missing;
    /// OpenEXR files: every part's name, in order ("" for a part without one).
    std::vector<std::string> partNames;
    /// "part 'beauty'", "parts 'rgba', 'depth'", "one unnamed part": for messages.
    std::string partsText() const;
};
/// Decides FileContent from the file's magic number and, for OpenEXR, its headers only (every
/// attribute size checked against the file first, as checkExrAttributeSizes does, then parsed by
/// OpenEXR's Core API, which sizes nothing by the image); no pixel is read. False with
/// "<path>: <problem>" when an OpenEXR file's headers are damaged or the file cannot be read.
bool probeFileContent(const std::string& path, FileContent& out, std::string& err);

/// What `mcstat f --info` says of headers `h` after its first line: size and M, renderer,
/// colour space, seeds, variance, sources, parts, features, beauty and AOVs, one string a line
/// (no newline), every string the file supplied shown through printable()
/// (mcstat/core/untrusted_text.h): no line holds a control byte.
std::vector<std::string> describeStatsHeader(const StatsHeader& h);

/// Validates the statistics file `path` completely, as exrcheck does for any OpenEXR file and
/// more (`mcstat f --check`): the headers and chunk table (as readStatsHeader), OpenEXR's own
/// checker (Imf::checkOpenEXRFile, in its reduced-memory mode), then every row of every part
/// decoded by blocks with every count checked (finite, integral, 0..2^24, the buffer counts of a
/// pixel summing to its count), part records by blocks and the state parts. Memory follows
/// the blocks, not the image. `progress` (0..1) is called between blocks when set. False with the
/// first problem as one line naming the file.
bool checkStatsFile(const std::string& path, StatsCheckReport& report, std::string& err,
                    const ReadLimits& limits = ReadLimits(), int nthreads = 0,
                    const std::function<void(double)>& progress = {});

/// Checks the in-memory invariants (sizes, adaptive buffer offsets, counts finite, non-negative and
/// integral, buffer counts summing to the moments count). `what` names the source in the message.
bool validateStats(const StatsImage& img, const std::string& what, std::string& err);
/// validateStats over the parts in `parts` only (StatsParts bits): the arrays of the other parts
/// are not looked at; the buffer-count sum is checked when buffers and moments are both there.
bool validateStats(const StatsImage& img, unsigned parts, const std::string& what,
                   std::string& err);

/// Variance of the samples of pixel p, channel c, estimated from its non-empty buffers
/// (mcstat:variance "buffers"): sum_j n_j (m_j - mean)^2 / (M_f - 1) over the M_f non-empty
/// buffers, `mean` the pixel's mean; NaN when fewer than two buffers hold samples. Unbiased for
/// buffers of independent samples (the between-group mean square of a one-way ANOVA).
double bufferVariance(const StatsImage& img, size_t p, size_t c, double mean);

/// How many inputs one node of an N-way merge takes by default (`mcstat --merge:fanin=K`): the
/// merge of n inputs is a tree of depth ceil(log_K n) (FORMAT.md "Merge of N files").
inline constexpr int kDefaultMergeFanIn = 8;

/// The canonical order of merge inputs (FORMAT.md "Merge of N files"): by their seed lists,
/// compared seed by seed (numbers by value, before other seeds, which compare as text), inputs
/// without seeds first, ties in the given order. Returns the input indices in that order; a merge
/// whose inputs are sorted so gives the same bytes whatever order they were given in.
std::vector<size_t> mergeOrder(const std::vector<const StatsHeader*>& inputs);

/// The header of mergeStats(inputs)'s result from the inputs' headers, after checking that they
/// can merge (same size, origin, M, assignment, variance source, features, colour space, display
/// window, AOVs, beauty channel names and part; no seed in two inputs): spp added, seeds and
/// sources lists concatenated in input order, renderer names each once in the order first seen,
/// source metadata the first input's. False with `err` naming the first difference and, when
/// `names` are given (one per input), the inputs involved.
bool mergeHeaders(const std::vector<const StatsHeader*>& inputs, StatsHeader& out, std::string& err,
                  const std::vector<std::string>& names = {});
/// mergeHeaders of two inputs.
bool mergeHeaders(const StatsHeader& a, const StatsHeader& b, StatsHeader& out, std::string& err);

/// Combines renders of the same image (same size, M, assignment) into one, as if a single render
/// had taken all their samples, in one pass (FORMAT.md "Merge"): per buffer the count-weighted mean
/// summed in input order in double and rounded once; the pooled variance; AOVs per buffer
/// count-weighted like the buffer means, except class Id: the value of the input whose buffer
/// count is the largest (the first such; a later input's when the earlier one's count is 0).
/// Adaptive M: every input adaptive with the same m_p in every pixel (else refused, naming the
/// first differing pixel); fixed and adaptive inputs are never merged. `nthreads` threads over
/// the pixels (0: all cores); the result does not depend on it. `out` may be one of the inputs.
bool mergeStats(const std::vector<const StatsImage*>& inputs, StatsImage& out, std::string& err,
                int nthreads = 1);
/// mergeStats of two inputs, on one thread.
bool mergeStats(const StatsImage& a, const StatsImage& b, StatsImage& out, std::string& err);

}  // namespace mcstat
