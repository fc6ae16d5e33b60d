// OpenImageIO reader plugin for mcstat statistics files (docs/plugin.md).
//
// Opening a statistics file in any OIIO tool gives an ordinary image: subimage 0 is the robust
// estimate (G-MoN by default) computed through the operation registry exactly as `mcstat FILE
// --gmon` computes it (any registry operation: `?estimator=3dwtmf` as `mcstat FILE --3dwtmf`);
// subimages 1..3 are the stored plain mean, the estimator's diagnostics and the first-hit features.
// Everything is computed in open(); reads copy rows out of memory.
//
// Parameters come from the open() configuration (oiiotool --iconfig mcstat:estimator mon,
// --iconfig mcstat:mode channel) and from the file-name form
// "file.mcstat?estimator=mon&mode=channel" (tools without --iconfig); the file name wins. No
// exception leaves this file: every virtual catches and reports through errorfmt().
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "mcstat/color.h"
#include "mcstat/imageops.h"
#include "mcstat/registry.h"
#include "mcstat/stats_file.h"

#ifndef MCSTAT_VERSION
#define MCSTAT_VERSION "unknown"
#endif

OIIO_PLUGIN_NAMESPACE_BEGIN

namespace {

using Strutil::fmt::format;

/// The estimator used when none is configured.
constexpr const char* kDefaultEstimator = "gmon";
/// Prefix of the configuration attributes the plugin reads.
constexpr const char* kConfigPrefix = "mcstat:";
/// Subimages, in order.
enum Subimage { kRobust = 0, kMean = 1, kDiagnostics = 2, kFeatures = 3, kSubimageCount = 4 };

/// Every registry operation: per-pixel estimators, neighbourhood filters, per-sample operations.
std::string acceptedEstimators() {
    std::string s;
    for (const mcstat::Operation& op : mcstat::operationRegistry())
        s += (s.empty() ? "" : ", ") + op.name;
    return s;
}

/// Text of a configuration value as the user typed it. oiiotool --iconfig turns "0.3" into a float
/// attribute; "{}" prints the shortest text that reads back as the same float.
std::string configValue(const ParamValue& p) {
    if (p.type() == TypeFloat) return format("{}", p.get_float());
    if (p.type() == TypeInt) return format("{}", p.get_int());
    return p.get_string();
}

/// Splits "path?key=value&..." into the path and the keys, unless a file of that exact name exists.
bool splitName(const std::string& name, std::string& path, std::map<std::string, std::string>& kv) {
    path = name;
    if (name.find('?') == std::string::npos || Filesystem::exists(name)) return true;
    return Strutil::get_rest_arguments(name, path, kv);
}

class McstatInput final : public ImageInput {
  public:
    McstatInput() = default;
    ~McstatInput() override { reset(); }
    const char* format_name() const override { return "mcstat"; }
    int supports(string_view) const override { return false; }
    bool valid_file(const std::string& filename) const override;
    bool open(const std::string& name, ImageSpec& newspec) override;
    bool open(const std::string& name, ImageSpec& newspec, const ImageSpec& config) override;
    bool close() override;
    int current_subimage() const override {
        lock_guard guard(*this);
        return m_current;
    }
    bool seek_subimage(int subimage, int miplevel) override;
    bool read_native_scanline(int subimage, int miplevel, int y, int z, void* data) override;
    bool read_native_scanlines(int subimage, int miplevel, int ybegin, int yend, int z,
                               void* data) override;
    bool read_native_scanlines(int subimage, int miplevel, int ybegin, int yend, int z, int chbegin,
                               int chend, void* data) override;

  private:
    struct Sub {
        ImageSpec spec;
        std::vector<float> pixels;  ///< spec.width * spec.height * spec.nchannels, scanline order
    };
    std::array<Sub, kSubimageCount> m_subs;
    /// Subimages this file has: kSubimageCount, or one fewer when it holds no features (an
    /// ingested render without G-buffer AOVs: FORMAT.md version 3, mcstat:features empty).
    int m_nsubs = kSubimageCount;
    int m_current = -1;
    std::string m_name;  ///< as passed to open(), for messages

