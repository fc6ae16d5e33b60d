// Format version 4 (exr-deep/FORMAT.md, "Version 4: samples and modes"): the optional parts a
// statistics file can carry after its four parts.
// - `records`: every sample of every pixel in the order taken (a deep scanline part). It is large
//   by nature, so it is written and read by blocks of rows: SampleRecordsWriter streams a render's
//   rows to a temporary file, which writeStatsFile copies chunk by chunk (no decoding) into the
//   final file; SampleRecordsReader reads rows [y0, y1) at a time.
// - state parts with an owner, a flat and a deep part: an operation's per-pixel state
//   (PixelStateParts), stored exactly, so that a render resumed from the file continues bit for
//   bit. The format stores the parts' channels, their owner and its parameter text, and checks
//   their shapes; the operation that owns them (its registry entry's OperationState) names the
//   parts and gives them meaning.
// No function throws; each returns false with a one-line `err` naming the file.
#pragma once

#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat {

/// Fields of a per-sample record. Required: R, G, B (the sample's radiance as float32) and Z (the
/// first-hit distance along the camera ray, +inf on a miss), plus A = 1 for deep tools. Optional
/// fields (random parameter filtering's inputs, Sen & Darabi 2011 section 3.1) are declared by
/// their channels being present and listed in `mcstat:recordFields`; readers ignore channels they
/// do not know (FORMAT.md "Per-sample fields").
inline constexpr int kRecordFloats = 4;  ///< R, G, B, Z: the required channels, first in memory
/// The record fields every records part holds (attribute mcstat:recordFields starts with these).
inline constexpr const char* kRecordFieldsBase = "R,G,B,Z";

/// One field of a record: its name in mcstat:recordFields and its FLOAT channels.
struct RecordField {
    const char* name;
    std::vector<const char*> channels;
    const char* meaning;  ///< one line: what the value is and its range
};
/// Every field this version knows, in the order they are stored (FORMAT.md lists the same).
const std::vector<RecordField>& recordFieldTable();
/// The field of per-sample AOVs: channels kRecordAovPrefix + every AOV of the file's header
/// (StatsHeader::aovs), after the table's fields (FORMAT.md "Per-sample fields").
inline constexpr const char* kRecordFieldAov = "aov";
/// The channels of `fields` (names from recordFieldTable, each once; R,G,B,Z always first; field
/// kRecordFieldAov last, one channel per AOV of `aovs`). False with `err` naming an unknown
/// field, or field aov without AOVs.
bool recordChannelsOf(const std::vector<std::string>& fields, std::vector<std::string>& channels,
                      std::string& err, const std::vector<AovChannel>& aovs = {});
/// Bytes one sample costs in the file before compression: its channels plus A, as float32.
inline int64_t recordBytesOnDisk(size_t channels) { return int64_t(channels + 1) * 4; }
/// Bytes of a record with only the required fields (R, G, B, Z, A).
inline constexpr int kRecordBytesOnDisk = 20;

/// Prefixes of channel names by role, for operations that find their inputs by name: random
/// parameters (the numbers a sample drew, in the form the renderer used them) and scene
/// features; screen position is `screen.x`, `screen.y`.
inline constexpr const char* kRandomParameterPrefix = "rand.";
/// Per-sample AOVs (docs/aovs.md): channel "aov.<name>" holds the sample's value of the file's
/// AOV <name> (StatsHeader::aovs), so that per-sample operations weight AOVs as the beauty.
inline constexpr const char* kRecordAovPrefix = "aov.";
inline constexpr const char* kFeaturePrefix = "feat.";

/// Default limit of `mcstat-render --keep-samples` (uncompressed bytes of the records part).
inline constexpr int64_t kDefaultMaxRecordBytes = int64_t(4) << 30;

/// Rows of samples: pixel p of the block (p = (y - y0) * width + x) holds counts[p] samples,
/// stored from samples[offset(p) * stride()], offset(p) = counts[0] + ... + counts[p-1]; a
/// sample's floats follow `channels` (R, G, B, Z first).
struct SampleBlock {
    int y0 = 0, rows = 0, width = 0;
    std::vector<std::string> channels{"R", "G", "B", "Z"};
    std::vector<uint32_t> counts;
    std::vector<float> samples;
    size_t stride() const { return channels.size(); }
    /// Index of channel `name` within a sample, or -1.
    int channel(const std::string& name) const {
        for (size_t i = 0; i < channels.size(); ++i)
            if (channels[i] == name) return int(i);
        return -1;
    }
    void clear(int firstRow, int nrows, int w) {
        y0 = firstRow;
        rows = nrows;
        width = w;
        counts.assign(size_t(nrows) * size_t(w), 0);
        samples.clear();
    }
};

