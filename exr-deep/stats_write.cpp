// writeStatsFile: validate, write the four parts (part 1 deep with adaptive M) to a temporary file
// in the target's directory, rename it onto the target. On failure the temporary file is removed
// and the target is untouched.
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
#include <errno.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <random>

#include "extra_parts.h"
#include "fd_stream.h"
#include "mcstat/sample_records.h"
#include "mcstat/stats_file.h"
#include "stats_layout.h"
#include "window.h"

namespace mcstat {

namespace {

using detail::windowBase;
using detail::windowOf;

}  // namespace

namespace detail {

std::string tempNameFor(const std::string& path) {
    const size_t slash = path.rfind('/');
    const std::string dir = slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
    const std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
    std::random_device rd;
    return fmt::format("{}.{}.tmp-{}-{:08x}", dir, name, long(::getpid()), rd());
}

Imf::Header commonHeader(const StatsHeader& h, const std::string& name, bool deep) {
    const Imath::Box2i window = windowOf(h);
    // Deep parts cannot use ZIP (16 lines); ZIPS (one line) is the deflate they allow.
    Imf::Header hdr(window, window, 1.f, Imath::V2f(0.f, 0.f), 1.f, Imf::INCREASING_Y,
                    deep ? Imf::ZIPS_COMPRESSION : Imf::ZIP_COMPRESSION);
    hdr.zipCompressionLevel() = 4;  // fixed, so equal images give equal bytes
    hdr.setName(name);
    hdr.setType(deep ? Imf::DEEPSCANLINE : Imf::SCANLINEIMAGE);
    hdr.insert(layout::kAttrPartVersion, Imf::IntAttribute(1));
    hdr.insert(layout::kAttrFormatVersion, Imf::IntAttribute(h.formatVersion));
    if (h.formatVersion >= kStatsFormatVersionAdaptive)
        hdr.insert(layout::kAttrAdaptiveM, Imf::IntAttribute(h.adaptiveM ? 1 : 0));
    hdr.insert(layout::kAttrM, Imf::IntAttribute(h.M));
    hdr.insert(layout::kAttrSpp, Imf::IntAttribute(int(h.spp)));
    hdr.insert(layout::kAttrAssignment, Imf::StringAttribute(h.assignment));
    hdr.insert(layout::kAttrRenderer, Imf::StringAttribute(h.renderer));
    hdr.insert(layout::kAttrColorSpace, Imf::StringAttribute(h.colorSpace));
    hdr.insert(layout::kAttrSeeds, Imf::StringAttribute(h.seeds));
    if (h.formatVersion >= kStatsFormatVersionProvenance) {
        hdr.insert(layout::kAttrVariance, Imf::StringAttribute(h.variance));
        hdr.insert(layout::kAttrFeatures, Imf::StringAttribute(featureListText(h.features)));
        hdr.insert(layout::kAttrSources, Imf::StringAttribute(h.sources));
    }
    return hdr;
}

}  // namespace detail

namespace {

std::vector<Imf::Header> makeHeaders(const StatsHeader& h) {
    std::vector<Imf::Header> headers;
    for (int part = 0; part < layout::kPartCount; ++part) {
        const bool deep = h.adaptiveM && part == layout::kBuffers;
        Imf::Header hdr = detail::commonHeader(h, layout::partNames(h.adaptiveM)[part], deep);
        if (part == layout::kBeauty) Imf::addChromaticities(hdr, Imf::Chromaticities());  // Rec.709
        for (const layout::ChannelPlace& c : layout::partChannels(part, h.M, h.adaptiveM))
            hdr.channels().insert(c.name, Imf::Channel(Imf::FLOAT));
        if (deep)
            for (const char* name : layout::kDeepChannels)
                hdr.channels().insert(name, Imf::Channel(Imf::FLOAT));
        headers.push_back(std::move(hdr));
    }
    return headers;
}

std::string dirOf(const std::string& path) {
    const size_t slash = path.rfind('/');
    if (slash == std::string::npos) return ".";
    return slash == 0 ? "/" : path.substr(0, slash);
}

/// Adaptive M: part "vbuffers", one deep sample per sub-buffer (R, G, B, count; Z = buffer index,
/// A = 1).
void writeDeepBuffers(Imf::MultiPartOutputFile& out, const StatsImage& img) {
    const StatsHeader& h = img.header;
    const size_t pixels = img.pixelCount();
    // Z and A are the same for every pixel: j and 1 for sample j, so all pixels point at one row.
    std::vector<float> zs(size_t(h.M)), ones(size_t(h.M), 1.f);
    for (size_t j = 0; j < zs.size(); ++j) zs[j] = float(j);
    std::vector<uint32_t> m(pixels);
    std::vector<const char*> ptr[6];
    for (auto& v : ptr) v.resize(pixels);
    for (size_t p = 0; p < pixels; ++p) {
        const size_t k = img.bufferBegin(p);
        m[p] = uint32_t(img.buffersOf(p));
        for (size_t c = 0; c < 3; ++c)
            ptr[c][p] = reinterpret_cast<const char*>(img.bufferMean.data() + k * 3 + c);
        ptr[3][p] = reinterpret_cast<const char*>(img.bufferCount.data() + k);
        ptr[4][p] = reinterpret_cast<const char*>(zs.data());
        ptr[5][p] = reinterpret_cast<const char*>(ones.data());
    }
    Imf::DeepFrameBuffer fb;
    const size_t xs = sizeof(char*), ys = xs * size_t(h.width);
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, windowBase(m.data(), h, sizeof(uint32_t)),
                                         sizeof(uint32_t), sizeof(uint32_t) * size_t(h.width)));
    for (size_t c = 0; c < 6; ++c)
        fb.insert(layout::kDeepChannels[c],
                  Imf::DeepSlice(Imf::FLOAT, windowBase(ptr[c].data(), h, xs), xs, ys,
                                 c < 3 ? 3 * sizeof(float) : sizeof(float)));
    Imf::DeepScanLineOutputPart op(out, layout::kBuffers);
    op.setFrameBuffer(fb);
    op.writePixels(h.height);
}

