// writeStatsFile: validate, write the four parts (part 1 deep with adaptive M) to a temporary file
// in the target's directory, rename it onto the target. On failure the temporary file is removed
// and the target is untouched. Every part (flat, deep `vbuffers`, and writeStatsFile's version-4
// parts) is written through OpenEXR's Core API with libdeflate's ZIP (core_part_writer.h); parts
// it cannot express (CorePartWriter::supports), or every part when the environment says
// MCSTAT_EXR_WRITER=cpp, through the C++ API with zlib.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepScanLineOutputPart.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfMultiPartOutputFile.h>
#include <OpenEXR/ImfOutputPart.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfStringVectorAttribute.h>
#include <errno.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <limits>
#include <memory>

#include "deep_frame_buffer.h"
#include "extra_parts.h"
#include "mcstat/core/color_space.h"
#include "mcstat/exr-deep/codec/detail/core_part_writer.h"
#include "mcstat/exr-deep/codec/detail/exr_headers.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/temp_file.h"
#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "part_header.h"
#include "stats_header_check.h"
#include "stats_layout.h"
#include "window.h"

namespace mcstat {

namespace {

using detail::DeepFrameBufferSet;
using detail::displayWindowOf;
using detail::windowBase;
using detail::windowOf;

}  // namespace

namespace {

/// The AOV list attributes (version 5), on part `aovs` or (version 6) the deep part `vbuffers`.
void insertAovAttributes(Imf::Header& hdr, const StatsHeader& h) {
    std::vector<std::string> names, classes, parts;
    for (const AovChannel& a : h.aovs) {
        names.push_back(a.name);
        classes.emplace_back(aovClassName(a.cls));
        parts.push_back(a.part);
    }
    hdr.insert(layout::kAttrAovNames, Imf::StringVectorAttribute(names));
    hdr.insert(layout::kAttrAovClasses, Imf::StringVectorAttribute(classes));
    hdr.insert(layout::kAttrAovParts, Imf::StringVectorAttribute(parts));
}

/// Part 0, what every stock EXR tool shows, says what its RGB values are: the standard
/// `chromaticities` of the working space and (OpenEXR 3.4's attribute, written as a plain string
/// by older libraries) its `colorInteropID`. A space mcstat does not know gets neither: no label
/// is better than a wrong one.
void addColorSpace(Imf::Header& hdr, const std::string& space) {
    const WorkingSpace* ws = findWorkingSpace(space);
    if (!ws) return;
    const Chromaticities& c = ws->xy;
    Imf::addChromaticities(hdr, Imf::Chromaticities(Imath::V2f(float(c.rx), float(c.ry)),
                                                    Imath::V2f(float(c.gx), float(c.gy)),
                                                    Imath::V2f(float(c.bx), float(c.by)),
                                                    Imath::V2f(float(c.wx), float(c.wy))));
    hdr.insert(layout::kAttrColorInteropID, Imf::StringAttribute(ws->interopID));
}

std::vector<Imf::Header> makeHeaders(const StatsHeader& h) {
    std::vector<Imf::Header> headers;
    for (int part = 0; part < layout::kPartCount; ++part) {
        const bool deep = h.adaptiveM && part == layout::kBuffers;
        Imf::Header hdr = detail::commonHeader(h, layout::partNames(h.adaptiveM)[part], deep);
        if (part == layout::kBeauty) addColorSpace(hdr, h.colorSpace);
        for (const layout::ChannelPlace& c :
             layout::partChannels(part, h.M, h.adaptiveM, layout::momentsOf(h)))
            hdr.channels().insert(c.name, Imf::Channel(Imf::FLOAT));
        if (deep) {
            for (const char* name : layout::kDeepChannels)
                hdr.channels().insert(name, Imf::Channel(Imf::FLOAT));
            for (const AovChannel& a : h.aovs)
                hdr.channels().insert(layout::aovDeepChannel(a.name), Imf::Channel(Imf::FLOAT));
            if (!h.aovs.empty()) insertAovAttributes(hdr, h);
        }
        if (part == layout::kBeauty && h.formatVersion >= kStatsFormatVersionAovs)
            hdr.insert(layout::kAttrSourceMetadata, Imf::StringAttribute(h.sourceMetadata));
        headers.push_back(std::move(hdr));
    }
    if (layout::hasAovPart(h)) {  // version 5, fixed M: part aovs, M * A channels
        Imf::Header hdr = detail::commonHeader(h, layout::kPartAovs, false);
        for (const layout::ChannelPlace& c : layout::aovChannels(h))
            hdr.channels().insert(c.name, Imf::Channel(Imf::FLOAT));
        insertAovAttributes(hdr, h);
        headers.push_back(std::move(hdr));
    }
    return headers;
}

std::string dirOf(const std::string& path) {
    const size_t slash = path.rfind('/');
    if (slash == std::string::npos) return ".";
    return slash == 0 ? "/" : path.substr(0, slash);
}

/// The buffer means of `blk` as part vbuffers stores them. With compactMeansInBeauty (version 8)
/// a pixel with one buffer stores R = G = B = 0, since part beauty holds its mean (validateStats
/// checks that they are the same floats): then a copy in `zeroed`, else blk's own array.
const float* deepMeans(const StatsImage& blk, std::vector<float>& zeroed) {
    if (!compactMeansInBeauty(blk.header)) return blk.bufferMean.data();
    zeroed = blk.bufferMean;
    for (size_t p = 0; p < blk.pixelCount(); ++p)
        if (blk.buffersOf(p) == 1) std::fill_n(zeroed.data() + 3 * blk.bufferBegin(p), 3, 0.f);
    return zeroed.data();
}

/// Adaptive M: rows of part "vbuffers" from `blk` (a block of rows, origin at its first row), one
/// deep sample per sub-buffer (R, G, B, count; Z = buffer index, A = 1).
void writeDeepBuffers(Imf::MultiPartOutputFile& out, const StatsImage& blk) {
    const StatsHeader& h = blk.header;
    const size_t pixels = blk.pixelCount();
    // Z and A are the same for every pixel: j and 1 for sample j, so all pixels point at one row.
    std::vector<float> zs(size_t(h.M)), ones(size_t(h.M), 1.f);
    for (size_t j = 0; j < zs.size(); ++j) zs[j] = float(j);
    std::vector<float> zeroed;
    const float* means = deepMeans(blk, zeroed);
    std::vector<uint32_t> m(pixels);
    DeepFrameBufferSet fb(h, m.data());
    const size_t A = h.aovs.size();
    for (size_t c = 0; c < 6; ++c)
        fb.addChannel(layout::kDeepChannels[c], pixels, c < 3 ? 3 * sizeof(float) : sizeof(float));
    for (size_t a = 0; a < A; ++a)
        fb.addChannel(layout::aovDeepChannel(h.aovs[a].name), pixels, A * sizeof(float));
    for (size_t p = 0; p < pixels; ++p) {
        const size_t k = blk.bufferBegin(p);
        m[p] = uint32_t(blk.buffersOf(p));
        for (size_t c = 0; c < 3; ++c) fb.point(c, p, means + k * 3 + c);
        fb.point(3, p, blk.bufferCount.data() + k);
        fb.point(4, p, zs.data());
        fb.point(5, p, ones.data());
        for (size_t a = 0; a < A; ++a) fb.point(6 + a, p, blk.aov.data() + k * A + a);
    }
    Imf::DeepScanLineOutputPart op(out, layout::kBuffers);
    op.setFrameBuffer(fb.frameBuffer());
    op.writePixels(h.height);
}

/// Writes the rows of `blk` (a block of whole rows) to every one of the four parts and, with AOVs,
/// part aovs; throws on failure.
void writeRows(Imf::MultiPartOutputFile& out, const StatsImage& blk) {
    const StatsHeader& h = blk.header;
    const int parts = layout::firstExtraPart(h);
    for (int part = 0; part < parts; ++part) {
        if (h.adaptiveM && part == layout::kBuffers) {
            writeDeepBuffers(out, blk);
            continue;
        }
        Imf::FrameBuffer fb;
        for (const layout::ChannelPlace& c :
             part == layout::kAovs
                 ? layout::aovChannels(h)
                 : layout::partChannels(part, h.M, h.adaptiveM, layout::momentsOf(h))) {
            const float* data = layout::arrayOf(blk, c.array).data() + c.offset;
            const size_t xStride = c.stride * sizeof(float);
            fb.insert(c.name, Imf::Slice(Imf::FLOAT, windowBase(data, h, xStride), xStride,
                                         xStride * size_t(h.width)));
        }
        Imf::OutputPart op(out, part);
        op.setFrameBuffer(fb);
        op.writePixels(h.height);
    }
}

/// What the Core writer reads of a block's adaptive buffers besides the image: per pixel its
/// buffer count, and the Z of deep sample j (j) and A (1).
struct DeepBufferRows {
    std::vector<uint32_t> counts;
    std::vector<float> zs;
    float one = 1.f;
    std::vector<float> zeroedMeans;  ///< deepMeans's copy, when it makes one
};

/// The rows of every part of `blk` for the Core writer, in part order (read only; `deep` holds
/// what vbuffers needs besides `blk`).
std::vector<detail::PartRows> partRows(const StatsImage& blk, DeepBufferRows& deep) {
    const StatsHeader& h = blk.header;
    const int parts = layout::firstExtraPart(h);
    std::vector<detail::PartRows> out(static_cast<size_t>(parts));
    for (int part = 0; part < parts; ++part) {
        detail::PartRows& rows = out[size_t(part)];
        if (h.adaptiveM && part == layout::kBuffers) {
            // One deep sample per sub-buffer: R, G, B, count; Z = the buffer's index, A = 1.
            const size_t pixels = blk.pixelCount(), k0 = pixels > 0 ? blk.bufferBegin(0) : 0;
            deep.counts.resize(pixels);
            for (size_t p = 0; p < pixels; ++p) deep.counts[p] = uint32_t(blk.buffersOf(p));
            deep.zs.resize(size_t(std::max(1, h.M)));
            for (size_t j = 0; j < deep.zs.size(); ++j) deep.zs[j] = float(j);
            const auto bytes = [](const float* f) { return reinterpret_cast<const char*>(f); };
            rows.counts = deep.counts.data();
            const float* means = deepMeans(blk, deep.zeroedMeans);
            for (size_t c = 0; c < 3; ++c)
                rows.deep.push_back({layout::kDeepChannels[c], bytes(means + k0 * 3 + c),
                                     3 * sizeof(float), false});
            rows.deep.push_back({layout::kDeepChannels[3], bytes(blk.bufferCount.data() + k0),
                                 sizeof(float), false});
            rows.deep.push_back(
                {layout::kDeepChannels[4], bytes(deep.zs.data()), sizeof(float), true});
            rows.deep.push_back({layout::kDeepChannels[5], bytes(&deep.one), 0, true});
            // Version 6: the AOVs, A values per deep sample.
            const size_t A = h.aovs.size();
            for (size_t a = 0; a < A; ++a) {
                rows.deep.push_back({layout::aovDeepChannel(h.aovs[a].name),
                                     bytes(blk.aov.data() + k0 * A + a), A * sizeof(float), false});
            }
            continue;
        }
        for (const layout::ChannelPlace& c :
             part == layout::kAovs
                 ? layout::aovChannels(h)
                 : layout::partChannels(part, h.M, h.adaptiveM, layout::momentsOf(h))) {
            const float* data = layout::arrayOf(blk, c.array).data() + c.offset;
            const size_t xStride = c.stride * sizeof(float);
            // The writer only reads through the slice.
            rows.slices.push_back({c.name, const_cast<char*>(reinterpret_cast<const char*>(data)),
                                   xStride, xStride * size_t(h.width)});
        }
    }
    return out;
}

/// MCSTAT_EXR_WRITER=cpp: every part through OpenEXR's C++ API with zlib, as before the Core
/// writer (the same pixels in other bytes; for comparisons in tests and benchmarks).
bool cppWriterAsked() {
    const char* v = std::getenv("MCSTAT_EXR_WRITER");
    return v != nullptr && std::strcmp(v, "cpp") == 0;
}

/// Bytes per pixel of the widest array a flat slice of `h` points into (the Core writer's
/// strides), `extra` those of the version-4 parts.
size_t widestPixelBytes(const StatsHeader& h, size_t extra) {
    const size_t m = size_t(std::max(1, h.M));
    return std::max(sizeof(float) * std::max({size_t(3) * m, m * h.aovs.size(), size_t(11)}),
                    extra);
}

}  // namespace

struct StatsFileWriter::Impl {
    std::string path;
    std::unique_ptr<TemporaryFile> tmp;  ///< removed when abandoned, on a signal, or renamed
    StatsHeader header;
    detail::Fd fd;
    std::unique_ptr<detail::FdOStream> os;
    std::unique_ptr<Imf::MultiPartOutputFile> file;
    std::unique_ptr<detail::CorePartWriter> core;  ///< instead of `file` when it takes the parts
    int nextRow = 0;                               ///< rows written so far
    /// writeStatsFile's version-4 parts: written with the image by the Core writer, or after the
    /// four parts by commit() through the C++ API.
    const StatsExtras* extras = nullptr;
    std::function<void(Imf::MultiPartOutputFile&)> extraParts;
    bool failed = false;
    /// replaceSeeds(): mcstat:seeds put in place by commit() ("" keeps open()'s).
    std::string seeds;
    /// writeStatsFile's image, validated before open(): write() does not check it again.
    const StatsImage* validated = nullptr;

