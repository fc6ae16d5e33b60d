#include "raw_exr.h"

#include <Imath/half.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepScanLineOutputPart.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfInputPart.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfMultiPartOutputFile.h>
#include <OpenEXR/ImfOutputPart.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfTiledOutputPart.h>

#include <cstdio>
#include <stdexcept>

namespace mcstat::test {

namespace {

Imf::Header baseHeader(const StatsHeader& h, const char* name) {
    const Imath::Box2i w(Imath::V2i(h.originX, h.originY),
                         Imath::V2i(h.originX + h.width - 1, h.originY + h.height - 1));
    Imf::Header hdr(w, w, 1.f, Imath::V2f(0, 0), 1.f, Imf::INCREASING_Y, Imf::ZIP_COMPRESSION);
    hdr.setName(name);
    hdr.setType(Imf::SCANLINEIMAGE);
    hdr.insert("version", Imf::IntAttribute(1));
    hdr.insert("mcstat:formatVersion", Imf::IntAttribute(h.formatVersion));
    hdr.insert("mcstat:M", Imf::IntAttribute(h.M));
    hdr.insert("mcstat:spp", Imf::IntAttribute(int(h.spp)));
    hdr.insert("mcstat:assignment", Imf::StringAttribute(h.assignment));
    hdr.insert("mcstat:renderer", Imf::StringAttribute(h.renderer));
    hdr.insert("mcstat:colorSpace", Imf::StringAttribute(h.colorSpace));
    hdr.insert("mcstat:seeds", Imf::StringAttribute(h.seeds));
    return hdr;
}

/// Adds channel `name` holding element `offset` of each `stride`-float pixel of `src`.
void addChannel(RawPart& part, const std::string& name, const std::vector<float>& src,
                size_t offset, size_t stride) {
    part.header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    std::vector<float>& v = part.values[name];
    const size_t n = src.size() / stride;
    v.resize(n);
    for (size_t p = 0; p < n; ++p) v[p] = src[p * stride + offset];
}

}  // namespace

std::vector<RawPart> rawPartsFrom(const StatsImage& img) {
    const StatsHeader& h = img.header;
    const size_t m = size_t(h.M);
    std::vector<RawPart> parts(4);
    parts[0].header = baseHeader(h, "beauty");
    Imf::addChromaticities(parts[0].header, Imf::Chromaticities());
    const char* rgb[3] = {"R", "G", "B"};
    const char* xyz[3] = {"X", "Y", "Z"};
    for (size_t c = 0; c < 3; ++c) addChannel(parts[0], rgb[c], img.beauty, c, 3);

    parts[1].header = baseHeader(h, "buffers");
    for (size_t j = 0; j < m; ++j) {
        char prefix[32];
        std::snprintf(prefix, sizeof prefix, "b%03zu.", j);
        for (size_t c = 0; c < 3; ++c)
            addChannel(parts[1], std::string(prefix) + rgb[c], img.bufferMean, j * 3 + c, 3 * m);
        addChannel(parts[1], std::string(prefix) + "count", img.bufferCount, j, m);
    }

    parts[2].header = baseHeader(h, "moments");
    addChannel(parts[2], "count", img.count, 0, 1);
    for (size_t c = 0; c < 3; ++c) {
        addChannel(parts[2], std::string("mean.") + rgb[c], img.mean, c, 3);
        addChannel(parts[2], std::string("variance.") + rgb[c], img.variance, c, 3);
    }

    parts[3].header = baseHeader(h, "features");
    for (size_t c = 0; c < 3; ++c) {
        addChannel(parts[3], std::string("N.") + xyz[c], img.normal, c, 3);
        addChannel(parts[3], std::string("P.") + xyz[c], img.position, c, 3);
        addChannel(parts[3], std::string("Albedo.") + rgb[c], img.albedo, c, 3);
    }
    addChannel(parts[3], "Z", img.depth, 0, 1);
    addChannel(parts[3], "A", img.coverage, 0, 1);
    return parts;
}

std::vector<RawPart> rawAdaptivePartsFrom(const StatsImage& img) {
    // The flat parts as for fixed M, then part 1 replaced by the deep part.
    StatsImage flat = img;
    flat.header.adaptiveM = false;
    flat.header.M = 1;
    flat.bufferOffset.clear();
    flat.bufferMean.assign(img.pixelCount() * 3, 0.f);
    flat.bufferCount.assign(img.pixelCount(), 0.f);
    std::vector<RawPart> parts = rawPartsFrom(flat);
    for (RawPart& p : parts) {
        p.header.insert("mcstat:M", Imf::IntAttribute(img.header.M));
        p.header.insert("mcstat:adaptiveM", Imf::IntAttribute(1));
    }
    RawPart& d = parts[1];
    Imf::Header h = baseHeader(img.header, "vbuffers");
    h.insert("mcstat:adaptiveM", Imf::IntAttribute(1));
    h.setType(Imf::DEEPSCANLINE);
    h.compression() = Imf::ZIPS_COMPRESSION;
    for (const char* c : {"R", "G", "B", "count", "Z", "A"})
        h.channels().insert(c, Imf::Channel(Imf::FLOAT));
    d.header = h;
    d.values.clear();
    const size_t pixels = img.pixelCount();
    d.deepCounts.resize(pixels);
    const char* rgb[3] = {"R", "G", "B"};
    for (size_t p = 0; p < pixels; ++p) {
        const PixelBuffers b = img.pixelBuffers(p);
        d.deepCounts[p] = unsigned(b.M);
        for (int j = 0; j < b.M; ++j) {
            for (int c = 0; c < 3; ++c) d.values[rgb[c]].push_back(b.mean[j * 3 + c]);
            d.values["count"].push_back(b.count[j]);
            d.values["Z"].push_back(float(j));
            d.values["A"].push_back(1.f);
        }
    }
    return parts;
}

std::vector<RawPart> readRaw(const std::string& path) {
    Imf::MultiPartInputFile in(path.c_str());
    std::vector<RawPart> parts(size_t(in.parts()));
    for (int i = 0; i < in.parts(); ++i) {
        RawPart& part = parts[size_t(i)];
        part.header = in.header(i);
        if (part.header.type() != Imf::SCANLINEIMAGE)
            throw std::runtime_error("readRaw: part " + std::to_string(i) + " is not flat");
        const Imath::Box2i dw = part.header.dataWindow();
        const size_t w = size_t(dw.max.x - dw.min.x + 1), n = w * size_t(dw.max.y - dw.min.y + 1);
        Imf::FrameBuffer fb;
        for (auto it = part.header.channels().begin(); it != part.header.channels().end(); ++it) {
            std::vector<float>& v = part.values[it.name()];
            v.assign(n, 0.f);
            fb.insert(it.name(),
                      Imf::Slice::Make(Imf::FLOAT, v.data(), dw, sizeof(float), sizeof(float) * w));
        }
        Imf::InputPart ip(in, i);
        ip.setFrameBuffer(fb);
        ip.readPixels(dw.min.y, dw.max.y);
    }
    return parts;
}

void setIntOnAll(std::vector<RawPart>& parts, const char* name, int v) {
    for (RawPart& p : parts) p.header.insert(name, Imf::IntAttribute(v));
}

void writeRaw(const std::string& path, const std::vector<RawPart>& parts) {
    std::vector<Imf::Header> headers;
    for (const RawPart& p : parts) headers.push_back(p.header);
    Imf::MultiPartOutputFile out(path.c_str(), headers.data(), int(headers.size()));
    for (size_t i = 0; i < parts.size(); ++i) {
        const Imf::Header& h = parts[i].header;
        const Imath::Box2i dw = h.dataWindow();
        const size_t w = size_t(dw.max.x - dw.min.x + 1), ht = size_t(dw.max.y - dw.min.y + 1);
        const size_t n = w * ht;
        // Storage for every channel in its declared type (kept alive until written).
        std::vector<std::vector<float>> floats;
        std::vector<std::vector<half>> halves;
        std::vector<std::vector<unsigned>> uints;
        Imf::FrameBuffer fb;
        for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
            std::vector<float> v(n, 0.f);
            const auto found = parts[i].values.find(it.name());
            if (found != parts[i].values.end())
                for (size_t k = 0; k < n && k < found->second.size(); ++k) v[k] = found->second[k];
            const Imf::PixelType t = it.channel().type;
            char* base = nullptr;
            size_t elem = 0;
            if (t == Imf::FLOAT) {
                floats.push_back(std::move(v));
                base = reinterpret_cast<char*>(floats.back().data());
                elem = sizeof(float);
            } else if (t == Imf::HALF) {
                halves.emplace_back(v.begin(), v.end());
                base = reinterpret_cast<char*>(halves.back().data());
                elem = sizeof(half);
            } else {
                uints.emplace_back(v.begin(), v.end());
                base = reinterpret_cast<char*>(uints.back().data());
                elem = sizeof(unsigned);
            }
            fb.insert(it.name(), Imf::Slice::Make(t, base, dw, elem, elem * w));
        }
        if (h.type() == Imf::SCANLINEIMAGE) {
            Imf::OutputPart op(out, int(i));
            op.setFrameBuffer(fb);
            op.writePixels(int(ht));
        } else if (h.type() == Imf::TILEDIMAGE) {
            Imf::TiledOutputPart op(out, int(i));
            op.setFrameBuffer(fb);
            op.writeTiles(0, op.numXTiles() - 1, 0, op.numYTiles() - 1);
        } else {  // deep scanline: deepCounts samples per pixel (zero if not given)
            std::vector<unsigned> counts = parts[i].deepCounts;
            counts.resize(n, 0);
            size_t total = 0;
            for (unsigned c : counts) total += c;
            // Every channel as FLOAT samples, pixel after pixel (missing values are zero).
            std::map<std::string, std::vector<float>> samples;
            std::map<std::string, std::vector<float*>> pointers;
            Imf::DeepFrameBuffer dfb;
            dfb.insertSampleCountSlice(Imf::Slice::Make(Imf::UINT, counts.data(), dw,
                                                        sizeof(unsigned), sizeof(unsigned) * w));
            for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
                std::vector<float>& v = samples[it.name()];
                v.assign(total + 1, 0.f);
                const auto found = parts[i].values.find(it.name());
                if (found != parts[i].values.end())
                    for (size_t k = 0; k < total && k < found->second.size(); ++k)
                        v[k] = found->second[k];
                std::vector<float*>& ptr = pointers[it.name()];
                ptr.resize(n);
                size_t k = 0;
                for (size_t p = 0; p < n; ++p) {
                    ptr[p] = v.data() + k;
                    k += counts[p];
                }
                dfb.insert(it.name(),
                           Imf::DeepSlice(Imf::FLOAT,
                                          reinterpret_cast<char*>(ptr.data()) -
                                              (dw.min.x + dw.min.y * ptrdiff_t(w)) * sizeof(float*),
                                          sizeof(float*), sizeof(float*) * w, sizeof(float)));
            }
            Imf::DeepScanLineOutputPart op(out, int(i));
            op.setFrameBuffer(dfb);
            op.writePixels(int(ht));
        }
    }
}

}  // namespace mcstat::test
