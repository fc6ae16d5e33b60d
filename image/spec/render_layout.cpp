// Drop-in outputs: the input render's names, parts, windows and metadata (render_layout.h).
#include "mcstat/image/spec/render_layout.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>

#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/temp_file.h"

namespace mcstat {

using OIIO::ImageSpec;
using OIIO::TypeDesc;
using OIIO::Strutil::fmt::format;

namespace {

/// Attributes that describe the file's encoding or OIIO's bookkeeping, not the render.
bool isEncodingAttribute(const std::string& name) {
    namespace SU = OIIO::Strutil;
    const std::string lower = SU::lower(name);
    for (const char* prefix : {"oiio:", "openexr:", "mcstat:", "mcstat.", "tiff:", "png:", "jpeg:"})
        if (SU::starts_with(lower, prefix)) return true;
    for (const char* n :
         {"compression", "planarconfig", "tile_width", "tile_height", "tiledesc", "lineorder",
          "chunkcount", "name", "type", "version", "channels", "datawindow", "displaywindow",
          "dwacompressionlevel", "zipcompressionlevel", "openexr_chunkcount"})
        if (lower == n) return true;
    return false;
}

std::string oneLine(std::string s) {
    std::replace(s.begin(), s.end(), '\n', ' ');
    return s;
}

}  // namespace

std::string sourceMetadataJson(const ImageSpec& spec) {
    nlohmann::json list = nlohmann::json::array();
    for (const OIIO::ParamValue& pv : spec.extra_attribs) {
        const std::string name = pv.name().string();
        if (isEncodingAttribute(name)) continue;
        // The type as it is written: several values of a type are one array of it, and a type
        // whose name does not parse back to itself (an odd one from a damaged or unusual file)
        // is left out rather than stored as something applySourceMetadata would read otherwise.
        TypeDesc t = pv.type();
        if (pv.nvalues() > 1) t.arraylen = int(t.numelements()) * pv.nvalues();
        if (TypeDesc(t.c_str()) != t) continue;
        const size_t n = t.numelements() * t.aggregate;
        nlohmann::json values = nlohmann::json::array();
        switch (t.basetype) {
            case TypeDesc::STRING: {
                const auto* u = static_cast<const OIIO::ustring*>(pv.data());
                for (size_t i = 0; i < n; ++i) values.push_back(u[i].string());
                break;
            }
            case TypeDesc::FLOAT:
            case TypeDesc::DOUBLE:
            case TypeDesc::HALF: {
                // Raw values converted as a whole (ParamValue's indexed getters do not read
                // aggregates such as matrices).
                std::vector<float> f(n);
                TypeDesc one(TypeDesc::BASETYPE(t.basetype));
                if (!OIIO::convert_type(one, pv.data(), TypeDesc::FLOAT, f.data(), int(n)))
                    continue;
                // JSON has no NaN or infinity (nlohmann writes null): those are the strings
                // "nan", "inf" and "-inf", which applySourceMetadata reads back.
                for (float x : f) {
                    if (std::isfinite(x))
                        values.push_back(x);
                    else
                        values.push_back(std::isnan(x) ? "nan" : x > 0 ? "inf" : "-inf");
                }
                break;
            }
            case TypeDesc::INT8:
            case TypeDesc::UINT8:
            case TypeDesc::INT16:
            case TypeDesc::UINT16:
            case TypeDesc::INT32:
            case TypeDesc::UINT32: {
                std::vector<int> v(n);
                TypeDesc one(TypeDesc::BASETYPE(t.basetype));
                if (!OIIO::convert_type(one, pv.data(), TypeDesc::INT32, v.data(), int(n)))
                    continue;
                for (int x : v) values.push_back(x);
                break;
            }
            default:
                continue;  // pointers, 64-bit integers: nothing a render's header needs
        }
        list.push_back({{"name", name}, {"type", t.c_str()}, {"values", values}});
    }
    // A renderer's string attribute is bytes, not always UTF-8 (a fuzzed file, a Latin-1 artist
    // name): invalid sequences become U+FFFD rather than an exception out of ingest.
    return list.empty() ? std::string()
                        : list.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

bool applySourceMetadata(ImageSpec& spec, const std::string& json, std::string& err) {
    if (json.empty()) return true;
    const nlohmann::json list = nlohmann::json::parse(json, nullptr, false);
    if (list.is_discarded() || !list.is_array()) {
        err = "source metadata is not a JSON list";
        return false;
    }
    ImageSpec staged;
    for (const nlohmann::json& a : list) {
        if (!a.is_object() || !a.contains("name") || !a["name"].is_string() ||
            !a.contains("type") || !a["type"].is_string() || !a.contains("values") ||
            !a["values"].is_array()) {
            err = "source metadata: an entry without name, type and values";
            return false;
        }
        const std::string name = a["name"];
        const TypeDesc t(a["type"].get<std::string>());
        const nlohmann::json& v = a["values"];
        const size_t n = t.numelements() * t.aggregate;
        if (t.basetype == TypeDesc::UNKNOWN || v.size() != n || n == 0 || n > 4096) {
            err = format("source metadata: '{}' has {} values for type '{}'", printable(name),
                         v.size(), printable(a["type"].get<std::string>()));
            return false;
        }
        if (t.basetype == TypeDesc::STRING) {
            std::vector<std::string> s;
            std::vector<OIIO::ustring> u;
            for (const auto& e : v) {
                if (!e.is_string()) {
                    err = format("source metadata: '{}' holds a non-string", printable(name));
                    return false;
                }
                u.emplace_back(e.get<std::string>());
            }
            staged.attribute(name, t, u.data());
        } else if (t.basetype == TypeDesc::FLOAT || t.basetype == TypeDesc::DOUBLE ||
                   t.basetype == TypeDesc::HALF) {
            std::vector<float> f;
            for (const auto& e : v) {
                if (e.is_number()) {
                    f.push_back(e.get<float>());
                } else if (e == "nan" || e == "inf" || e == "-inf") {
                    f.push_back(e == "nan"   ? std::numeric_limits<float>::quiet_NaN()
                                : e == "inf" ? std::numeric_limits<float>::infinity()
                                             : -std::numeric_limits<float>::infinity());
                } else {
                    err = format("source metadata: '{}' holds a non-number", printable(name));
                    return false;
                }
            }
            TypeDesc ft = t;
            ft.basetype = TypeDesc::FLOAT;
            staged.attribute(name, ft, f.data());
        } else {
            std::vector<int> i;
            for (const auto& e : v) {
                if (!e.is_number_integer()) {
                    err = format("source metadata: '{}' holds a non-integer", printable(name));
                    return false;
                }
                i.push_back(e.get<int>());
            }
            TypeDesc it = t;
            it.basetype = t.basetype == TypeDesc::UINT32 ? TypeDesc::UINT32 : TypeDesc::INT32;
            staged.attribute(name, it, i.data());
        }
    }
    for (const OIIO::ParamValue& pv : staged.extra_attribs)
        spec.attribute(pv.name(), pv.type(), pv.data());
    return true;
}

namespace {

/// The renderers' own sample counts among the first render's attributes (those ingest reads:
/// pbrt-v4's samplesPerPixel, Cycles' cycles.<ViewLayer>.samples) say the result's samples per
/// pixel, all renders together, in the attribute's own type: a tool reading them must not take
/// one seed's count for the result's.
void setRendererSampleCounts(ImageSpec& spec, int64_t spp) {
    for (OIIO::ParamValue& pv : spec.extra_attribs) {
        const std::string n = pv.name().string();
        const bool count = n == "samplesPerPixel" || (OIIO::Strutil::starts_with(n, "cycles.") &&
                                                      OIIO::Strutil::ends_with(n, ".samples"));
        if (!count || pv.type().aggregate != 1 || pv.type().arraylen != 0) continue;
        if (pv.type() == OIIO::TypeString)
            pv = OIIO::ParamValue(pv.name(), OIIO::string_view(std::to_string(spp)));
        else if (pv.type() == OIIO::TypeInt)
            pv = OIIO::ParamValue(pv.name(), int(std::min<int64_t>(spp, INT32_MAX)));
    }
}

}  // namespace

void describeSource(ImageSpec& spec, const StatsHeader& h, std::string* warning) {
    std::string err;
    if (!applySourceMetadata(spec, h.sourceMetadata, err) && warning) *warning = err;
    setRendererSampleCounts(spec, h.spp);
    const std::string p = kProvenancePrefix;
    spec.attribute(p + "M", h.M);
    spec.attribute(p + "spp", int(std::min<int64_t>(h.spp, INT32_MAX)));
    if (!h.sources.empty()) spec.attribute(p + "sources", printable(h.sources, 0));
    if (!h.renderer.empty()) spec.attribute(p + "renderer", printable(h.renderer));
}

bool needsRenderLayout(const StatsHeader& h) {
    return !h.aovs.empty() || !h.beautyPart.empty() ||
           h.beautyNames != std::array<std::string, 3>{"R", "G", "B"};
}

bool parseWriteType(const std::string& text, TypeDesc& out) {
    if (text == "half")
        out = TypeDesc::HALF;
    else if (text == "float")
        out = TypeDesc::FLOAT;
    else
        return false;
    return true;
}

bool applyWriteOptions(ImageSpec& spec, const ImageWriteOptions& opt, const std::string& ext,
                       std::string& err) {
    spec.set_format(opt.type);
    spec.channelformats.clear();
    if (!opt.channelTypes.empty()) {
        for (const auto& [name, type] : opt.channelTypes)
            if (spec.channelindex(name) < 0) {
                err = format("-d {}=...: the image has no channel '{}' (channels: {})", name, name,
                             printableList(spec.channelnames));
                return false;
            }
        for (int c = 0; c < spec.nchannels; ++c) {
            const auto it = opt.channelTypes.find(spec.channel_name(c));
            spec.channelformats.push_back(it == opt.channelTypes.end() ? opt.type : it->second);
        }
    }
    spec.erase_attribute("compression");
    if (opt.compression.empty()) return true;
    if (!checkCompression(opt.compression, ext, err)) return false;
    spec.attribute("compression", opt.compression);
    return true;
}

bool checkCompression(const std::string& text, const std::string& ext, std::string& err) {
    const size_t colon = text.find(':');
    const std::string name = text.substr(0, colon);
    if (name.empty()) {
        err = format("compression '{}': no codec name before the level", printable(text));
        return false;
    }
    const bool exr = ext == "exr" || ext == "sxr" || ext == "mxr";
    if (exr) {
        static const char* known[] = {"none",  "rle", "zips", "zip",  "piz",
                                      "pxr24", "b44", "b44a", "dwaa", "dwab"};
        if (std::find(std::begin(known), std::end(known), name) == std::end(known)) {
            err = format(
                "compression '{}' is not one of OpenEXR's (none, rle, zips, zip, piz, "
                "pxr24, b44, b44a, dwaa, dwab)",
                printable(name));
            return false;
        }
    }
    if (colon == std::string::npos) return true;
    // OIIO reads the level as an integer and ignores what it cannot use, silently: "dwaa:abc"
    // and "dwaa:-5" wrote level 45, "dwaa:1e9" level 1. Every level is checked here instead.
    const std::string level = text.substr(colon + 1);
    const bool dwa = name == "dwaa" || name == "dwab", zip = name == "zip" || name == "zips";
    if (exr && !dwa && !zip) {
        err =
            format("compression '{}': OpenEXR's {} takes no level (only zip, zips, dwaa, dwab do)",
                   printable(text), name);
        return false;
    }
    const long hi = !exr ? 100 : zip ? 9 : 1000000, lo = exr ? 1 : 0;
    const bool digits = !level.empty() && level.size() <= 7 &&
                        level.find_first_not_of("0123456789") == std::string::npos;
    const long v = digits ? std::stol(level) : -1;
    if (!digits || v < lo || v > hi) {
        err = format("compression '{}': the level must be a whole number {}..{}{}, not '{}'",
                     printable(text), lo, hi,
                     !exr  ? std::string(" (PNG and TIFF zip 0..9, JPEG quality 1..100)")
                     : zip ? std::string(" (zlib's levels)")
                           : std::string(" (DWA quantisation; OpenEXR's default is 45)"),
                     printable(level));
        return false;
    }
    return true;
}

size_t halfOverflow(const OIIO::ImageBuf& img, const ImageSpec& spec) {
    size_t n = 0;
    const ImageSpec& src = img.spec();
    std::vector<float> v(size_t(src.width) * size_t(src.height));
    for (int c = 0; c < spec.nchannels && c < src.nchannels; ++c) {
        if (spec.channelformat(c) != TypeDesc::HALF) continue;
        if (!img.get_pixels(
                OIIO::ROI(src.x, src.x + src.width, src.y, src.y + src.height, 0, 1, c, c + 1),
                TypeDesc::FLOAT, v.data()))
            continue;
        for (float x : v)
            if (std::isfinite(x) && std::fabs(x) > 65504.f) ++n;
    }
    return n;
}

namespace {

/// Which part of the render each channel of `src` goes to (in channel order), and its name there:
/// R, G, B the render's beauty names in its beauty part, an AOV its own part, a residual
/// (appendResidual) beside its channel, named after the render's name.
void renderPlaces(const ImageSpec& src, const StatsHeader& layout, std::vector<std::string>& partOf,
                  std::vector<std::string>& nameOf) {
    partOf.assign(size_t(src.nchannels), layout.beautyPart);
    nameOf = src.channelnames;
    for (int c = 0; c < 3; ++c) nameOf[size_t(c)] = layout.beautyNames[size_t(c)];
    for (int c = 3; c < src.nchannels; ++c) {
        std::string n = src.channelnames[size_t(c)];
        const bool residual = OIIO::Strutil::starts_with(n, "residual.");
        if (residual) n = n.substr(9);
        const int a = layout.aovIndex(n);
        if (a >= 0) partOf[size_t(c)] = layout.aovs[size_t(a)].part;
        if (residual)
            for (int b = 0; b < 3; ++b)
                if (n == "RGB"[b] + std::string())
                    nameOf[size_t(c)] = "residual." + layout.beautyNames[size_t(b)];
    }
}

}  // namespace

bool writeRenderLike(const OIIO::ImageBuf& img, const StatsHeader& layout, const std::string& path,
                     const ImageWriteOptions& opt, std::string& err, size_t* overflow) {
    if (!checkOutputTarget(path, err)) return false;
    const ImageSpec& src = img.spec();
    if (src.nchannels < 3 || src.deep) {
        err = format("{}: the image has no R, G, B to write as the render's beauty", path);
        return false;
    }
    std::vector<std::string> partOf, nameOf;
    renderPlaces(src, layout, partOf, nameOf);
    std::vector<std::string> parts;  // in order of first channel, the beauty's first
    for (const std::string& p : partOf)
        if (std::find(parts.begin(), parts.end(), p) == parts.end()) parts.push_back(p);
    const std::string ext = OIIO::Strutil::lower(OIIO::Filesystem::extension(path, false));
    std::unique_ptr<OIIO::ImageOutput> out = OIIO::ImageOutput::create(ext);
    if (!out) {
        (void)OIIO::geterror();
        err = format("{}: OpenImageIO has no writer for '.{}' files", path, ext);
        return false;
    }
    if (parts.size() > 1 && !out->supports("multiimage")) {
        err =
            format("{}: the render had {} parts ({}...), which a .{} file cannot hold; write .exr",
                   path, parts.size(), parts[1], ext);
        return false;
    }
    std::vector<ImageSpec> specs;
    std::vector<std::vector<int>> channelsOf;
    for (const std::string& part : parts) {
        std::vector<int> chans;
        for (int c = 0; c < src.nchannels; ++c)
            if (partOf[size_t(c)] == part) chans.push_back(c);
        ImageSpec s = src;
        s.nchannels = int(chans.size());
        s.channelnames.clear();
        s.channelformats.clear();
        s.alpha_channel = -1;
        s.z_channel = -1;
        for (size_t i = 0; i < chans.size(); ++i) {
            s.channelnames.push_back(nameOf[size_t(chans[i])]);
            if (chans[i] == src.alpha_channel) s.alpha_channel = int(i);
        }
        if (!applyWriteOptions(s, opt, ext, err)) {
            err = format("{}: {}", path, err);
            return false;
        }
        // In-memory bookkeeping of which channels are AOVs (imageops.h), not the render's.
        s.erase_attribute("mcstat:firstAov");
        s.erase_attribute("mcstat:aovClasses");
        if (parts.size() > 1)
            s.attribute("oiio:subimagename", part.empty() ? std::string("rgba") : part);
        specs.push_back(std::move(s));
        channelsOf.push_back(std::move(chans));
    }
    TemporaryFile tmp(path);
    const auto fail = [&](const std::string& why) {
        err = format("{}: {}", path,
                     oneLine(OIIO::Strutil::replace(why.empty() ? "the writer failed" : why,
                                                    tmp.path(), path, true)));
        return false;
    };
    if (!out->open(tmp.path(), int(specs.size()), specs.data())) return fail(out->geterror());
    std::vector<float> pixels;
    for (size_t i = 0; i < specs.size(); ++i) {
        if (i > 0 && !out->open(tmp.path(), specs[i], OIIO::ImageOutput::AppendSubimage))
            return fail(out->geterror());
        const std::vector<int>& chans = channelsOf[i];
        const size_t npix = size_t(src.width) * size_t(src.height);
        pixels.assign(npix * chans.size(), 0.f);
        std::vector<float> one(npix);
        for (size_t k = 0; k < chans.size(); ++k) {
            if (!img.get_pixels(OIIO::ROI(src.x, src.x + src.width, src.y, src.y + src.height, 0, 1,
                                          chans[k], chans[k] + 1),
                                TypeDesc::FLOAT, one.data()))
                return fail(img.geterror());
            for (size_t q = 0; q < npix; ++q) pixels[q * chans.size() + k] = one[q];
        }
        if (overflow) {
            // The part's channels (float, as gathered) against the part's formats.
            ImageSpec asFloat = specs[i];
            asFloat.set_format(TypeDesc::FLOAT);
            asFloat.channelformats.clear();
            const OIIO::ImageBuf part(asFloat, pixels.data());
            *overflow += halfOverflow(part, specs[i]);
        }
        if (!out->write_image(TypeDesc::FLOAT, pixels.data())) return fail(out->geterror());
    }
    if (!out->close()) return fail(out->geterror());
    return tmp.commit(err);
}

}  // namespace mcstat