    ~Impl() {
        file.reset();  // OpenEXR writes the offset tables here; the file is removed anyway
        core.reset();
        fd.reset();
        tmp.reset();  // removes the temporary unless it was renamed
    }
};

/// writeStatsFile's access to the writer's extra parts.
struct StatsFileWriterAccess {
    static bool open(StatsFileWriter& w, const std::string& path, const StatsHeader& h,
                     const std::vector<Imf::Header>& extraHeaders, const StatsExtras* extras,
                     std::function<void(Imf::MultiPartOutputFile&)> extraParts, std::string& err,
                     int nthreads);
    static void markValidated(StatsFileWriter& w, const StatsImage& img) {
        w.impl_->validated = &img;
    }
};

StatsFileWriter::StatsFileWriter() = default;
StatsFileWriter::~StatsFileWriter() = default;

bool StatsFileWriter::open(const std::string& path, const StatsHeader& header, std::string& err,
                           int nthreads) {
    return StatsFileWriterAccess::open(*this, path, header, {}, nullptr, {}, err, nthreads);
}

bool StatsFileWriterAccess::open(StatsFileWriter& w, const std::string& path, const StatsHeader& h,
                                 const std::vector<Imf::Header>& extraHeaders,
                                 const StatsExtras* extras,
                                 std::function<void(Imf::MultiPartOutputFile&)> extraParts,
                                 std::string& err, int nthreads) {
    w.impl_.reset();
    StatsImage probe;  // header checks without pixels: validateStats over no part
    probe.header = h;
    if (!validateStats(probe, 0u, path, err)) return false;
    if (h.spp > std::numeric_limits<int>::max()) {
        err = fmt::format("{}: spp {} does not fit the int attribute {}", path, h.spp,
                          layout::kAttrSpp);
        return false;
    }
    if (!checkOutputTarget(path, err)) return false;
    auto impl = std::make_unique<StatsFileWriter::Impl>();
    impl->path = path;
    impl->header = h;
    impl->extras = extras;
    impl->extraParts = std::move(extraParts);
    impl->tmp = std::make_unique<TemporaryFile>(path);
    const std::string& tmp = impl->tmp->path();
    impl->fd = detail::Fd(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666));
    if (impl->fd.get() < 0) {
        err = fmt::format("{}: cannot write the file ({})", path, std::strerror(errno));
        impl->tmp->remove();  // nothing was created; forget the name
        return false;
    }
    try {
        std::vector<Imf::Header> headers = makeHeaders(h);
        headers.insert(headers.end(), extraHeaders.begin(), extraHeaders.end());
        const size_t extraBytes = extras != nullptr ? detail::extraPixelBytes(*extras) : 0;
        if (!cppWriterAsked() &&
            detail::CorePartWriter::supports(headers, widestPixelBytes(h, extraBytes))) {
            impl->core = std::make_unique<detail::CorePartWriter>();
            std::string problem;
            if (!impl->core->open(impl->fd.get(), path, headers, detail::codecThreads(nthreads),
                                  problem)) {
                err = fmt::format("{}: cannot write ({})", path, problem);
                return false;
            }
        } else {
            impl->os = std::make_unique<detail::FdOStream>(impl->fd.get(), tmp);
            impl->file = std::make_unique<Imf::MultiPartOutputFile>(*impl->os, headers.data(),
                                                                    int(headers.size()), false,
                                                                    detail::codecThreads(nthreads));
        }
    } catch (const std::exception& e) {
        err = fmt::format("{}: cannot write ({})", path, e.what());
        return false;
    }
    w.impl_ = std::move(impl);
    return true;
}

