// readStatsFile / readStatsHeader: header validation first (stats_header_check), then each part is
// read straight into the StatsImage arrays through Imf::FrameBuffer slices, then validateStats.
// Adaptive M (format 2): the deep part's sample counts are read and checked first, then the image
// is allocated for them, then the deep samples are read through per-pixel pointers.
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

#include <cstdint>
#include <cstring>

#include "fd_stream.h"
#include "mcstat/stats_file.h"
#include "stats_header_check.h"
#include "stats_layout.h"
#include "window.h"

namespace mcstat {

namespace {

/// Opens `path` for reading and checks its headers. On success `fd` is open and `size` set.
bool openAndCheck(const std::string& path, const ReadLimits& limits, detail::Fd& fd, uint64_t& size,
                  StatsHeader& hdr, std::string& err) {
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
    return detail::checkStatsHeaders(fd.get(), size, path, limits, hdr, err);
}

using detail::windowBase;
using detail::windowOf;

/// Checks that the file opened by the C++ API is the file the header check saw.
void checkSameFile(const Imf::MultiPartInputFile& in, const StatsHeader& h) {
    // Same open file as the header check; guard anyway against it changing under us.
    const int expected = layout::kPartCount + (h.hasPajot ? 2 : 0) + (h.hasRecords ? 1 : 0);
    if (in.parts() != expected) throw std::runtime_error("file changed while reading");
    const char* const* names = layout::partNames(h.adaptiveM);
    for (int part = 0; part < layout::kPartCount; ++part) {
        const Imf::Header& ph = in.header(part);
        const bool deep = h.adaptiveM && part == layout::kBuffers;
        if (ph.dataWindow() != windowOf(h) || !ph.hasName() || ph.name() != names[part] ||
            ph.type() != (deep ? Imf::DEEPSCANLINE : Imf::SCANLINEIMAGE))
            throw std::runtime_error("file changed while reading");
    }
}

/// Reads the flat parts into `img` (allocated for img.header); throws on failure.
void readFlatParts(Imf::MultiPartInputFile& in, StatsImage& img) {
    const StatsHeader& h = img.header;
    const Imath::Box2i window = windowOf(h);
    for (int part = 0; part < layout::kPartCount; ++part) {
        if (h.adaptiveM && part == layout::kBuffers) continue;
        Imf::FrameBuffer fb;
        for (const layout::ChannelPlace& c : layout::partChannels(part, h.M, h.adaptiveM)) {
            float* base = layout::arrayOf(img, c.array).data() + c.offset;
            const size_t xStride = c.stride * sizeof(float);
            fb.insert(c.name, Imf::Slice::Make(Imf::FLOAT, base, window, xStride,
                                               xStride * size_t(h.width)));
        }
        Imf::InputPart ip(in, part);
        ip.setFrameBuffer(fb);
        ip.readPixels(window.min.y, window.max.y);
    }
}

/// Adaptive M: reads the per-pixel sample counts of part "vbuffers", checks them (1..M each,
/// total within the limits) and allocates `img` for them. False with `err` on a bad file;
/// throws on read errors.
bool readDeepCounts(Imf::MultiPartInputFile& in, const std::string& path, const ReadLimits& limits,
                    StatsImage& img, std::string& err) {
    const StatsHeader& h = img.header;
    const size_t pixels = size_t(h.width) * size_t(h.height);
    std::vector<uint32_t> m(pixels);
    Imf::DeepScanLineInputPart dp(in, layout::kBuffers);
    Imf::DeepFrameBuffer fb;
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, windowBase(m.data(), h, sizeof(uint32_t)),
                                         sizeof(uint32_t), sizeof(uint32_t) * size_t(h.width)));
    dp.setFrameBuffer(fb);
    dp.readPixelSampleCounts(h.originY, h.originY + h.height - 1);
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
        total += m[p];
    }
    const double bytes =
        double(layout::floatsPerPixel(0) * sizeof(float) + sizeof(uint64_t)) * double(pixels) +
        double(total) * 4.0 * sizeof(float);
    if (int64_t(total) > limits.maxDeepSamples || bytes > double(limits.maxBytes)) {
        err = fmt::format(
            "{}: part '{}' holds {} sub-buffers ({} bytes in memory), exceeding the limit of {} "
            "deep samples or {} bytes",
            path, layout::kPartNamesAdaptive[layout::kBuffers], total, bytes, limits.maxDeepSamples,
            limits.maxBytes);
        return false;
    }
    std::string allocErr;
    if (!img.allocateAdaptive(m, allocErr)) {
        err = path + ": " + allocErr;
        return false;
    }
    return true;
}

