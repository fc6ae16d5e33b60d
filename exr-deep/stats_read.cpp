// readStatsFile / readStatsHeader: header validation first (stats_header_check), then each part is
// read straight into the StatsImage arrays through Imf::FrameBuffer slices, then validateStats.
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputPart.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfPartType.h>
#include <errno.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>

#include <cstring>

#include "fd_stream.h"
#include "mcstat/stats_file.h"
#include "stats_header_check.h"
#include "stats_layout.h"

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

/// Reads the pixels of every part into `img` (allocated for img.header); throws on failure.
void readParts(detail::FdIStream& is, StatsImage& img) {
    const StatsHeader& h = img.header;
    const Imath::Box2i window(Imath::V2i(h.originX, h.originY),
                              Imath::V2i(h.originX + h.width - 1, h.originY + h.height - 1));
    Imf::MultiPartInputFile in(is);
    // Same open file as the header check; guard anyway against it changing under us.
    if (in.parts() != layout::kPartCount) throw std::runtime_error("file changed while reading");
    for (int part = 0; part < layout::kPartCount; ++part) {
        const Imf::Header& ph = in.header(part);
        if (ph.dataWindow() != window || !ph.hasName() || ph.name() != layout::kPartNames[part] ||
            ph.type() != Imf::SCANLINEIMAGE)
            throw std::runtime_error("file changed while reading");
    }
    for (int part = 0; part < layout::kPartCount; ++part) {
        Imf::FrameBuffer fb;
        for (const layout::ChannelPlace& c : layout::partChannels(part, h.M)) {
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
        std::string allocErr;
        if (!t.allocate(allocErr)) {
            err = path + ": " + allocErr;
            return false;
        }
        try {
            detail::FdIStream is(fd.get(), path, size);
            readParts(is, t);
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