bool StatsFileWriter::write(const StatsImage& block, std::string& err) {
    if (!impl_ || impl_->failed) {
        err =
            impl_ ? impl_->path + ": an earlier write failed" : "statistics file writer: not open";
        return false;
    }
    Impl& im = *impl_;
    const StatsHeader& h = im.header;
    const StatsHeader& b = block.header;
    if (b.width != h.width || b.originX != h.originX || b.M != h.M || b.adaptiveM != h.adaptiveM ||
        b.originY != h.originY + im.nextRow || b.height > h.height - im.nextRow ||
        b.aovs.size() != h.aovs.size()) {
        err = fmt::format(
            "{}: a block of rows {}..{} ({} wide, M = {}, {} AOVs) does not continue the image at "
            "row {} of {} ({} wide, M = {}, {} AOVs)",
            im.path, int64_t(b.originY) - h.originY, int64_t(b.originY) - h.originY + b.height - 1,
            b.width, b.M, b.aovs.size(), im.nextRow, h.height, h.width, h.M, h.aovs.size());
        return false;
    }
    if (b.aovs != h.aovs) {
        for (size_t a = 0; a < h.aovs.size(); ++a)
            if (!(b.aovs[a] == h.aovs[a])) {
                err = fmt::format(
                    "{}: a block's AOV {} is '{}' ({}, part '{}'), the image's is '{}' ({}, part "
                    "'{}')",
                    im.path, a, printable(b.aovs[a].name), aovClassName(b.aovs[a].cls),
                    printable(b.aovs[a].part), printable(h.aovs[a].name),
                    aovClassName(h.aovs[a].cls), printable(h.aovs[a].part));
                return false;
            }
    }
    if (&block != im.validated && !validateStats(block, im.path, err)) return false;
    if (im.core) {
        std::string problem;
        bool ok = false;
        try {
            DeepBufferRows deep;
            std::vector<detail::PartRows> rows = partRows(block, deep);
            // The version-4 parts come with the whole image (writeStatsFile).
            if (im.extras != nullptr) detail::appendExtraRows(rows, block, *im.extras);
            ok = im.core->write(rows, b.height, problem);
        } catch (const std::bad_alloc&) {
            problem = "out of memory";
        }
        if (!ok) {
            im.failed = true;
            err = fmt::format("{}: cannot write ({})", im.path, problem);
            return false;
        }
        im.nextRow += b.height;
        return true;
    }
    try {
        writeRows(*im.file, block);
        if (!im.os->error().empty()) throw std::runtime_error(im.os->error());
    } catch (const std::exception& e) {
        im.failed = true;
        err = fmt::format("{}: cannot write ({})", im.path, e.what());
        return false;
    }
    im.nextRow += b.height;
    return true;
}