/// Writes every part to `os`; throws on failure.
void writeParts(Imf::OStream& os, const StatsImage& img, const StatsExtras& extras) {
    const StatsHeader& h = img.header;
    std::vector<Imf::Header> headers = makeHeaders(h);
    detail::appendExtraHeaders(headers, h, extras);
    const Imath::Box2i window = windowOf(h);
    Imf::MultiPartOutputFile out(os, headers.data(), int(headers.size()));
    for (int part = 0; part < layout::kPartCount; ++part) {
        if (h.adaptiveM && part == layout::kBuffers) {
            writeDeepBuffers(out, img);
            continue;
        }
        Imf::FrameBuffer fb;
        for (const layout::ChannelPlace& c : layout::partChannels(part, h.M, h.adaptiveM)) {
            const float* base = layout::arrayOf(img, c.array).data() + c.offset;
            const size_t xStride = c.stride * sizeof(float);
            fb.insert(c.name, Imf::Slice::Make(Imf::FLOAT, base, window, xStride,
                                               xStride * size_t(h.width)));
        }
        Imf::OutputPart op(out, part);
        op.setFrameBuffer(fb);
        op.writePixels(h.height);
    }
    detail::writeExtraParts(out, img, extras);
}

}  // namespace

bool writeStatsFile(const std::string& path, const StatsImage& img, std::string& err) {
    return writeStatsFile(path, img, StatsExtras(), err);
}

bool writeStatsFile(const std::string& path, const StatsImage& img, const StatsExtras& extras,
                    std::string& err) {
    if (!validateStats(img, path, err)) return false;
    if (!detail::checkExtras(path, img, extras, err)) return false;
    if (img.header.spp > std::numeric_limits<int>::max()) {
        err = fmt::format("{}: spp {} does not fit the int attribute {}", path, img.header.spp,
                          layout::kAttrSpp);
        return false;
    }
    const std::string tmp = detail::tempNameFor(path);
    detail::Fd fd(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666));
    if (fd.get() < 0) {
        err = fmt::format("{}: cannot create temporary file {} ({})", path, tmp,
                          std::strerror(errno));
        return false;
    }
    std::string problem;
    try {
        detail::FdOStream os(fd.get(), tmp);
        writeParts(os, img, extras);  // the offset table is written when `out` is destroyed
        problem = os.error();
    } catch (const std::exception& e) {
        problem = e.what();
    }
    if (problem.empty() && ::fsync(fd.get()) != 0) problem = std::strerror(errno);
    if (const std::string closeErr = fd.close(); problem.empty()) problem = closeErr;
    if (problem.empty() && std::rename(tmp.c_str(), path.c_str()) != 0)
        problem = fmt::format("cannot rename {} onto it ({})", tmp, std::strerror(errno));
    if (!problem.empty()) {
        ::unlink(tmp.c_str());
        err = fmt::format("{}: cannot write ({})", path, problem);
        return false;
    }
    // Make the rename durable; a failure here does not undo the write.
    detail::Fd dir(::open(dirOf(path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
    if (dir.get() >= 0) (void)::fsync(dir.get());
    return true;
}

}  // namespace mcstat