/// Streams the records of a render, rows in increasing order, to a single-part deep file (a
/// temporary next to the target); writeStatsFile then moves its chunks into the statistics file.
class SampleRecordsWriter {
  public:
    SampleRecordsWriter();
    ~SampleRecordsWriter();  ///< removes the temporary file unless release() was called
    SampleRecordsWriter(const SampleRecordsWriter&) = delete;
    SampleRecordsWriter& operator=(const SampleRecordsWriter&) = delete;
    /// Opens a temporary file next to `target` for an image of header `h` (its data window),
    /// storing `fields` (names from recordFieldTable; R, G, B, Z are always stored).
    bool open(const std::string& target, const StatsHeader& h, std::string& err,
              const std::vector<std::string>& fields = {});
    /// The channels a written block must hold, in this order (SampleBlock::channels).
    const std::vector<std::string>& channels() const;
    /// Writes the next rows (block.y0 must be the first row not yet written, block.channels
    /// equal to channels()).
    bool write(const SampleBlock& block, std::string& err);
    /// Finishes the file (every row must have been written).
    bool close(std::string& err);
    const std::string& path() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// Reads the `records` part of a statistics file by blocks of rows.
class SampleRecordsReader {
  public:
    SampleRecordsReader();
    ~SampleRecordsReader();
    /// Opens `path` and checks its headers (readStatsHeader) and that it has a records part.
    /// `nthreads`: threads decoding the records (detail::codecThreads: 0 all cores, 1 the caller
    /// alone); -1 leaves it to OpenEXR (its global thread count). The records read are the same.
    bool open(const std::string& path, std::string& err, const ReadLimits& limits = ReadLimits(),
              int nthreads = -1);
    const StatsHeader& header() const;
    /// The FLOAT channels of the part (A excepted): R, G, B, Z, then the others in file order.
    const std::vector<std::string>& available() const;
    /// The fields listed in mcstat:recordFields.
    const std::vector<std::string>& fields() const;
    /// Reads only `channels` from now on (R, G, B, Z are always read, first); false with `err`
    /// naming the first channel the part does not hold.
    bool select(const std::vector<std::string>& channels, std::string& err);
    /// Reads rows [y0, y0 + rows) into `block` (its channels set to the selection); the block's
    /// samples are bounded by the limits (checked against the counts before anything is allocated)
    /// and every count by 2^24.
    bool read(int y0, int rows, SampleBlock& block, std::string& err);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// Per-pixel state an operation keeps in a statistics file (FORMAT.md "State parts with an
/// owner"): a flat part of FLOAT and UINT channels (one value each per pixel) and a deep part of
/// FLOAT channels (any number of records per pixel), both carrying the owner's name and its
/// parameter text. Channels are found by name: the writer writes the channels listed, the reader
/// returns every FLOAT and UINT channel the file holds (in the file's order), and the operation
/// looks up the ones it needs.
struct PixelStateParts {
    StateOwner owner;  ///< the owning operation, its parameters and the parts' names
    std::vector<std::string> floatChannels, uintChannels;  ///< the flat part's channels
    std::vector<float> floats;                             ///< [p * floatChannels.size() + c]
    std::vector<uint32_t> words;                           ///< [p * uintChannels.size() + c]
    std::vector<std::string> recordChannels;               ///< the deep part's channels (FLOAT)
    std::vector<uint32_t> recordCounts;                    ///< [p]: records of pixel p
    std::vector<float> records;  ///< [k * recordChannels.size() + c], pixels in scanline order
};
/// A double kept exactly in two UINT words of a state part (high 32 bits, then low): how an
/// operation stores running sums it must resume bit for bit (sample delaying's, the cascades).
inline void putStateDouble(uint32_t* w, double d) {
    uint64_t bits = 0;
    std::memcpy(&bits, &d, sizeof bits);
    w[0] = uint32_t(bits >> 32);
    w[1] = uint32_t(bits & 0xffffffffu);
}
/// The double putStateDouble stored in w[0], w[1].
inline double getStateDouble(const uint32_t* w) {
    const uint64_t bits = (uint64_t(w[0]) << 32) | uint64_t(w[1]);
    double d = 0;
    std::memcpy(&d, &bits, sizeof d);
    return d;
}

/// What writeStatsFile adds to the four parts (format version 4).
struct StatsExtras {
    const PixelStateParts* state = nullptr;  ///< the state parts, named by their owner
    std::string recordsFile;                 ///< a closed SampleRecordsWriter's file: part records
};

/// writeStatsFile with the version-4 parts; img.header.formatVersion must be 4 when any is given.
bool writeStatsFile(const std::string& path, const StatsImage& img, const StatsExtras& extras,
                    std::string& err);

/// What a per-sample operation reads of a statistics file, behind an interface so that the
/// operation itself (filters/, free of I/O) never opens a file: exr-deep implements it.
class SampleSource {
  public:
    virtual ~SampleSource() = default;
    virtual const StatsHeader& header() const = 0;
    /// Rows [y0, y0 + rows) of part records (header().hasRecords).
    virtual bool readRecords(int y0, int rows, SampleBlock& block, std::string& err) = 0;
    /// The channels part records holds (SampleRecordsReader::available), empty without it.
    virtual std::vector<std::string> recordChannels() const = 0;
    /// Restricts readRecords to `channels` (SampleRecordsReader::select).
    virtual bool selectRecordChannels(const std::vector<std::string>& channels,
                                      std::string& err) = 0;
    /// The state parts (header().hasState()).
    virtual bool readPixelState(PixelStateParts& out, std::string& err) = 0;
    /// The file name, for messages.
    virtual const std::string& path() const = 0;
};
/// A SampleSource over statistics file `path` (its headers checked); nullptr with `err`. Its
/// records are decoded on `nthreads` threads (SampleRecordsReader::open).
std::unique_ptr<SampleSource> openSampleSource(const std::string& path, std::string& err,
                                               const ReadLimits& limits = ReadLimits(),
                                               int nthreads = -1);

/// Reads the state parts of a statistics file (the whole state: small next to records), their
/// sizes checked against the limits before anything is allocated. An error names the file; a file
/// without state parts is one. With `header`, the file's headers (read and checked on the way).
bool readPixelStateParts(const std::string& path, PixelStateParts& out, std::string& err,
                         const ReadLimits& limits = ReadLimits(), StatsHeader* header = nullptr);

}  // namespace mcstat
