// StatsFileReader, readStatsFile, readStatsHeader: header validation first (stats_header_check),
// then blocks of rows of the parts asked for are decoded straight into a StatsImage's arrays, then
// each block is validated. readStatsFile is one block of every row and part. The flat parts go
// through OpenEXR's Core API with libdeflate for ZIP, a block's chunks in parallel
// (flat_part_reader.h); the deep part likewise (deep_part_reader.h) when its chunks are one line
// of NONE or ZIPS, else, and the optional parts, through the C++ API.
// Adaptive M (format 2): the block's deep sample counts are read and checked first, then the block
// is sized for them, then the deep samples are read through per-pixel pointers.
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepScanLineInputPart.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputPart.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfPartType.h>
#include <errno.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <memory>
#include <new>
#include <stdexcept>
#include <vector>

#include "deep_frame_buffer.h"
#include "mcstat/exr-deep/codec/detail/deep_part_reader.h"
#include "mcstat/exr-deep/codec/detail/exr_headers.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/detail/flat_part_reader.h"
#include "mcstat/exr-deep/stats_file.h"
#include "stats_header_check.h"
#include "stats_layout.h"
#include "window.h"

namespace mcstat {

namespace {

/// Opens `path` for reading and checks its headers. On success `fd` is open and `size` set.
bool openRegular(const std::string& path, detail::Fd& fd, uint64_t& size, std::string& err) {
    fd = detail::Fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    if (fd.get() < 0) {
        err = fmt::format("{}: cannot open ({})", path, std::strerror(errno));
        return false;
    }
    struct stat st {};
    if (::fstat(fd.get(), &st) != 0) {
        err = fmt::format("{}: cannot stat ({})", path, std::strerror(errno));
        return false;
    }
    if (!S_ISREG(st.st_mode)) {
        err = path + ": not a regular file";
        return false;
    }
    size = uint64_t(st.st_size);
    return true;
}

bool openAndCheck(const std::string& path, const ReadLimits& limits, detail::Fd& fd, uint64_t& size,
                  StatsHeader& hdr, std::string& err) {
    return openRegular(path, fd, size, err) &&
           detail::checkStatsHeaders(fd.get(), size, path, limits, hdr, err);
}

using detail::DeepFrameBufferSet;
using detail::windowBase;
using detail::windowOf;

/// Checks that the file opened by the C++ API is the file the header check saw.
void checkSameFile(const Imf::MultiPartInputFile& in, const StatsHeader& h) {
    // Same open file as the header check; guard anyway against it changing under us.
    const int expected =
        layout::firstExtraPart(h) + (h.hasState() ? 2 : 0) + (h.hasRecords ? 1 : 0);
    if (in.parts() != expected) throw std::runtime_error("file changed while reading");
    if (layout::hasAovPart(h)) {
        const Imf::Header& ph = in.header(layout::kAovs);
        if (ph.dataWindow() != windowOf(h) || !ph.hasName() || ph.name() != layout::kPartAovs ||
            ph.type() != Imf::SCANLINEIMAGE)
            throw std::runtime_error("file changed while reading");
    }
    const char* const* names = layout::partNames(h.adaptiveM);
    for (int part = 0; part < layout::kPartCount; ++part) {
        const Imf::Header& ph = in.header(part);
        const bool deep = h.adaptiveM && part == layout::kBuffers;
        if (ph.dataWindow() != windowOf(h) || !ph.hasName() || ph.name() != names[part] ||
            ph.type() != (deep ? Imf::DEEPSCANLINE : Imf::SCANLINEIMAGE))
            throw std::runtime_error("file changed while reading");
    }
}

/// Rows of one compressed chunk for `c` (OpenEXR's per-compression line buffers).
int linesPerChunk(Imf::Compression c) {
    switch (c) {
        case Imf::NO_COMPRESSION:
        case Imf::RLE_COMPRESSION:
        case Imf::ZIPS_COMPRESSION:
            return 1;
        case Imf::ZIP_COMPRESSION:
        case Imf::PXR24_COMPRESSION:
            return 16;
        case Imf::PIZ_COMPRESSION:
        case Imf::B44_COMPRESSION:
        case Imf::B44A_COMPRESSION:
        case Imf::DWAA_COMPRESSION:
            return 32;
        case Imf::DWAB_COMPRESSION:
            return 256;
        default:
            return 16;
    }
}

/// A Core reader's failure as the exception StatsFileReader::read reports (out of memory, or
/// "truncated or corrupt" with the reader's problem).
void throwOnFailure(detail::FlatPartReader::Result r, const std::string& problem) {
    if (r == detail::FlatPartReader::Result::OutOfMemory) throw std::bad_alloc();
    if (r == detail::FlatPartReader::Result::Corrupt) throw std::runtime_error(problem);
}

/// Reads the flat parts of `parts` (StatsParts) into `blk`, whose header is the block's (origin
/// at its first row) and whose arrays are sized, rows `firstRow`.. of the file (0-based): through
/// OpenEXR's Core API with libdeflate and the chunks on `threads` threads (flat_part_reader.h),
/// or, for a part it does not take (B44, B44A, DWAA, DWAB), through the C++ API. Throws on failure.
void readFlatParts(Imf::MultiPartInputFile& in, detail::FlatPartReader& flat, int firstRow,
                   int threads, unsigned parts, StatsImage& blk) {
    const StatsHeader& h = blk.header;
    std::vector<detail::PartSlices> core;
    for (int part = 0; part < layout::kPartBits; ++part) {
        if (!(parts & (1u << part)) || (h.adaptiveM && part == layout::kBuffers)) continue;
        // No part aovs (no AOVs, or they are in the deep part): nothing to read.
        if (part == layout::kAovs && !layout::hasAovPart(h)) continue;
        const std::vector<layout::ChannelPlace> channels =
            part == layout::kAovs
                ? layout::aovChannels(h)
                : layout::partChannels(part, h.M, h.adaptiveM, layout::momentsOf(h));
        if (flat.handles(part)) {
            detail::PartSlices req;
            req.part = part;
            req.slices.reserve(channels.size());
            for (const layout::ChannelPlace& c : channels) {
                float* data = layout::arrayOf(blk, c.array).data() + c.offset;
                const size_t xStride = c.stride * sizeof(float);
                req.slices.push_back(
                    {c.name, reinterpret_cast<char*>(data), xStride, xStride * size_t(h.width)});
            }
            core.push_back(std::move(req));
            continue;
        }
        Imf::FrameBuffer fb;
        for (const layout::ChannelPlace& c : channels) {
            float* data = layout::arrayOf(blk, c.array).data() + c.offset;
            const size_t xStride = c.stride * sizeof(float);
            fb.insert(c.name, Imf::Slice(Imf::FLOAT, windowBase(data, h, xStride), xStride,
                                         xStride * size_t(h.width)));
        }
        Imf::InputPart ip(in, part);
        ip.setFrameBuffer(fb);
        ip.readPixels(h.originY, h.originY + h.height - 1);
    }
    if (core.empty()) return;
    std::string problem;
    throwOnFailure(flat.read(core, firstRow, h.height, threads, problem), problem);
}

/// Adaptive M: reads the per-pixel sample counts of the block's rows (from `firstRow`) of part
/// "vbuffers", through `deep` when it takes the part, else the C++ API, and checks them (1..M each,
/// total within the limits). False with `err` on a bad file; throws on read errors.
bool readDeepCounts(Imf::MultiPartInputFile& in, detail::DeepPartReader& deep, int firstRow,
                    int threads, const std::string& path, const ReadLimits& limits,
                    const StatsHeader& h, std::vector<uint32_t>& m, std::string& err) {
    const size_t pixels = size_t(h.width) * size_t(h.height);
    if (deep.handles()) {
        std::string problem;
        throwOnFailure(deep.readCounts(firstRow, h.height, threads, m, problem), problem);
    } else {
        m.assign(pixels, 0);
        Imf::DeepScanLineInputPart dp(in, layout::kBuffers);
        DeepFrameBufferSet fb(h, m.data());
        dp.setFrameBuffer(fb.frameBuffer());
        dp.readPixelSampleCounts(h.originY, h.originY + h.height - 1);
    }
    uint64_t total = 0;
    for (size_t p = 0; p < pixels; ++p) {
        if (m[p] < 1 || m[p] > uint32_t(h.M)) {
            err = fmt::format(
                "{}: pixel ({}, {}): part '{}' holds {} sub-buffers, outside 1..{} "
                "({})",
                path, h.originX + int64_t(p % size_t(h.width)),
                h.originY + int64_t(p / size_t(h.width)),
                layout::kPartNamesAdaptive[layout::kBuffers], m[p], h.M, layout::kAttrM);
            return false;
        }
        if (h.compact && m[p] != 1 && m[p] != uint32_t(h.M)) {
            err = fmt::format(
                "{}: pixel ({}, {}): part '{}' holds {} sub-buffers in a compact file (1 or {} = "
                "{})",
                path, h.originX + int64_t(p % size_t(h.width)),
                h.originY + int64_t(p / size_t(h.width)),
                layout::kPartNamesAdaptive[layout::kBuffers], m[p], layout::kAttrM, h.M);
            return false;
        }
        total += m[p];
    }
    const double bytes = double(layout::floatsPerPixel(0, 0, layout::momentsOf(h)) * sizeof(float) +
                                sizeof(uint64_t)) *
                             double(pixels) +
                         double(total) * double(4 + h.aovs.size()) * sizeof(float);
    if (int64_t(total) > limits.maxDeepSamples || bytes > double(limits.maxBytes)) {
        err = fmt::format(
            "{}: part '{}' holds {} sub-buffers ({} bytes in memory), exceeding the limit of {} "
            "deep samples or {} bytes",
            path, layout::kPartNamesAdaptive[layout::kBuffers], total, bytes, limits.maxDeepSamples,
            limits.maxBytes);
        return false;
    }
    return true;
}

/// Adaptive M: reads the buffer means and counts of the block's rows of part "vbuffers" into
/// `blk` (sized for `counts`, what readDeepCounts returned), and its AOV channels when `aovs`; Z
/// and A are not read. Through `deep` when it takes the part, else the C++ API. Throws on read
/// errors.
void readDeepBuffers(Imf::MultiPartInputFile& in, detail::DeepPartReader& deep, int firstRow,
                     int threads, const std::vector<uint32_t>& counts, StatsImage& blk, bool aovs) {
    const StatsHeader& h = blk.header;
    const size_t pixels = blk.pixelCount();
    const size_t A = aovs ? h.aovs.size() : 0;
    if (deep.handles()) {
        std::vector<detail::DeepSlice> slices;
        for (size_t c = 0; c < 3; ++c)
            slices.push_back({layout::kDeepChannels[c], blk.bufferMean.data() + c, 3});
        slices.push_back({layout::kDeepChannels[3], blk.bufferCount.data(), 1});
        for (size_t a = 0; a < A; ++a)
            slices.push_back({layout::aovDeepChannel(h.aovs[a].name), blk.aov.data() + a, A});
        std::string problem;
        throwOnFailure(deep.readSamples(firstRow, h.height, counts, slices, threads, problem),
                       problem);
        return;
    }
    std::vector<uint32_t> m(pixels);
    DeepFrameBufferSet fb(h, m.data());
    for (size_t c = 0; c < 4; ++c)
        fb.addChannel(layout::kDeepChannels[c], pixels, c < 3 ? 3 * sizeof(float) : sizeof(float));
    for (size_t a = 0; a < A; ++a)
        fb.addChannel(layout::aovDeepChannel(h.aovs[a].name), pixels, A * sizeof(float));
    for (size_t p = 0; p < pixels; ++p) {
        const size_t k = blk.bufferBegin(p);
        for (size_t c = 0; c < 3; ++c) fb.point(c, p, blk.bufferMean.data() + k * 3 + c);
        fb.point(3, p, blk.bufferCount.data() + k);
        for (size_t a = 0; a < A; ++a) fb.point(4 + a, p, blk.aov.data() + k * A + a);
    }
    Imf::DeepScanLineInputPart dp(in, layout::kBuffers);
    dp.setFrameBuffer(fb.frameBuffer());
    dp.readPixelSampleCounts(h.originY, h.originY + h.height - 1);
    for (size_t p = 0; p < pixels; ++p)
        if (m[p] != uint32_t(blk.buffersOf(p)))
            throw std::runtime_error("file changed while reading");
    dp.readPixels(h.originY, h.originY + h.height - 1);
}

/// Version 8 (compactMeansInBeauty): the mean of each pixel with one buffer from part beauty into
/// its buffer, whose deep sample must hold R = G = B = 0 (+0, as the writer stores them). False
/// with `err` naming the first pixel where it does not.
bool meansFromBeauty(StatsImage& blk, const std::string& path, std::string& err) {
    const StatsHeader& h = blk.header;
    for (size_t p = 0; p < blk.pixelCount(); ++p) {
        if (blk.buffersOf(p) != 1) continue;
        float* m = blk.bufferMean.data() + 3 * blk.bufferBegin(p);
        static constexpr float kZero[3] = {0.f, 0.f, 0.f};
        if (std::memcmp(m, kZero, sizeof kZero) != 0) {
            err = fmt::format(
                "{}: pixel ({}, {}): part '{}' holds a mean ({}, {}, {}) for a pixel with one "
                "buffer, which a compact file of format {} keeps in part '{}' (0 here)",
                path, h.originX + int64_t(p % size_t(h.width)),
                h.originY + int64_t(p / size_t(h.width)),
                layout::kPartNamesAdaptive[layout::kBuffers], m[0], m[1], m[2], h.formatVersion,
                layout::kPartNames[layout::kBeauty]);
            return false;
        }
        std::memcpy(m, blk.beauty.data() + 3 * p, sizeof kZero);
    }
    return true;
}

}  // namespace

bool readStatsHeader(const std::string& path, StatsHeader& hdr, std::string& err,
                     const ReadLimits& limits) {
    try {
        detail::Fd fd;
        uint64_t size = 0;
        StatsHeader h;
        if (!openAndCheck(path, limits, fd, size, h, err)) return false;
        hdr = std::move(h);
        return true;
    } catch (const std::exception& e) {
        err = fmt::format("{}: {}", path, libraryMessage(e.what()));
    } catch (...) {
        err = path + ": unknown error while reading the headers";
    }
    return false;
}

struct StatsFileReader::Impl {
    std::string path;
    ReadLimits limits;
    detail::Fd fd;
    uint64_t size = 0;
    StatsHeader header;
    std::unique_ptr<detail::FdIStream> stream;
    std::unique_ptr<Imf::MultiPartInputFile> file;
    detail::FlatPartReader flat;  // the flat parts, through the Core API and libdeflate
    detail::DeepPartReader deep;  // adaptive M: part vbuffers, likewise
    int chunkRows = 1;
    int threads = 1;                   // decoding threads (codecThreads)
    std::vector<uint32_t> deepCounts;  // adaptive M: the block's m_p, reused
};

StatsFileReader::StatsFileReader() = default;
StatsFileReader::~StatsFileReader() = default;

bool StatsFileReader::isOpen() const { return impl_ && impl_->file; }
const std::string& StatsFileReader::path() const {
    static const std::string none;
    return impl_ ? impl_->path : none;
}
const StatsHeader& StatsFileReader::header() const {
    static const StatsHeader none;
    return impl_ ? impl_->header : none;
}
int StatsFileReader::chunkRows() const { return impl_ ? impl_->chunkRows : 1; }
int StatsFileReader::decodeThreads() const { return impl_ ? impl_->threads : 1; }

bool StatsFileReader::open(const std::string& path, std::string& err, const ReadLimits& limits,
                           int nthreads) {
    impl_.reset();
    try {
        auto impl = std::make_unique<Impl>();
        impl->path = path;
        impl->limits = limits;
        if (!openAndCheck(path, limits, impl->fd, impl->size, impl->header, err)) return false;
        const int threads = detail::codecThreads(nthreads);
        impl->stream = std::make_unique<detail::FdIStream>(impl->fd.get(), path, impl->size);
        impl->file = std::make_unique<Imf::MultiPartInputFile>(*impl->stream, threads);
        checkSameFile(*impl->file, impl->header);
        const StatsHeader& h = impl->header;
        std::string problem;
        if (!impl->flat.open(impl->fd.get(), impl->size, path, h.originX, h.originY, h.width,
                             h.height, problem)) {
            err = fmt::format("{}: truncated or corrupt ({})", path, problem);
            return false;
        }
        if (h.adaptiveM && !impl->deep.open(impl->flat, layout::kBuffers, problem)) {
            err = fmt::format("{}: truncated or corrupt ({})", path, problem);
            return false;
        }
        impl->chunkRows = linesPerChunk(impl->file->header(layout::kBuffers).compression());
        impl->threads = threads;
        impl_ = std::move(impl);
        return true;
    } catch (const std::bad_alloc&) {
        err = path + ": out of memory while reading the headers";
    } catch (const std::exception& e) {
        err = fmt::format("{}: truncated or corrupt ({})", path, libraryMessage(e.what()));
    }
    return false;
}

bool StatsFileReader::read(int firstRow, int rows, unsigned parts, StatsImage& block,
                           std::string& err) {
    if (!isOpen()) {
        err = "statistics file reader: read before a successful open";
        return false;
    }
    Impl& im = *impl_;
    const StatsHeader& fh = im.header;
    if (rows < 1 || firstRow < 0 || firstRow > fh.height - rows || (parts & ~kStatsAllParts)) {
        err = fmt::format("{}: cannot read rows {}..{} of parts {:#x} (the image has {} rows)",
                          im.path, firstRow, int64_t(firstRow) + rows - 1, parts, fh.height);
        return false;
    }
    parts = detail::partsToRead(fh, parts);
    try {
        block.header = fh;
        block.header.height = rows;
        block.header.originY = fh.originY + firstRow;
        const StatsHeader& h = block.header;
        const size_t pixels = size_t(h.width) * size_t(rows);
        // The byte limit applies to what this read holds (ReadLimits::maxBytes): a whole read
        // (rows = height) to the image, a streamed one to its block, so a file streamed a block
        // at a time is not refused for its whole size. Adaptive M: checked on the counts below.
        if (!h.adaptiveM) {
            const double bytes =
                double(pixels) * double(layout::floatsPerPixel(h.M, h.aovs.size()) * sizeof(float));
            if (bytes > double(im.limits.maxBytes)) {
                err = fmt::format(
                    "{}: rows {}..{} ({}x{} with M = {}{}) need {} bytes, exceeding "
                    "the limit of {} bytes",
                    im.path, firstRow, int64_t(firstRow) + rows - 1, h.width, rows, h.M,
                    h.aovs.empty() ? std::string() : fmt::format(" and {} AOVs", h.aovs.size()),
                    bytes, im.limits.maxBytes);
                return false;
            }
        }
        std::vector<uint64_t> offsets;
        size_t buffers = 0;
        if (parts & kStatsPartBuffers) {
            if (h.adaptiveM) {
                if (!readDeepCounts(*im.file, im.deep, firstRow, im.threads, im.path, im.limits, h,
                                    im.deepCounts, err))
                    return false;
                offsets.resize(pixels + 1);
                for (size_t p = 0; p < pixels; ++p) {
                    offsets[p] = buffers;
                    buffers += im.deepCounts[p];
                }
                offsets[pixels] = buffers;
            } else {
                buffers = pixels * size_t(h.M);
            }
        }
        std::string allocErr;
        if (!detail::resizeParts(block, parts, buffers, std::move(offsets), allocErr)) {
            err = im.path + ": " + allocErr;
            return false;
        }
        if (h.adaptiveM && (parts & kStatsPartBuffers))
            readDeepBuffers(*im.file, im.deep, firstRow, im.threads, im.deepCounts, block,
                            (parts & kStatsPartAovs) != 0);
        readFlatParts(*im.file, im.flat, firstRow, im.threads, parts, block);
        if (compactMeansInBeauty(h) && (parts & kStatsPartBuffers) &&
            !meansFromBeauty(block, im.path, err))
            return false;
    } catch (const std::bad_alloc&) {
        err = im.path + ": out of memory while reading pixels";
        return false;
    } catch (const std::exception& e) {
        err = fmt::format("{}: truncated or corrupt ({})", im.path, libraryMessage(e.what()));
        return false;
    }
    return validateStats(block, parts, im.path, err);
}

bool readStatsFile(const std::string& path, StatsImage& img, std::string& err,
                   const ReadLimits& limits) {
    StatsFileReader reader;
    if (!reader.open(path, err, limits)) return false;
    StatsImage t;
    if (!reader.read(0, reader.header().height, kStatsAllParts, t, err)) return false;
    img = std::move(t);
    return true;
}

bool checkExrAttributeSizes(const std::string& path, std::string& err, int64_t maxPixels) {
    detail::Fd fd;
    uint64_t size = 0;
    return openRegular(path, fd, size, err) &&
           detail::checkExrAttributeSizes(fd.get(), size, path, err, maxPixels);
}

std::string FileContent::partsText() const {
    if (partNames.size() == 1)
        return partNames[0].empty() ? "one unnamed part"
                                    : fmt::format("part '{}'", printable(partNames[0]));
    std::string list;
    for (size_t i = 0; i < partNames.size() && i < 8; ++i)
        list += fmt::format("{}'{}'", i ? ", " : "", printable(partNames[i], 40));
    if (partNames.size() > 8) list += ", ...";
    return fmt::format("parts {}", list);
}

bool probeFileContent(const std::string& path, FileContent& out, std::string& err) {
    out = FileContent();
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) {
        if (errno == ENOENT || errno == ENOTDIR) return true;  // Missing
        err = fmt::format("{}: cannot stat ({})", path, std::strerror(errno));
        return false;
    }
    if (S_ISDIR(st.st_mode)) {
        out.kind = FileContent::Directory;
        return true;
    }
    if (!S_ISREG(st.st_mode)) {
        out.kind = FileContent::Special;
        return true;
    }
    detail::Fd fd;
    uint64_t size = 0;
    if (!openRegular(path, fd, size, err)) return false;
    static constexpr unsigned char kMagic[4] = {0x76, 0x2f, 0x31, 0x01};
    unsigned char magic[4] = {};
    if (size < 8 || detail::preadFull(fd.get(), magic, 4, 0) != 4 ||
        std::memcmp(magic, kMagic, 4) != 0) {
        out.kind = FileContent::NotExr;
        return true;
    }
    bool newer = false;
    std::vector<std::string> names;
    if (!detail::readExrPartNames(fd.get(), size, path, names, newer, err)) return false;
    // The sub-buffers make a statistics file; part 0 alone is an image (its mean). A file from a
    // newer mcstat is one too, so that its reader says so (checkStatsHeaders).
    const bool subBuffers = std::any_of(names.begin(), names.end(), [](const std::string& n) {
        return n == layout::kPartNames[layout::kBuffers] ||
               n == layout::kPartNamesAdaptive[layout::kBuffers];
    });
    out.kind = subBuffers || newer ? FileContent::Stats : FileContent::PlainExr;
    out.partNames = std::move(names);
    return true;
}

}  // namespace mcstat
