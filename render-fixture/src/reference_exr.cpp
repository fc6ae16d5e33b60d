#include "reference_exr.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <fmt/format.h>

#include <ctime>
#include <exception>

#include "mcstat/core/color_space.h"
#include "mcstat/exr-deep/codec/temp_file.h"
#include "mcstat/render-fixture/render.h"

namespace mcstat::render {
namespace {

constexpr const char* kChannels[3] = {"R", "G", "B"};  ///< in the order of `rgb`'s floats

/// The EXR capDate of now, local time ("YYYY:MM:DD HH:MM:SS", the standard attribute's form).
std::string captureDate() {
    const std::time_t now = std::time(nullptr);
    std::tm local{};
    localtime_r(&now, &local);
    char text[32] = {};
    std::strftime(text, sizeof text, "%Y:%m:%d %H:%M:%S", &local);
    return text;
}

Imf::Header referenceHeader(int width, int height, const std::string& colorSpace, uint64_t seed,
                            int64_t spp) {
    Imf::Header header(width, height);
    header.compression() = Imf::ZIP_COMPRESSION;
    for (const char* name : kChannels) header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    header.insert("Software", Imf::StringAttribute(kRendererName));
    Imf::addCapDate(header, captureDate());
    header.insert("mcstat:seeds", Imf::StringAttribute(std::to_string(seed)));
    header.insert("mcstat:spp", Imf::StringAttribute(std::to_string(spp)));
    // The working space as every mcstat output labels it (image/spec's labelColorSpace).
    if (const WorkingSpace* ws = findWorkingSpace(colorSpace)) {
        const Chromaticities& c = ws->xy;
        Imf::addChromaticities(header, Imf::Chromaticities(Imath::V2f(float(c.rx), float(c.ry)),
                                                           Imath::V2f(float(c.gx), float(c.gy)),
                                                           Imath::V2f(float(c.bx), float(c.by)),
                                                           Imath::V2f(float(c.wx), float(c.wy))));
        header.insert("colorInteropID", Imf::StringAttribute(ws->interopID));
    }
    return header;
}

}  // namespace

bool writeReferenceExr(const std::string& path, int width, int height,
                       const std::vector<float>& rgb, const std::string& colorSpace, uint64_t seed,
                       int64_t spp, std::string& err) {
    if (width <= 0 || height <= 0 || rgb.size() != size_t(width) * size_t(height) * 3) {
        err = fmt::format("{}: {} values for a {} x {} RGB image", path, rgb.size(), width, height);
        return false;
    }
    if (!checkOutputTarget(path, err)) return false;
    TemporaryFile tmp(path, ".exr");
    try {
        Imf::OutputFile out(tmp.path().c_str(),
                            referenceHeader(width, height, colorSpace, seed, spp));
        Imf::FrameBuffer frame;
        const size_t pixel = 3 * sizeof(float), row = pixel * size_t(width);
        char* base = const_cast<char*>(reinterpret_cast<const char*>(rgb.data()));
        for (size_t c = 0; c < 3; ++c)
            frame.insert(kChannels[c],
                         Imf::Slice(Imf::FLOAT, base + c * sizeof(float), pixel, row));
        out.setFrameBuffer(frame);
        out.writePixels(height);
    } catch (const std::exception& e) {
        err = path + ": " + e.what();
        return false;  // tmp removes the partial file
    }
    return tmp.commit(err);
}

}  // namespace mcstat::render