bool StatsFileWriter::replaceSeeds(const std::string& seeds, std::string& err) {
    if (!impl_) {
        err = "statistics file writer: not open";
        return false;
    }
    if (seeds.size() != impl_->header.seeds.size()) {
        err = fmt::format("{}: mcstat:seeds of {} bytes cannot replace the {} written", impl_->path,
                          seeds.size(), impl_->header.seeds.size());
        return false;
    }
    impl_->seeds = seeds;
    return true;
}

bool StatsFileWriter::commit(std::string& err) {
    if (!impl_ || impl_->failed || impl_->nextRow != impl_->header.height) {
        err = !impl_ ? "statistics file writer: not open"
                     : fmt::format("{}: {} of {} rows written", impl_->path, impl_->nextRow,
                                   impl_->header.height);
        return false;
    }
    Impl& im = *impl_;
    std::string problem;
    try {
        if (im.core) {
            im.core->finish(problem);  // the spilled chunks and the offset tables
            im.core.reset();
        } else {
            if (im.extraParts) im.extraParts(*im.file);
            im.file.reset();  // writes the offset tables
            problem = im.os->error();
        }
    } catch (const std::exception& e) {
        problem = e.what();
    }
    if (problem.empty() && !im.seeds.empty() && im.seeds != im.header.seeds) {
        // The seeds known once every row was written (replaceSeeds), in place in every header.
        const std::string& tmp = im.tmp->path();
        detail::Fd rw(::open(tmp.c_str(), O_RDWR | O_CLOEXEC));
        struct stat st {};
        std::string why;
        if (rw.get() < 0 || ::fstat(rw.get(), &st) != 0)
            problem = std::strerror(errno);
        else if (!detail::replaceStringAttribute(rw.get(), uint64_t(st.st_size), tmp,
                                                 layout::kAttrSeeds, im.seeds, why))
            problem = why;
    }
    if (problem.empty() && ::fsync(im.fd.get()) != 0) problem = std::strerror(errno);
    if (const std::string closeErr = im.fd.close(); problem.empty()) problem = closeErr;
    if (!problem.empty()) {
        err = fmt::format("{}: cannot write ({})", im.path, problem);
        impl_.reset();  // removes the temporary file
        return false;
    }
    if (!im.tmp->commit(err)) {
        impl_.reset();
        return false;
    }
    // Make the rename durable; a failure here does not undo the write.
    detail::Fd dir(::open(dirOf(im.path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
    if (dir.get() >= 0) (void)::fsync(dir.get());
    impl_.reset();
    return true;
}

bool writeStatsFile(const std::string& path, const StatsImage& img, std::string& err) {
    return writeStatsFile(path, img, StatsExtras(), err);
}

bool writeStatsFile(const std::string& path, const StatsImage& img, const StatsExtras& extras,
                    std::string& err) {
    if (!validateStats(img, path, err)) return false;
    if (!detail::checkExtras(path, img, extras, err)) return false;
    // The four parts as one block, then the extras: part after part, as a reader expects them.
    std::vector<Imf::Header> extraHeaders;
    detail::appendExtraHeaders(extraHeaders, img.header, extras);
    StatsFileWriter w;
    auto extraParts = [&img, &extras](Imf::MultiPartOutputFile& out) {
        detail::writeExtraParts(out, img, extras);
    };
    if (!StatsFileWriterAccess::open(w, path, img.header, extraHeaders, &extras,
                                     extraHeaders.empty() ? nullptr : std::function(extraParts),
                                     err, 0))
        return false;
    StatsFileWriterAccess::markValidated(w, img);  // above: one pass over the pixels, not two
    return w.write(img, err) && w.commit(err);
}

}  // namespace mcstat