    void reset() {
        for (Sub& s : m_subs) s = Sub();
        m_nsubs = kSubimageCount;
        m_current = -1;
        m_name.clear();
        m_spec = ImageSpec();
    }
    bool openImpl(const std::string& name, ImageSpec& newspec, const ImageSpec& config);
    bool copyRows(int subimage, int miplevel, int ybegin, int yend, int chbegin, int chend,
                  void* data);
};

bool McstatInput::valid_file(const std::string& filename) const {
    try {
        std::string path;
        std::map<std::string, std::string> kv;
        if (!splitName(filename, path, kv)) return false;
        if (Strutil::lower(Filesystem::extension(path, false)) != mcstat::kStatsExtension)
            return false;
        FILE* f = Filesystem::fopen(path, "rb");
        if (!f) return false;
        unsigned char magic[4] = {0, 0, 0, 0};
        const size_t n = std::fread(magic, 1, 4, f);
        std::fclose(f);
        // OpenEXR magic number 20000630 (little endian): the statistics file is an OpenEXR file.
        return n == 4 && magic[0] == 0x76 && magic[1] == 0x2f && magic[2] == 0x31 &&
               magic[3] == 0x01;
    } catch (...) {
        return false;
    }
}

bool McstatInput::open(const std::string& name, ImageSpec& newspec) {
    try {
        return open(name, newspec, ImageSpec());
    } catch (const std::exception& e) {
        errorfmt("{}: {}", name, e.what());
    } catch (...) {
        errorfmt("{}: unknown error", name);
    }
    return false;
}

bool McstatInput::open(const std::string& name, ImageSpec& newspec, const ImageSpec& config) {
    try {
        lock_guard guard(*this);
        if (openImpl(name, newspec, config)) return true;
    } catch (const std::exception& e) {
        errorfmt("{}: {}", name, e.what());
    } catch (...) {
        errorfmt("{}: unknown error", name);
    }
    reset();
    return false;
}

bool McstatInput::openImpl(const std::string& name, ImageSpec& newspec, const ImageSpec& config) {
    reset();
    m_name = name;

    // Parameters: the configuration first, then the file name (which wins).
    std::map<std::string, std::string> kv;
    const size_t prefixLen = std::strlen(kConfigPrefix);
    for (const ParamValue& p : config.extra_attribs) {
        const std::string attr = p.name().string();
        if (attr.size() > prefixLen && Strutil::istarts_with(attr, kConfigPrefix))
            kv[attr.substr(prefixLen)] = configValue(p);
    }
    std::string path;
    std::map<std::string, std::string> fromName;
    if (!splitName(name, path, fromName)) {
        errorfmt("{}: cannot parse the parameters after '?' (expected key=value&key=value)", name);
        return false;
    }
    for (const auto& [k, v] : fromName) kv[k] = v;

    std::string estName = kDefaultEstimator;
    if (auto it = kv.find("estimator"); it != kv.end()) {
        estName = it->second;
        kv.erase(it);
    }
    const mcstat::Operation* est = mcstat::findOperation(estName);
    if (!est) {
        errorfmt("{}: unknown estimator '{}' (accepted: {})", path, estName, acceptedEstimators());
        return false;
    }
    mcstat::ParamValues values;
    std::string err;
    if (!mcstat::parseOperationParams(*est, kv, values, err, "estimator '" + est->name + "'")) {
        errorfmt("{}: {}; the plugin also takes 'estimator' (one of: {})", path, err,
                 acceptedEstimators());
        return false;
    }
    const std::array<double, 3> luma = mcstat::lumaCoefficients();

    // The file, validated (the message names the file).
    mcstat::StatsImage stats;
    if (!mcstat::readStatsFile(path, stats, err)) {
        errorfmt("{}", err);
        return false;
    }
    const mcstat::StatsHeader& h = stats.header;
    const size_t npix = stats.pixelCount();

    // Subimage 0 and the diagnostics in one pass: every operation returns R, G, B first; an
    // estimator over buffer means (with diagnostics) its gini/kept/excluded channels after them,
    // computed by the same per-pixel call as without them. Neighbourhood operations run over the
    // sub-buffers (3D filters) or over the stored mean (MIF, WMIF); per-sample operations stream
    // the file themselves (docs/plugin.md).
    OIIO::ImageBuf robust;
    const bool ok =
        est->input == mcstat::InputKind::Samples
            ? mcstat::runSamplesOperation(robust, path, h, *est, values, luma, threads())
            : mcstat::applyOperation(robust, stats, *est, values, luma, true, {}, threads());
    if (!ok) {
        errorfmt("{}: {}", path, robust.geterror());
        return false;
    }
    const int estCh = robust.nchannels();
    const float* estPix = static_cast<const float*>(robust.localpixels());
    if (!estPix || size_t(robust.spec().image_pixels()) != npix || estCh < 3) {
        errorfmt("{}: the estimate has an unexpected layout", path);
        return false;
    }

    // Shared specification: data window, float pixels, the file's header attributes.
    auto makeSpec = [&](const std::vector<std::string>& channels, const char* subname) {
        ImageSpec s(h.width, h.height, int(channels.size()), TypeFloat);
        s.x = s.full_x = h.originX;
        s.y = s.full_y = h.originY;
        s.channelnames = channels;
        s.attribute("oiio:subimagename", subname);
        s.attribute("oiio:subimages", m_nsubs);
        s.attribute("mcstat:formatVersion", h.formatVersion);
        s.attribute("mcstat:M", h.M);
        if (h.adaptiveM) s.attribute("mcstat:adaptiveM", 1);
        s.attribute("mcstat:spp", int(std::min<int64_t>(h.spp, INT32_MAX)));
        s.attribute("mcstat:assignment", h.assignment);
        if (h.formatVersion >= mcstat::kStatsFormatVersionProvenance) {
            s.attribute("mcstat:variance", h.variance);
            s.attribute("mcstat:features", mcstat::featureListText(h.features));
            s.attribute("mcstat:sources", h.sources);
        }
        s.attribute("mcstat:renderer", h.renderer);
        s.attribute("mcstat:colorSpace", h.colorSpace);
        s.attribute("mcstat:seeds", h.seeds);
        return s;
    };
    auto describeEstimator = [&](ImageSpec& s) {
        s.attribute("mcstat:estimator", est->name);
        for (const mcstat::ParamSpec* pi : est->settable()) {
            auto it = kv.find(pi->name);
            s.attribute("mcstat:" + pi->name, it != kv.end() ? it->second : pi->defaultValue);
        }
    };

    // 0: the robust estimate.
    const std::string meanName = est->name == "mean" ? "beauty" : "mean";
    Sub& r = m_subs[kRobust];
    r.spec = makeSpec({"R", "G", "B"}, est->name.c_str());
    r.spec.attribute("oiio:ColorSpace", h.colorSpace);
    describeEstimator(r.spec);
    r.pixels.resize(npix * 3);
    // 2: diagnostics: the estimator's gini/kept/excluded channels plus the sample count, and with
    // adaptive M the map of buffer counts m_p ("M").
    std::vector<std::string> diagNames(robust.spec().channelnames.begin() + 3,
                                       robust.spec().channelnames.end());
    diagNames.push_back("count");
    if (h.adaptiveM) diagNames.push_back("M");
    Sub& d = m_subs[kDiagnostics];
    d.spec = makeSpec(diagNames, "diagnostics");
    describeEstimator(d.spec);
    const size_t dch = diagNames.size();

    d.pixels.resize(npix * dch);
    for (size_t p = 0; p < npix; ++p) {
        const float* src = estPix + p * size_t(estCh);
        std::copy(src, src + 3, &r.pixels[p * 3]);
        std::copy(src + 3, src + estCh, &d.pixels[p * dch]);
        d.pixels[p * dch + estCh - 3] = stats.count[p];
        if (h.adaptiveM) d.pixels[p * dch + dch - 1] = float(stats.buffersOf(p));
    }
    robust.reset();

    // 1: the plain mean as stored (part "beauty").
    Sub& m = m_subs[kMean];
    m.spec = makeSpec({"R", "G", "B"}, meanName.c_str());
    m.spec.attribute("oiio:ColorSpace", h.colorSpace);
    m.pixels = std::move(stats.beauty);

    // 3: first-hit features, only those the file holds (version 3 records absent ones as NaN).
    struct FeatureChannel {
        const char* name;
        unsigned feature;
        const std::vector<float>* array;
        size_t stride, offset;
    };
    const FeatureChannel all[] = {{"N.X", mcstat::kFeatureNormal, &stats.normal, 3, 0},
                                  {"N.Y", mcstat::kFeatureNormal, &stats.normal, 3, 1},
                                  {"N.Z", mcstat::kFeatureNormal, &stats.normal, 3, 2},
                                  {"P.X", mcstat::kFeaturePosition, &stats.position, 3, 0},
                                  {"P.Y", mcstat::kFeaturePosition, &stats.position, 3, 1},
                                  {"P.Z", mcstat::kFeaturePosition, &stats.position, 3, 2},
                                  {"Albedo.R", mcstat::kFeatureAlbedo, &stats.albedo, 3, 0},
                                  {"Albedo.G", mcstat::kFeatureAlbedo, &stats.albedo, 3, 1},
                                  {"Albedo.B", mcstat::kFeatureAlbedo, &stats.albedo, 3, 2},
                                  {"Z", mcstat::kFeatureDepth, &stats.depth, 1, 0},
                                  {"A", mcstat::kFeatureCoverage, &stats.coverage, 1, 0}};
    std::vector<const FeatureChannel*> present;
    std::vector<std::string> featureNames;
    for (const FeatureChannel& c : all)
        if (h.features & c.feature) {
            present.push_back(&c);
            featureNames.push_back(c.name);
        }
    if (present.empty()) {
        m_nsubs = kFeatures;  // no features subimage; the specs made above say so too
        for (int i = 0; i < kFeatures; ++i)
            m_subs[size_t(i)].spec.attribute("oiio:subimages", m_nsubs);
    } else {
        Sub& f = m_subs[kFeatures];
        f.spec = makeSpec(featureNames, "features");
        const size_t nf = present.size();
        f.pixels.resize(npix * nf);
        for (size_t p = 0; p < npix; ++p)
            for (size_t i = 0; i < nf; ++i)
                f.pixels[p * nf + i] =
                    (*present[i]->array)[p * present[i]->stride + present[i]->offset];
    }

    m_current = kRobust;
    m_spec = m_subs[kRobust].spec;
    newspec = m_spec;
    return true;
}

bool McstatInput::close() {
    try {
        lock_guard guard(*this);
        reset();
    } catch (...) {
    }
    return true;
}

bool McstatInput::seek_subimage(int subimage, int miplevel) {
    try {
        lock_guard guard(*this);
        if (m_current < 0 || subimage < 0 || subimage >= m_nsubs || miplevel != 0) return false;
        if (subimage != m_current) {
            m_current = subimage;
            m_spec = m_subs[subimage].spec;
        }
        return true;
    } catch (const std::exception& e) {
        errorfmt("{}: {}", m_name, e.what());
    } catch (...) {
        errorfmt("{}: unknown error", m_name);
    }
    return false;
}

bool McstatInput::copyRows(int subimage, int miplevel, int ybegin, int yend, int chbegin, int chend,
                           void* data) {
    lock_guard guard(*this);
    if (m_current < 0 || subimage < 0 || subimage >= m_nsubs || miplevel != 0) {
        errorfmt("{}: no subimage {} MIP level {}", m_name, subimage, miplevel);
        return false;
    }
    const Sub& s = m_subs[subimage];
    const ImageSpec& sp = s.spec;
    if (chend < 0) chend = sp.nchannels;  // all channels
    if (ybegin < sp.y || yend > sp.y + sp.height || ybegin > yend || chbegin < 0 ||
        chend > sp.nchannels || chbegin >= chend) {
        errorfmt("{}: scanlines {}..{} channels {}..{} are outside subimage {}", m_name, ybegin,
                 yend, chbegin, chend, subimage);
        return false;
    }
    const size_t w = size_t(sp.width), nch = size_t(sp.nchannels), nsel = size_t(chend - chbegin);
    float* out = static_cast<float*>(data);
    for (int y = ybegin; y < yend; ++y) {
        const float* row = &s.pixels[size_t(y - sp.y) * w * nch];
        if (nsel == nch) {
            std::memcpy(out, row, w * nch * sizeof(float));
            out += w * nch;
        } else {
            for (size_t x = 0; x < w; ++x, out += nsel)
                std::memcpy(out, row + x * nch + size_t(chbegin), nsel * sizeof(float));
        }
    }
    return true;
}

bool McstatInput::read_native_scanline(int subimage, int miplevel, int y, int, void* data) {
    try {
        return copyRows(subimage, miplevel, y, y + 1, 0, -1, data);
    } catch (const std::exception& e) {
        errorfmt("{}: {}", m_name, e.what());
    } catch (...) {
        errorfmt("{}: unknown error", m_name);
    }
    return false;
}

bool McstatInput::read_native_scanlines(int subimage, int miplevel, int ybegin, int yend, int,
                                        void* data) {
    try {
        return copyRows(subimage, miplevel, ybegin, yend, 0, -1, data);
    } catch (const std::exception& e) {
        errorfmt("{}: {}", m_name, e.what());
    } catch (...) {
        errorfmt("{}: unknown error", m_name);
    }
    return false;
}

bool McstatInput::read_native_scanlines(int subimage, int miplevel, int ybegin, int yend, int,
                                        int chbegin, int chend, void* data) {
    try {
        return copyRows(subimage, miplevel, ybegin, yend, chbegin, chend, data);
    } catch (const std::exception& e) {
        errorfmt("{}: {}", m_name, e.what());
    } catch (...) {
        errorfmt("{}: unknown error", m_name);
    }
    return false;
}

}  // namespace

OIIO_PLUGIN_EXPORTS_BEGIN

OIIO_EXPORT int mcstat_imageio_version = OIIO_PLUGIN_VERSION;

OIIO_EXPORT const char* mcstat_imageio_library_version() { return "mcstat " MCSTAT_VERSION; }

OIIO_EXPORT ImageInput* mcstat_input_imageio_create() {
    try {
        return new McstatInput;
    } catch (...) {
        return nullptr;
    }
}

OIIO_EXPORT const char* mcstat_input_extensions[] = {mcstat::kStatsExtension, nullptr};

OIIO_PLUGIN_EXPORTS_END

OIIO_PLUGIN_NAMESPACE_END