/// Adaptive M: reads the buffer means and counts of part "vbuffers" into `img` (allocated by
/// readDeepCounts); Z and A are not read. Throws on read errors.
void readDeepBuffers(Imf::MultiPartInputFile& in, StatsImage& img) {
    const StatsHeader& h = img.header;
    const size_t pixels = img.pixelCount();
    std::vector<uint32_t> m(pixels);
    std::vector<char*> ptr[4];
    for (auto& v : ptr) v.resize(pixels);
    for (size_t p = 0; p < pixels; ++p) {
        const size_t k = img.bufferBegin(p);
        for (size_t c = 0; c < 3; ++c)
            ptr[c][p] = reinterpret_cast<char*>(img.bufferMean.data() + k * 3 + c);
        ptr[3][p] = reinterpret_cast<char*>(img.bufferCount.data() + k);
    }
    Imf::DeepFrameBuffer fb;
    const size_t xs = sizeof(char*), ys = xs * size_t(h.width);
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, windowBase(m.data(), h, sizeof(uint32_t)),
                                         sizeof(uint32_t), sizeof(uint32_t) * size_t(h.width)));
    for (size_t c = 0; c < 4; ++c)
        fb.insert(layout::kDeepChannels[c],
                  Imf::DeepSlice(Imf::FLOAT, windowBase(ptr[c].data(), h, xs), xs, ys,
                                 c < 3 ? 3 * sizeof(float) : sizeof(float)));
    Imf::DeepScanLineInputPart dp(in, layout::kBuffers);
    dp.setFrameBuffer(fb);
    dp.readPixelSampleCounts(h.originY, h.originY + h.height - 1);
    for (size_t p = 0; p < pixels; ++p)
        if (m[p] != uint32_t(img.buffersOf(p)))
            throw std::runtime_error("file changed while reading");
    dp.readPixels(h.originY, h.originY + h.height - 1);
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
        err = fmt::format("{}: {}", path, detail::oneLine(e.what()));
    } catch (...) {
        err = path + ": unknown error while reading the headers";
    }
    return false;
}

bool readStatsFile(const std::string& path, StatsImage& img, std::string& err,
                   const ReadLimits& limits) {
    try {
        detail::Fd fd;
        uint64_t size = 0;
        StatsImage t;
        if (!openAndCheck(path, limits, fd, size, t.header, err)) return false;
        if (!t.header.adaptiveM) {
            std::string allocErr;
            if (!t.allocate(allocErr)) {
                err = path + ": " + allocErr;
                return false;
            }
        }
        try {
            detail::FdIStream is(fd.get(), path, size);
            Imf::MultiPartInputFile in(is);
            checkSameFile(in, t.header);
            if (t.header.adaptiveM) {
                if (!readDeepCounts(in, path, limits, t, err)) return false;
                readDeepBuffers(in, t);
            }
            readFlatParts(in, t);
        } catch (const std::bad_alloc&) {
            err = path + ": out of memory while reading pixels";
            return false;
        } catch (const std::exception& e) {
            err = fmt::format("{}: truncated or corrupt ({})", path, detail::oneLine(e.what()));
            return false;
        }
        if (!validateStats(t, path, err)) return false;
        img = std::move(t);
        return true;
    } catch (const std::exception& e) {
        err = fmt::format("{}: {}", path, detail::oneLine(e.what()));
    } catch (...) {
        err = path + ": unknown error while reading";
    }
    return false;
}

}  // namespace mcstat
