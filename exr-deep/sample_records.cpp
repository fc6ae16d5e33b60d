// Format version 4's optional parts (FORMAT.md "Version 4: samples and modes"): the per-sample
// part `records`, written by blocks of rows to a temporary deep file and moved chunk by chunk into
// the statistics file, read back by blocks of rows; and an operation's per-pixel state, parts
// an operation's state parts (flat: FLOAT and UINT channels; deep: FLOAT records), stored as given
// with their owner and read back by name (what they mean: the owner's OperationState).
#include "mcstat/exr-deep/sample_records.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepScanLineInputFile.h>
#include <OpenEXR/ImfDeepScanLineInputPart.h>
#include <OpenEXR/ImfDeepScanLineOutputPart.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfInputPart.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfOutputPart.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <errno.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include "deep_frame_buffer.h"
#include "extra_parts.h"
#include "mcstat/core/params.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/temp_file.h"
#include "part_header.h"
#include "stats_layout.h"
#include "window.h"

namespace mcstat {

namespace {

constexpr double kMaxExactCount = 16777216.0;  // 2^24: counts are float32 in the file

using detail::DeepFrameBufferSet;
using detail::windowBase;
using detail::windowOf;

// ---- records ---------------------------------------------------------------------------------

Imf::Header recordsHeader(const StatsHeader& h, const std::vector<std::string>& channels,
                          const std::string& fields) {
    Imf::Header hdr = detail::commonHeader(h, layout::kPartRecords, true);
    for (const std::string& c : channels) hdr.channels().insert(c, Imf::Channel(Imf::FLOAT));
    hdr.channels().insert("A", Imf::Channel(Imf::FLOAT));
    hdr.insert(layout::kAttrRecordFields, Imf::StringAttribute(fields));
    return hdr;
}

std::vector<std::string> splitList(const std::string& text) {
    std::vector<std::string> out;
    size_t start = 0;
    while (start <= text.size()) {
        const size_t comma = std::min(text.find(',', start), text.size());
        if (comma > start) out.push_back(text.substr(start, comma - start));
        start = comma + 1;
    }
    return out;
}

/// The deep frame buffer over `block` for a read: its counts and each channel's per-pixel pointers
/// into its samples. Set it, read the counts into block.counts, allocate the samples and only then
/// call point() (deep_frame_buffer.h).
struct RecordPointers {
    DeepFrameBufferSet set;
    RecordPointers(const StatsHeader& h, SampleBlock& b) : set(h, b.counts.data(), b.y0) {
        const size_t nc = b.stride();
        for (size_t c = 0; c < nc; ++c)
            set.addChannel(b.channels[c], b.counts.size(), nc * sizeof(float));
    }
    /// Points every pixel at its samples (after the counts are known and the samples allocated).
    void point(SampleBlock& b) {
        set.pointContiguous(b.samples.data(), b.counts.data(), b.counts.size(), b.stride());
    }
    Imf::DeepFrameBuffer& fb() { return set.frameBuffer(); }
};

}  // namespace

const std::vector<RecordField>& recordFieldTable() {
    static const std::vector<RecordField> table = {
        {"R", {"R"}, "red radiance of the sample"},
        {"G", {"G"}, "green radiance of the sample"},
        {"B", {"B"}, "blue radiance of the sample"},
        {"Z", {"Z"}, "first-hit distance along the camera ray, +inf on a miss"},
        {"screen",
         {"screen.x", "screen.y"},
         "raster position of the camera sample in the data window: pixel (i, j) covers "
         "[i, i+1) x [j, j+1)"},
        {"lens",
         {"rand.lens.u", "rand.lens.v"},
         "point on the lens in unit-disk coordinates, [-1, 1] (depth of field)"},
        {"time", {"rand.time"}, "shutter time of the sample, [0, 1) (motion blur)"},
        {"light",
         {"rand.light.u", "rand.light.v"},
         "the two numbers that chose the point on the light sampled at the first hit, [0, 1); "
         "0 when none was sampled"},
        {"bounce",
         {"rand.bounce.u", "rand.bounce.v"},
         "the two numbers that chose the direction leaving the first hit, [0, 1); 0 when none"},
        {"N1", {"N1.X", "N1.Y", "N1.Z"}, "unit shading normal at the first hit; 0 on a miss"},
        {"P1", {"P1.X", "P1.Y", "P1.Z"}, "world position of the first hit; 0 on a miss"},
        {"T1",
         {"T1.R", "T1.G", "T1.B"},
         "texture value at the first hit: the albedo the shader used; 0 on a miss"},
        {"N2", {"N2.X", "N2.Y", "N2.Z"}, "unit normal at the second hit; 0 when none"},
        {"P2", {"P2.X", "P2.Y", "P2.Z"}, "world position of the second hit; 0 when none"},
    };
    return table;
}

bool recordChannelsOf(const std::vector<std::string>& fields, std::vector<std::string>& channels,
                      std::string& err, const std::vector<AovChannel>& aovs) {
    const auto& table = recordFieldTable();
    std::vector<bool> want(table.size(), false);
    for (int i = 0; i < kRecordFloats; ++i) want[size_t(i)] = true;
    bool wantAovs = false;
    for (const std::string& f : fields) {
        if (f == kRecordFieldAov) {
            if (aovs.empty()) {
                err = "record field 'aov' needs AOVs in the header (part aovs)";
                return false;
            }
            wantAovs = true;
            continue;
        }
        size_t i = 0;
        while (i < table.size() && f != table[i].name) ++i;
        if (i == table.size()) {
            std::string known;
            for (const RecordField& r : table)
                known += (known.empty() ? "" : ", ") + std::string(r.name);
            err = fmt::format("unknown record field '{}' (known: {})", printable(f), known);
            return false;
        }
        want[i] = true;
    }
    channels.clear();
    for (size_t i = 0; i < table.size(); ++i)
        if (want[i])
            for (const char* c : table[i].channels) channels.emplace_back(c);
    if (wantAovs)
        for (const AovChannel& a : aovs) channels.push_back(kRecordAovPrefix + a.name);
    return true;
}

struct SampleRecordsWriter::Impl {
    StatsHeader header;
    std::unique_ptr<TemporaryFile> tmp;  ///< the records file, removed with the writer
    std::string path;                    ///< tmp's path
    std::vector<std::string> channels;
    detail::Fd fd;
    std::unique_ptr<detail::CorePartWriter> file;  ///< one deep part, chunks straight to `fd`
    int nextRow = 0;
};

SampleRecordsWriter::SampleRecordsWriter() : impl_(new Impl) {}

SampleRecordsWriter::~SampleRecordsWriter() {
    impl_->file.reset();
    impl_->fd.reset();
    impl_->tmp.reset();
}

const std::string& SampleRecordsWriter::path() const { return impl_->path; }
const std::vector<std::string>& SampleRecordsWriter::channels() const { return impl_->channels; }

bool SampleRecordsWriter::open(const std::string& target, const StatsHeader& h, std::string& err,
                               const std::vector<std::string>& fields) {
    impl_->header = h;
    std::string why;
    if (!recordChannelsOf(fields, impl_->channels, why, h.aovs)) {
        err = target + ": " + why;
        return false;
    }
    // mcstat:recordFields: the fields in table order (R, G, B, Z first), then aov.
    std::string list;
    for (const RecordField& f : recordFieldTable()) {
        bool present = false;
        for (const std::string& c : impl_->channels) present = present || c == f.channels[0];
        if (present) list += (list.empty() ? "" : ",") + std::string(f.name);
    }
    if (std::find(fields.begin(), fields.end(), kRecordFieldAov) != fields.end())
        list += std::string(",") + kRecordFieldAov;
    if (!checkOutputTarget(target, err)) return false;
    impl_->tmp = std::make_unique<TemporaryFile>(target, ".records");
    impl_->path = impl_->tmp->path();
    impl_->fd =
        detail::Fd(::open(impl_->path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600));
    if (impl_->fd.get() < 0) {
        err = fmt::format("{}: cannot create the per-sample records {} ({})", target, impl_->path,
                          std::strerror(errno));
        impl_->tmp->remove();  // nothing was created; forget the name
        return false;
    }
    std::string problem;
    try {
        impl_->file = std::make_unique<detail::CorePartWriter>();
        if (!impl_->file->open(impl_->fd.get(), impl_->path,
                               {recordsHeader(h, impl_->channels, list)}, detail::codecThreads(0),
                               problem))
            impl_->file.reset();
    } catch (const std::exception& e) {
        problem = e.what();
        impl_->file.reset();
    }
    if (!impl_->file) {
        err = fmt::format("{}: cannot create the per-sample records ({})", target,
                          libraryMessage(problem));
        return false;
    }
    return true;
}

bool SampleRecordsWriter::write(const SampleBlock& block, std::string& err) {
    if (!impl_->file || block.y0 != impl_->nextRow || block.width != impl_->header.width ||
        block.rows < 1 || impl_->nextRow + block.rows > impl_->header.height) {
        err = impl_->path + ": records written out of order";
        return false;
    }
    if (block.channels != impl_->channels ||
        block.samples.size() <
            block.stride() *
                size_t(std::accumulate(block.counts.begin(), block.counts.end(), uint64_t(0)))) {
        err = impl_->path + ": a block of records does not hold the channels the file declares";
        return false;
    }
    // Sample k of the block at samples[k * stride + c]; A is 1 for every sample.
    static const float kOne = 1.f;
    detail::PartRows rows;
    rows.counts = block.counts.data();
    const size_t nc = block.stride();
    for (size_t c = 0; c < nc; ++c)
        rows.deep.push_back({block.channels[c],
                             block.samples.empty()
                                 ? nullptr
                                 : reinterpret_cast<const char*>(block.samples.data() + c),
                             nc * sizeof(float), false});
    rows.deep.push_back({"A", reinterpret_cast<const char*>(&kOne), 0, true});
    std::string problem;
    bool ok = false;
    try {
        ok = impl_->file->write({rows}, block.rows, problem);
    } catch (const std::bad_alloc&) {
        problem = "out of memory";
    }
    if (!ok) {
        impl_->file.reset();  // no further writes
        err = fmt::format("{}: cannot write records ({})", impl_->path, libraryMessage(problem));
        return false;
    }
    impl_->nextRow += block.rows;
    return true;
}

bool SampleRecordsWriter::close(std::string& err) {
    if (!impl_->file || impl_->nextRow != impl_->header.height) {
        err = impl_->path + ": records closed before the last row";
        return false;
    }
    std::string problem;
    if (!impl_->file->finish(problem)) {
        impl_->file.reset();
        err = fmt::format("{}: cannot finish records ({})", impl_->path, libraryMessage(problem));
        return false;
    }
    impl_->file.reset();
    if (const std::string closeErr = impl_->fd.close(); !closeErr.empty()) {
        err = fmt::format("{}: cannot finish records ({})", impl_->path, closeErr);
        return false;
    }
    return true;
}

struct SampleRecordsReader::Impl {
    std::string path;
    StatsHeader header;
    ReadLimits limits;
    std::unique_ptr<Imf::MultiPartInputFile> file;
    int part = -1;
    std::vector<std::string> available, fields, selected;
};

SampleRecordsReader::SampleRecordsReader() : impl_(new Impl) {}
SampleRecordsReader::~SampleRecordsReader() = default;
const StatsHeader& SampleRecordsReader::header() const { return impl_->header; }
const std::vector<std::string>& SampleRecordsReader::available() const { return impl_->available; }
const std::vector<std::string>& SampleRecordsReader::fields() const { return impl_->fields; }

bool SampleRecordsReader::open(const std::string& path, std::string& err, const ReadLimits& limits,
                               int nthreads) {
    impl_->path = path;
    impl_->limits = limits;
    if (!readStatsHeader(path, impl_->header, err, limits)) return false;
    if (!impl_->header.hasRecords) {
        err = path +
              ": no per-sample records (part 'records'); render with mcstat-render "
              "--keep-samples";
        return false;
    }
    try {
        // OpenEXR decodes the line buffers of a read on its global pool (codecThreads sizes it
        // when nothing did); 0 threads: one line buffer at a time, on the caller.
        const int threads =
            nthreads < 0 ? Imf::globalThreadCount() : detail::codecThreads(nthreads);
        impl_->file.reset(new Imf::MultiPartInputFile(path.c_str(), threads > 1 ? threads : 0));
        for (int i = 0; i < impl_->file->parts(); ++i)
            if (impl_->file->header(i).name() == layout::kPartRecords) impl_->part = i;
        if (impl_->part < 0) throw std::runtime_error("part 'records' vanished");
        const Imf::Header& hdr = impl_->file->header(impl_->part);
        const Imf::ChannelList& ch = hdr.channels();
        impl_->available.clear();
        for (const char* c : {"R", "G", "B", "Z"}) {
            const Imf::Channel* x = ch.findChannel(c);
            if (x == nullptr || x->type != Imf::FLOAT)
                throw std::runtime_error(fmt::format(
                    "part 'records' has no FLOAT channel '{}' (required: R, G, B, Z)", c));
            impl_->available.emplace_back(c);
        }
        for (auto it = ch.begin(); it != ch.end(); ++it) {
            const std::string name = it.name();
            if (it.channel().type != Imf::FLOAT || name == "A" || name == "R" || name == "G" ||
                name == "B" || name == "Z")
                continue;
            impl_->available.push_back(name);
        }
        // mcstat:recordFields: every field it lists must have its channels (FORMAT.md).
        const auto* f = hdr.findTypedAttribute<Imf::StringAttribute>(layout::kAttrRecordFields);
        impl_->fields = splitList(f != nullptr ? f->value() : std::string(kRecordFieldsBase));
        const auto requireFloat = [&](const std::string& field, const std::string& c) {
            const Imf::Channel* x = ch.findChannel(c);
            if (x == nullptr || x->type != Imf::FLOAT)
                throw std::runtime_error(fmt::format(
                    "part 'records' lists field '{}' but has no FLOAT channel '{}'", field, c));
        };
        for (const std::string& name : impl_->fields) {
            for (const RecordField& rf : recordFieldTable())
                if (name == rf.name)
                    for (const char* c : rf.channels) requireFloat(name, c);
            if (name == kRecordFieldAov)
                for (const AovChannel& a : impl_->header.aovs)
                    requireFloat(name, kRecordAovPrefix + a.name);
        }
        impl_->selected = impl_->available;
    } catch (const std::exception& e) {
        err = fmt::format("{}: {}", path, libraryMessage(e.what()));
        return false;
    }
    return true;
}

bool SampleRecordsReader::select(const std::vector<std::string>& channels, std::string& err) {
    std::vector<std::string> sel{"R", "G", "B", "Z"};
    for (const std::string& c : channels) {
        if (std::find(sel.begin(), sel.end(), c) != sel.end()) continue;
        if (std::find(impl_->available.begin(), impl_->available.end(), c) ==
            impl_->available.end()) {
            err = fmt::format("{}: part 'records' has no channel '{}'", impl_->path, c);
            return false;
        }
        sel.push_back(c);
    }
    impl_->selected = std::move(sel);
    return true;
}

bool SampleRecordsReader::read(int y0, int rows, SampleBlock& block, std::string& err) {
    const StatsHeader& h = impl_->header;
    if (y0 < 0 || rows < 1 || y0 + rows > h.height) {
        err = fmt::format("{}: rows {}..{} outside the image", impl_->path, y0, y0 + rows - 1);
        return false;
    }
    try {
        block.clear(y0, rows, h.width);
        block.channels = impl_->selected;
        const size_t recordBytes = block.stride() * sizeof(float);
        Imf::DeepScanLineInputPart ip(*impl_->file, impl_->part);
        RecordPointers rp(h, block);
        ip.setFrameBuffer(rp.fb());
        ip.readPixelSampleCounts(h.originY + y0, h.originY + y0 + rows - 1);
        // The counts come from the file's own chunks; bound them before allocating.
        uint64_t total = 0;
        for (size_t p = 0; p < block.counts.size(); ++p) {
            if (block.counts[p] > uint32_t(kMaxExactCount)) {
                err = fmt::format("{}: pixel ({}, {}): {} records, more than 2^24", impl_->path,
                                  p % size_t(h.width), y0 + int(p / size_t(h.width)),
                                  block.counts[p]);
                return false;
            }
            total += block.counts[p];
        }
        if (total * recordBytes > uint64_t(impl_->limits.maxBytes) ||
            total > uint64_t(impl_->limits.maxDeepSamples)) {
            err = fmt::format(
                "{}: rows {}..{} hold {} records ({} bytes), exceeding the limit of "
                "{} bytes",
                impl_->path, y0, y0 + rows - 1, total, total * recordBytes, impl_->limits.maxBytes);
            return false;
        }
        block.samples.assign(size_t(total) * block.stride(), 0.f);
        rp.point(block);
        ip.readPixels(h.originY + y0, h.originY + y0 + rows - 1);
    } catch (const std::bad_alloc&) {
        err = impl_->path + ": out of memory while reading records";
        return false;
    } catch (const std::exception& e) {
        err = fmt::format("{}: truncated or corrupt ({})", impl_->path, libraryMessage(e.what()));
        return false;
    }
    return true;
}

// ---- state parts with an owner: an operation's per-pixel state ---------------------------------

namespace {

/// The flat part's frame buffer over pixel-interleaved floats and words.
Imf::FrameBuffer stateFrameBuffer(const PixelStateParts& s, const Imath::Box2i& window) {
    const size_t width = size_t(window.max.x - window.min.x + 1);
    const size_t nf = s.floatChannels.size(), nu = s.uintChannels.size();
    Imf::FrameBuffer fb;
    auto* fl = const_cast<float*>(s.floats.data());
    auto* words = const_cast<uint32_t*>(s.words.data());
    for (size_t c = 0; c < nf; ++c)
        fb.insert(s.floatChannels[c],
                  Imf::Slice::Make(Imf::FLOAT, fl + c, window, nf * sizeof(float),
                                   nf * sizeof(float) * width));
    for (size_t c = 0; c < nu; ++c)
        fb.insert(s.uintChannels[c],
                  Imf::Slice::Make(Imf::UINT, words + c, window, nu * sizeof(uint32_t),
                                   nu * sizeof(uint32_t) * width));
    return fb;
}

/// The deep part's frame buffer: the counts of `s.recordCounts` and one channel per record
/// channel (deep_frame_buffer.h: set it, read the counts, allocate, then pointRecords()).
std::unique_ptr<DeepFrameBufferSet> stateDeepFrameBuffer(const StatsHeader& h,
                                                         const PixelStateParts& s) {
    auto set =
        std::make_unique<DeepFrameBufferSet>(h, const_cast<uint32_t*>(s.recordCounts.data()));
    const size_t nc = s.recordChannels.size();
    for (const std::string& c : s.recordChannels)
        set->addChannel(c, s.recordCounts.size(), nc * sizeof(float));
    return set;
}

/// Points every pixel's channels at its first record in `s.records` (every pixel's records
/// contiguous, in scanline order, as `s.recordCounts` says).
void pointRecords(const PixelStateParts& s, DeepFrameBufferSet& set) {
    if (s.records.empty()) return;  // no records: the pointers stay null
    set.pointContiguous(s.records.data(), s.recordCounts.data(), s.recordCounts.size(),
                        s.recordChannels.size());
}

}  // namespace

namespace detail {

bool checkExtras(const std::string& path, const StatsImage& img, const StatsExtras& extras,
                 std::string& err) {
    const StatsHeader& h = img.header;
    const bool any = extras.state != nullptr || !extras.recordsFile.empty();
    if (any && h.formatVersion < kStatsFormatVersionSamples) {
        err = fmt::format(
            "{}: state parts and records need format version {} (header "
            "says {})",
            path, kStatsFormatVersionSamples, h.formatVersion);
        return false;
    }
    if (extras.state != nullptr) {
        const PixelStateParts& s = *extras.state;
        const StateOwner& o = s.owner;
        std::map<std::string, std::string> kv;
        std::string problem;
        if (o.operation.empty() || o.operation.size() > layout::kMaxStateOwner ||
            !layout::validStatePartName(o.flatPart) || !layout::validStatePartName(o.deepPart) ||
            o.flatPart == o.deepPart || o.params.size() > layout::kMaxStateParams ||
            !parseParamText(o.params, kv, problem)) {
            err = path + ": state parts '" + printable(o.flatPart) + "', '" +
                  printable(o.deepPart) + "' of '" + printable(o.operation) +
                  "': not an owner, part names and parameter text the format stores";
            return false;
        }
        const size_t pixels = img.pixelCount();
        const uint64_t total =
            std::accumulate(s.recordCounts.begin(), s.recordCounts.end(), uint64_t(0));
        if (s.floats.size() != pixels * s.floatChannels.size() ||
            s.words.size() != pixels * s.uintChannels.size() || s.recordCounts.size() != pixels ||
            s.records.size() != total * s.recordChannels.size()) {
            err = path + ": the per-pixel state (parts " + printable(o.flatPart) + ", " +
                  printable(o.deepPart) + ") does not match the image size";
            return false;
        }
    }
    return true;
}

void appendExtraHeaders(std::vector<Imf::Header>& headers, const StatsHeader& h,
                        const StatsExtras& extras) {
    if (extras.state != nullptr) {
        const PixelStateParts& s = *extras.state;
        Imf::Header flat = commonHeader(h, s.owner.flatPart, false);
        for (const std::string& c : s.floatChannels)
            flat.channels().insert(c, Imf::Channel(Imf::FLOAT));
        for (const std::string& c : s.uintChannels)
            flat.channels().insert(c, Imf::Channel(Imf::UINT));
        flat.insert(layout::kAttrStateOwner, Imf::StringAttribute(s.owner.operation));
        flat.insert(layout::kAttrStateParams, Imf::StringAttribute(s.owner.params));
        headers.push_back(std::move(flat));
        Imf::Header deep = commonHeader(h, s.owner.deepPart, true);
        for (const std::string& c : s.recordChannels)
            deep.channels().insert(c, Imf::Channel(Imf::FLOAT));
        deep.insert(layout::kAttrStateOwner, Imf::StringAttribute(s.owner.operation));
        deep.insert(layout::kAttrStateParams, Imf::StringAttribute(s.owner.params));
        headers.push_back(std::move(deep));
    }
    if (!extras.recordsFile.empty()) {
        // The records part takes the temporary file's channels and field list as they are.
        Imf::DeepScanLineInputFile in(extras.recordsFile.c_str());
        std::vector<std::string> channels;
        for (auto it = in.header().channels().begin(); it != in.header().channels().end(); ++it)
            if (std::string(it.name()) != "A") channels.emplace_back(it.name());
        const auto* f =
            in.header().findTypedAttribute<Imf::StringAttribute>(layout::kAttrRecordFields);
        headers.push_back(
            recordsHeader(h, channels, f != nullptr ? f->value() : std::string(kRecordFieldsBase)));
    }
}

void writeExtraParts(Imf::MultiPartOutputFile& out, const StatsImage& img,
                     const StatsExtras& extras) {
    const StatsHeader& h = img.header;
    int part = layout::firstExtraPart(h);  // after the four parts and part aovs
    if (extras.state != nullptr) {
        const PixelStateParts& s = *extras.state;
        Imf::OutputPart op(out, part++);
        op.setFrameBuffer(stateFrameBuffer(s, windowOf(h)));
        op.writePixels(h.height);
        const auto set = stateDeepFrameBuffer(h, s);
        pointRecords(s, *set);
        Imf::DeepScanLineOutputPart dp(out, part++);
        dp.setFrameBuffer(set->frameBuffer());
        dp.writePixels(h.height);
    }
    if (!extras.recordsFile.empty()) {
        // Chunks move as they are: no decoding, no memory growing with the image.
        Imf::DeepScanLineInputFile in(extras.recordsFile.c_str());
        Imf::DeepScanLineOutputPart op(out, part++);
        op.copyPixels(in);
    }
}

size_t extraPixelBytes(const StatsExtras& extras) {
    if (extras.state == nullptr) return 0;
    return sizeof(float) *
           std::max(extras.state->floatChannels.size(), extras.state->uintChannels.size());
}

void appendExtraRows(std::vector<PartRows>& rows, const StatsImage& img,
                     const StatsExtras& extras) {
    const size_t width = size_t(img.header.width);
    if (extras.state != nullptr) {
        const PixelStateParts& s = *extras.state;
        // The flat state part: pixel-interleaved floats and words (the writer only reads them).
        PartRows flat;
        const size_t nf = s.floatChannels.size(), nu = s.uintChannels.size();
        auto* fl = const_cast<char*>(reinterpret_cast<const char*>(s.floats.data()));
        auto* words = const_cast<char*>(reinterpret_cast<const char*>(s.words.data()));
        for (size_t c = 0; c < nf; ++c)
            flat.slices.push_back({s.floatChannels[c], fl + c * sizeof(float), nf * sizeof(float),
                                   nf * sizeof(float) * width});
        for (size_t c = 0; c < nu; ++c)
            flat.slices.push_back({s.uintChannels[c], words + c * sizeof(uint32_t),
                                   nu * sizeof(uint32_t), nu * sizeof(uint32_t) * width});
        rows.push_back(std::move(flat));
        // The deep state part: every pixel's records contiguous, in scanline order.
        PartRows deep;
        const size_t nc = s.recordChannels.size();
        deep.counts = s.recordCounts.data();
        for (size_t c = 0; c < nc; ++c)  // no records: nothing is read through the pointer
            deep.deep.push_back(
                {s.recordChannels[c],
                 s.records.empty() ? nullptr : reinterpret_cast<const char*>(s.records.data() + c),
                 nc * sizeof(float), false});
        rows.push_back(std::move(deep));
    }
    if (!extras.recordsFile.empty()) {
        // Chunks move as they are: no decoding, no memory growing with the image.
        PartRows records;
        records.copyFrom = extras.recordsFile;
        rows.push_back(std::move(records));
    }
}

}  // namespace detail

bool readPixelStateParts(const std::string& path, PixelStateParts& out, std::string& err,
                         const ReadLimits& limits, StatsHeader* header) {
    StatsHeader h;
    if (!readStatsHeader(path, h, err, limits)) return false;
    if (header) *header = h;
    if (!h.hasState()) {
        err = path + ": holds no operation's state parts";
        return false;
    }
    try {
        Imf::MultiPartInputFile in(path.c_str());
        const int flatPart = layout::firstExtraPart(h), deepPart = flatPart + 1;
        const Imf::Header& fh = in.header(flatPart);
        PixelStateParts r;
        r.owner = h.state;  // owner, parameters and names, checked with the headers
        for (auto it = fh.channels().begin(); it != fh.channels().end(); ++it) {
            if (it.channel().type == Imf::FLOAT) r.floatChannels.emplace_back(it.name());
            if (it.channel().type == Imf::UINT) r.uintChannels.emplace_back(it.name());
        }
        const size_t pixels = size_t(h.width) * size_t(h.height);
        const Imath::Box2i window = windowOf(h);
        const uint64_t flatBytes =
            uint64_t(pixels) * (r.floatChannels.size() + r.uintChannels.size()) * 4;
        if (flatBytes > uint64_t(limits.maxBytes))
            throw std::runtime_error(fmt::format("part '{}' holds {} channels, beyond the limits",
                                                 printable(h.state.flatPart),
                                                 r.floatChannels.size() + r.uintChannels.size()));
        r.floats.resize(pixels * r.floatChannels.size());
        r.words.resize(pixels * r.uintChannels.size());
        {
            Imf::InputPart ip(in, flatPart);
            ip.setFrameBuffer(stateFrameBuffer(r, window));
            ip.readPixels(window.min.y, window.max.y);
        }
        Imf::DeepScanLineInputPart dp(in, deepPart);
        for (auto it = dp.header().channels().begin(); it != dp.header().channels().end(); ++it)
            if (it.channel().type == Imf::FLOAT) r.recordChannels.emplace_back(it.name());
        r.recordCounts.assign(pixels, 0);
        const auto set = stateDeepFrameBuffer(h, r);
        dp.setFrameBuffer(set->frameBuffer());
        dp.readPixelSampleCounts(window.min.y, window.max.y);  // the counts first, then room
        const uint64_t total =
            std::accumulate(r.recordCounts.begin(), r.recordCounts.end(), uint64_t(0));
        if (total > uint64_t(limits.maxDeepSamples) ||
            total * std::max<size_t>(r.recordChannels.size(), 1) * sizeof(float) >
                uint64_t(limits.maxBytes))
            throw std::runtime_error(fmt::format("part '{}' holds {} records, beyond the limits",
                                                 printable(h.state.deepPart), total));
        r.records.resize(total * r.recordChannels.size());
        pointRecords(r, *set);
        dp.readPixels(window.min.y, window.max.y);
        out = std::move(r);
    } catch (const std::bad_alloc&) {
        err = path + ": out of memory while reading the state parts";
        return false;
    } catch (const std::exception& e) {
        err = fmt::format("{}: {}", path, libraryMessage(e.what()));
        return false;
    }
    return true;
}

namespace {

class FileSampleSource : public SampleSource {
  public:
    FileSampleSource(std::string path, const ReadLimits& limits, int nthreads)
        : path_(std::move(path)), limits_(limits), nthreads_(nthreads) {}
    bool open(std::string& err) {
        if (!readStatsHeader(path_, header_, err, limits_)) return false;
        if (header_.hasRecords && !records_.open(path_, err, limits_, nthreads_)) return false;
        return true;
    }
    const StatsHeader& header() const override { return header_; }
    const std::string& path() const override { return path_; }
    std::vector<std::string> recordChannels() const override {
        return header_.hasRecords ? records_.available() : std::vector<std::string>();
    }
    bool selectRecordChannels(const std::vector<std::string>& channels, std::string& err) override {
        if (!header_.hasRecords) return readRecords(0, 1, scratch_, err);
        return records_.select(channels, err);
    }
    bool readRecords(int y0, int rows, SampleBlock& block, std::string& err) override {
        if (!header_.hasRecords) {
            err = path_ +
                  ": no per-sample records (part 'records'); render with mcstat-render "
                  "--keep-samples";
            return false;
        }
        return records_.read(y0, rows, block, err);
    }
    bool readPixelState(PixelStateParts& out, std::string& err) override {
        return readPixelStateParts(path_, out, err, limits_);
    }

  private:
    std::string path_;
    ReadLimits limits_;
    int nthreads_;
    StatsHeader header_;
    SampleRecordsReader records_;
    SampleBlock scratch_;
};

}  // namespace

std::unique_ptr<SampleSource> openSampleSource(const std::string& path, std::string& err,
                                               const ReadLimits& limits, int nthreads) {
    auto src = std::make_unique<FileSampleSource>(path, limits, nthreads);
    if (!src->open(err)) return nullptr;
    return src;
}

}  // namespace mcstat
