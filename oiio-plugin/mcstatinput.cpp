// OpenImageIO reader plugin for mcstat statistics files (docs/plugin.md).
//
// Opening a statistics file in any OIIO tool gives an ordinary image: subimage 0 is the robust
// estimate (G-MoN by default) computed through the operation registry exactly as `mcstat FILE
// --gmon` computes it (any registry operation: `?estimator=3dwtmf` as `mcstat FILE --3dwtmf`);
// subimages 1..3 are the stored plain mean, the estimator's diagnostics and the first-hit features.
//
// open() reads the headers only. A subimage's pixels are computed when first read, streaming the
// file by blocks of rows (StatsFileReader), and kept in a process-wide cache (PixelCache) keyed by
// the file's identity and the operation: oiiotool opens a file twice and iv reopens it on every
// subimage switch, yet each file is decoded once per process and only the subimages asked for.
//
// Parameters come from the open() configuration (oiiotool --iconfig mcstat:estimator mon,
// --iconfig mcstat:mode channel) and from the file-name form
// "file.mcstat?estimator=mon&mode=channel" (tools without --iconfig); the file name wins. No
// exception leaves this file: every entry point runs its work through guardEntry(), which records
// what was thrown on the ImageInput (errorfmt) and returns the entry point's failure value.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <functional>
#include <future>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "mcstat/color/color.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/keep_light_image.h"
#include "mcstat/image/operation_input.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/version.h"

OIIO_PLUGIN_NAMESPACE_BEGIN

namespace {

using Strutil::fmt::format;

/// The estimator used when none is configured.
constexpr const char* kDefaultEstimator = "gmon";
/// Prefix of the configuration attributes the plugin reads.
constexpr const char* kConfigPrefix = "mcstat:";
/// The one guard of the plugin boundary: `body()`, or, when it throws, `fallback` after
/// `onError(what was thrown)` (itself guarded). No exception leaves an entry point of this file.
template <class T, class Body, class OnError>
T guardEntry(T fallback, Body&& body, OnError&& onError) noexcept {
    try {
        return body();
    } catch (const std::exception& e) {
        try {
            onError(e.what());
        } catch (...) {
        }
    } catch (...) {
        try {
            onError("unknown error");
        } catch (...) {
        }
    }
    return fallback;
}

/// guardEntry()'s onError for entry points that report nothing (a probe, close, the factory).
void ignoreError(const char*) {}

/// Subimages, in order.
enum Subimage { kRobust = 0, kMean = 1, kDiagnostics = 2, kFeatures = 3, kSubimageCount = 4 };

/// The first-hit feature channels in file order, with where a StatsImage holds them.
struct FeatureChannel {
    const char* name;
    unsigned feature;
    std::vector<float> mcstat::StatsImage::*array;
    size_t stride, offset;
};
const FeatureChannel kFeatureChannels[] = {
    {"N.X", mcstat::kFeatureNormal, &mcstat::StatsImage::normal, 3, 0},
    {"N.Y", mcstat::kFeatureNormal, &mcstat::StatsImage::normal, 3, 1},
    {"N.Z", mcstat::kFeatureNormal, &mcstat::StatsImage::normal, 3, 2},
    {"P.X", mcstat::kFeaturePosition, &mcstat::StatsImage::position, 3, 0},
    {"P.Y", mcstat::kFeaturePosition, &mcstat::StatsImage::position, 3, 1},
    {"P.Z", mcstat::kFeaturePosition, &mcstat::StatsImage::position, 3, 2},
    {"Albedo.R", mcstat::kFeatureAlbedo, &mcstat::StatsImage::albedo, 3, 0},
    {"Albedo.G", mcstat::kFeatureAlbedo, &mcstat::StatsImage::albedo, 3, 1},
    {"Albedo.B", mcstat::kFeatureAlbedo, &mcstat::StatsImage::albedo, 3, 2},
    {"Z", mcstat::kFeatureDepth, &mcstat::StatsImage::depth, 1, 0},
    {"A", mcstat::kFeatureCoverage, &mcstat::StatsImage::coverage, 1, 0}};

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

/// Pixels a subimage is served from: `channels` interleaved per pixel, scanline order, held in
/// `pixels` or (an operation's result, kept without a copy) in `image`.
struct Computed {
    std::vector<std::string> channels;
    std::vector<float> pixels;
    OIIO::ImageBuf image;
    const float* data() const {
        return image.initialized() ? static_cast<const float*>(image.localpixels()) : pixels.data();
    }
    size_t size() const {
        return image.initialized() ? size_t(image.spec().image_pixels()) * size_t(image.nchannels())
                                   : pixels.size();
    }
};
using ComputedPtr = std::shared_ptr<const Computed>;

/// Process-wide cache of computed pixels, least recently used first out once it holds more than
/// its budget (MCSTAT_PLUGIN_CACHE_MB, default 2048 MiB; 0 disables keeping anything). A key is
/// computed once: concurrent requests for it wait for the first one's result.
class PixelCache {
  public:
    static PixelCache& instance() {
        static PixelCache cache;
        return cache;
    }

    /// The pixels of `key`, made by `make` (which returns false with `err`) unless cached.
    /// Failures are not kept: the next request tries again.
    ComputedPtr get(const std::string& key,
                    const std::function<bool(Computed&, std::string&)>& make, std::string& err) {
        std::promise<Result> promise;
        std::shared_future<Result> future;
        bool mine = false;
        {
            std::lock_guard<std::mutex> lock(m_mutex);
            auto it = m_entries.find(key);
            if (it != m_entries.end()) {
                m_lru.splice(m_lru.begin(), m_lru, it->second.lru);
                future = it->second.value;
            } else {
                future = promise.get_future().share();
                m_lru.push_front(key);
                m_entries.emplace(key, Entry{future, 0, m_lru.begin()});
                mine = true;
            }
        }
        if (mine) {
            Result r;
            try {
                auto c = std::make_shared<Computed>();
                if (make(*c, r.error))
                    r.pixels = std::move(c);
                else if (r.error.empty())
                    r.error = "cannot compute the pixels";
            } catch (const std::bad_alloc&) {
                r.error = "out of memory while computing the pixels";
            } catch (const std::exception& e) {
                r.error = e.what();
            }
            promise.set_value(r);
            std::lock_guard<std::mutex> lock(m_mutex);
            auto it = m_entries.find(key);
            if (it != m_entries.end()) {
                if (!r.pixels) {
                    m_lru.erase(it->second.lru);
                    m_entries.erase(it);
                } else {
                    it->second.bytes = std::max<size_t>(1, r.pixels->size() * sizeof(float));
                    m_bytes += it->second.bytes;
                    evict(key);
                }
            }
        }
        const Result& r = future.get();
        if (!r.pixels) err = r.error;
        return r.pixels;
    }

  private:
    struct Result {
        ComputedPtr pixels;
        std::string error;
    };
    struct Entry {
        std::shared_future<Result> value;
        size_t bytes;  ///< 0 while being computed
        std::list<std::string>::iterator lru;
    };
    PixelCache() {
        if (const char* mb = std::getenv("MCSTAT_PLUGIN_CACHE_MB")) {
            uint64_t v = 0;
            if (mcstat::parseUnsignedText(mb, v))
                m_budget = size_t(std::min<uint64_t>(v, 1ull << 40)) << 20;
        }
    }
    /// Drops least recently used finished entries until the budget holds (never `keep`, never
    /// one being computed; holders of a dropped entry's pointer keep its pixels alive).
    void evict(const std::string& keep) {
        for (auto it = m_lru.end(); m_bytes > m_budget && it != m_lru.begin();) {
            --it;
            auto e = m_entries.find(*it);
            if (*it == keep || e == m_entries.end() || e->second.bytes == 0) continue;
            m_bytes -= e->second.bytes;
            m_entries.erase(e);
            it = m_lru.erase(it);
        }
    }
    std::mutex m_mutex;
    std::map<std::string, Entry> m_entries;
    std::list<std::string> m_lru;  ///< most recently used first
    size_t m_bytes = 0;
    size_t m_budget = size_t(2048) << 20;
};

/// Pixel computations run by this process (cache misses): the tests check that reopening a file
/// computes nothing again (mcstat_imageio_computations below).
std::atomic<uint64_t> g_computations{0};

/// The identity of the file's content: a file rewritten in place (new size or time) or replaced
/// (new inode) is a new cache key.
bool fileIdentity(const std::string& path, std::string& id) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return false;
    id = format("{}:{}:{}:{}.{}", uint64_t(st.st_dev), uint64_t(st.st_ino), int64_t(st.st_size),
                int64_t(st.st_mtim.tv_sec), int64_t(st.st_mtim.tv_nsec));
    return true;
}

class McstatInput final : public ImageInput {
  public:
    McstatInput() = default;
    ~McstatInput() override { reset(); }
    const char* format_name() const override { return "mcstat"; }
    int supports(string_view) const override { return false; }
    /// Every error this reader records is one line of printable text, whatever the file or its
    /// name holds (oiiotool, iv and idiff print it as it is): it hides ImageInput::errorfmt.
    template <typename... Args>
    void errorfmt(const char* pattern, const Args&... args) const {
        ImageInput::errorfmt("{}", mcstat::oneLine(OIIO::Strutil::fmt::format(pattern, args...)));
    }
    /// guardEntry() for a virtual that reports failure as false: what was thrown is recorded as
    /// "WHAT: message" (errorfmt).
    template <class Body>
    bool guarded(const std::string& what, Body&& body) const {
        return guardEntry(false, body, [&](const char* why) { errorfmt("{}: {}", what, why); });
    }
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
    /// The cached arrays subimages are served from.
    /// kEstimate: the operation's result (R, G, B; a per-sample operation's every channel);
    /// kEstimateDiag: an estimator's result with its diagnostics (subimage 2), a second pass so
    /// that showing the robust image never computes or holds the diagnostics.
    enum Source { kEstimate, kEstimateDiag, kCounts, kBeauty, kFeatureArrays, kSourceCount };
    /// Channel c of a subimage is channel `index` of source `source`.
    struct ChannelFrom {
        Source source;
        size_t index;
    };
    struct Sub {
        ImageSpec spec;
        std::vector<ChannelFrom> from;  ///< one per channel of spec
    };
    std::array<Sub, kSubimageCount> m_subs;
    std::array<ComputedPtr, kSourceCount> m_sources;  ///< null until first read
    /// Subimages this file has: kSubimageCount, or one fewer when it holds no features (an
    /// ingested render without G-buffer AOVs: FORMAT.md version 3, mcstat:features empty).
    int m_nsubs = kSubimageCount;
    int m_current = -1;
    std::string m_name;  ///< as passed to open(), for messages
    std::string m_path;  ///< the file (name without "?...")
    std::string m_identity;
    const mcstat::Operation* m_op = nullptr;
    mcstat::ParamValues m_values;
    /// The confidence interval's channels (ci=LEVEL) in subimage 0; empty without.
    std::vector<std::string> m_intervalChannels;
    std::array<double, 3> m_luma{0.0, 0.0, 0.0};
    mcstat::StatsHeader m_header;

    void reset() {
        for (Sub& s : m_subs) s = Sub();
        for (ComputedPtr& c : m_sources) c.reset();
        m_nsubs = kSubimageCount;
        m_current = -1;
        m_name.clear();
        m_path.clear();
        m_identity.clear();
        m_op = nullptr;
        m_values.clear();
        m_header = mcstat::StatsHeader();
        m_spec = ImageSpec();
    }
    bool openImpl(const std::string& name, ImageSpec& newspec, const ImageSpec& config);
    /// Reads the operation and its parameters (`kv`, as given) from `config` and the file name
    /// into m_op, m_values, m_path, m_luma; false with errorfmt called.
    bool readParameters(const std::string& name, const ImageSpec& config,
                        std::map<std::string, std::string>& kv);
    /// Reads the file's validated headers into m_header and its identity; false with errorfmt.
    bool readHeader();
    /// The channels of the estimate (a per-sample operation runs for them); false with errorfmt.
    bool estimateChannels(std::vector<std::string>& estChannels);
    /// Shared specification: data window, float pixels, the file's header attributes.
    ImageSpec makeSpec(const std::vector<std::string>& channels, const char* subname) const;
    /// Names the operation and every settable parameter's value in `s`.
    void describeEstimator(ImageSpec& s, const std::map<std::string, std::string>& kv) const;
    /// Subimage 0: the operation's result, then the AOVs.
    void makeRobustSub(const std::map<std::string, std::string>& kv, size_t nAovs);
    /// Subimage 2: the estimator's diagnostics and the counts.
    void makeDiagnosticsSub(const std::vector<std::string>& estChannels, size_t nAovs,
                            const std::map<std::string, std::string>& kv);
    /// Subimage 1: the stored mean.
    void makeMeanSub();
    /// Subimage 3: the features the file holds; none at all lowers m_nsubs.
    void makeFeaturesSub();
    /// The cached source `s`, computed (once per process) if needed; null with errorfmt called.
    const Computed* source(Source s);
    bool computeSource(Source s, Computed& out, std::string& err);
    /// computeSource of kEstimate and kEstimateDiag: runs the operation.
    bool computeEstimate(Source s, Computed& out, std::string& err);
    std::string cacheKey(Source s) const;
    bool copyRows(int subimage, int miplevel, int ybegin, int yend, int chbegin, int chend,
                  void* data);
};

/// valid_file's test: the name is FILE.mcstat[?...] and FILE starts with OpenEXR's magic number.
bool isStatsFileName(const std::string& filename) {
    std::string path;
    std::map<std::string, std::string> kv;
    if (!splitName(filename, path, kv)) return false;
    if (Strutil::lower(Filesystem::extension(path, false)) != mcstat::kStatsExtension) return false;
    FILE* f = Filesystem::fopen(path, "rb");
    if (!f) return false;
    unsigned char magic[4] = {0, 0, 0, 0};
    const size_t n = std::fread(magic, 1, 4, f);
    std::fclose(f);
    // OpenEXR magic number 20000630 (little endian): the statistics file is an OpenEXR file.
    return n == 4 && magic[0] == 0x76 && magic[1] == 0x2f && magic[2] == 0x31 && magic[3] == 0x01;
}

bool McstatInput::valid_file(const std::string& filename) const {
    return guardEntry(
        false, [&] { return isStatsFileName(filename); }, ignoreError);
}

bool McstatInput::open(const std::string& name, ImageSpec& newspec) {
    return guarded(name, [&] { return open(name, newspec, ImageSpec()); });
}

bool McstatInput::open(const std::string& name, ImageSpec& newspec, const ImageSpec& config) {
    const bool opened = guarded(name, [&] {
        lock_guard lock(*this);
        return openImpl(name, newspec, config);
    });
    if (!opened) reset();
    return opened;
}

bool McstatInput::openImpl(const std::string& name, ImageSpec& newspec, const ImageSpec& config) {
    reset();
    m_name = name;
    std::map<std::string, std::string> kv;
    if (!readParameters(name, config, kv) || !readHeader()) return false;
    std::vector<std::string> estChannels;
    if (!estimateChannels(estChannels)) return false;
    // With AOVs (format version 5) they follow the diagnostics (imageops.h).
    const size_t nAovs = !mcstat::readsSamples(*m_op) ? m_header.aovs.size() : 0;
    // With ci=LEVEL the interval's channels follow R, G, B (and the diagnostics), before the
    // AOVs, as in `mcstat f --OP:ci=LEVEL -o x.exr`.
    m_intervalChannels.clear();
    if (!mcstat::readsSamples(*m_op)) {
        const std::vector<std::string> est =
            mcstat::operationChannels(*m_op, m_values, false, &m_header);
        m_intervalChannels.assign(est.begin() + 3, est.end() - std::ptrdiff_t(nAovs));
    }
    makeRobustSub(kv, nAovs);
    makeDiagnosticsSub(estChannels, nAovs, kv);
    makeMeanSub();
    makeFeaturesSub();

    m_current = kRobust;
    m_spec = m_subs[kRobust].spec;
    newspec = m_spec;
    return true;
}

bool McstatInput::readParameters(const std::string& name, const ImageSpec& config,
                                 std::map<std::string, std::string>& kv) {
    // Parameters: the configuration first, then the file name (which wins).
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
    std::string err;
    // ci, ciaovs: the confidence interval's layers, as --OP:ci=0.95 (docs/confidence.md).
    mcstat::ParamValues ci;
    if (!mcstat::takeConfidenceModifiers("estimator '" + est->name + "'", kv, ci, err)) {
        errorfmt("{}: {}", path, err);
        return false;
    }
    // keeplight (keeplightgamma, keeplightradius): the removed light given back, as
    // --OP:keeplight=1.
    mcstat::ParamValues keep;
    if (!mcstat::takeKeepLightModifiers("estimator '" + est->name + "'", kv, keep, err)) {
        errorfmt("{}: {}", path, err);
        return false;
    }
    if (!mcstat::parseOperationParams(*est, kv, m_values, err, "estimator '" + est->name + "'")) {
        errorfmt("{}: {}; the plugin also takes 'estimator' (one of: {})", path, err,
                 acceptedEstimators());
        return false;
    }
    m_values.insert(ci.begin(), ci.end());
    m_values.insert(keep.begin(), keep.end());
    if (const std::string why = mcstat::keepLightRefusal(*est, m_values); !why.empty()) {
        errorfmt("{}: {}", path, why);
        return false;
    }
    m_op = est;
    m_path = path;
    return true;
}

bool McstatInput::readHeader() {
    // The headers, validated (the message names the file); pixels wait for the first read.
    {
        std::string err;
        mcstat::StatsFileReader reader;
        if (!reader.open(m_path, err)) {
            errorfmt("{}", err);
            return false;
        }
        m_header = reader.header();
        // The luminance of the file's own working space (docs/color.md).
        if (!mcstat::lumaCoefficients(m_header.colorSpace, m_luma, err)) {
            errorfmt("{}: {}", m_path, err);
            return false;
        }
    }
    if (!fileIdentity(m_path, m_identity)) {
        errorfmt("{}: cannot stat the file", m_path);
        return false;
    }
    return true;
}

bool McstatInput::estimateChannels(std::vector<std::string>& estChannels) {
    // The estimate's channels: R, G, B, then an estimator's diagnostics (gini/kept/excluded).
    // A per-sample operation's extra channels are known only once it ran: it runs now.
    estChannels = mcstat::operationChannels(*m_op, m_values, true, &m_header);
    if (mcstat::readsSamples(*m_op)) {
        const Computed* c = source(kEstimate);
        if (!c) return false;
        estChannels = c->channels;
    }
    if (estChannels.size() < 3) {
        errorfmt("{}: the estimate has an unexpected layout", m_path);
        return false;
    }
    return true;
}

ImageSpec McstatInput::makeSpec(const std::vector<std::string>& channels,
                                const char* subname) const {
    const mcstat::StatsHeader& h = m_header;
    // Overscan: the render's windows. No alpha unless an AOV of class alpha says so (features'
    // P.X and diagnostics' count are not).
    ImageSpec s =
        mcstat::floatSpec(mcstat::dataWindowROI(h), channels, mcstat::displayWindowROI(h));
    s.attribute("oiio:subimagename", subname);
    s.attribute("oiio:subimages", m_nsubs);
    s.attribute("mcstat:formatVersion", h.formatVersion);
    s.attribute("mcstat:M", h.M);
    if (h.adaptiveM) s.attribute("mcstat:adaptiveM", 1);
    if (h.compact) s.attribute("mcstat:compact", mcstat::printable(h.compactRule));
    s.attribute("mcstat:spp", int(std::min<int64_t>(h.spp, INT32_MAX)));
    s.attribute("mcstat:assignment", mcstat::printable(h.assignment));
    if (h.formatVersion >= mcstat::kStatsFormatVersionProvenance) {
        s.attribute("mcstat:variance", mcstat::printable(h.variance));
        s.attribute("mcstat:features", mcstat::featureListText(h.features));
        // Rendered files list no sources: the attribute is left out rather than shown empty.
        if (!h.sources.empty()) s.attribute("mcstat:sources", mcstat::printable(h.sources, 0));
    }
    s.attribute("mcstat:renderer", mcstat::printable(h.renderer));
    s.attribute("mcstat:colorSpace", mcstat::printable(h.colorSpace));
    s.attribute("mcstat:seeds", mcstat::printable(h.seeds, 0));
    return s;
}

void McstatInput::describeEstimator(ImageSpec& s,
                                    const std::map<std::string, std::string>& kv) const {
    s.attribute("mcstat:estimator", m_op->name);
    for (const mcstat::ParamSpec* pi : m_op->settable()) {
        auto it = kv.find(pi->name);
        s.attribute("mcstat:" + pi->name, it != kv.end() ? it->second : pi->defaultValue);
    }
}

void McstatInput::makeRobustSub(const std::map<std::string, std::string>& kv, size_t nAovs) {
    const mcstat::StatsHeader& h = m_header;
    const mcstat::Operation* est = m_op;
    // 0: the robust estimate.
    // Beauty under the input render's names (R, G, B for mcstat's own files), then every AOV:
    // `oiiotool f.mcstat --subimage 0 -o x.exr` writes a drop-in for one input render.
    Sub& r = m_subs[kRobust];
    std::vector<std::string> robustNames(h.beautyNames.begin(), h.beautyNames.end());
    robustNames.insert(robustNames.end(), m_intervalChannels.begin(), m_intervalChannels.end());
    for (size_t a = 0; a < nAovs; ++a) robustNames.push_back(h.aovs[a].name);
    r.spec = makeSpec(robustNames, est->name.c_str());
    r.spec.alpha_channel = mcstat::aovAlphaChannel(h, 3 + m_intervalChannels.size());
    r.spec.z_channel = mcstat::aovDepthChannel(h, 3 + m_intervalChannels.size());
    if (nAovs == 0) r.spec.alpha_channel = r.spec.z_channel = -1;
    r.spec.attribute("oiio:ColorSpace", h.colorSpace);
    describeEstimator(r.spec, kv);
    mcstat::describeResult(r.spec, *est, m_values, h);
    if (!h.adaptiveM) {
        // iv shows subimage 0 under the estimator's name: say when it cannot differ from the mean.
        const int minM = mcstat::smallestRobustM(*est, m_values);
        if (minM > 1 && h.M < minM)
            r.spec.attribute(std::string(mcstat::kProvenancePrefix) + "warning",
                             format("{} over M = {} sub-buffers is the plain mean (it trims "
                                    "nothing below M = {})",
                                    est->name, h.M, minM));
    }
    r.from = {{kEstimate, 0}, {kEstimate, 1}, {kEstimate, 2}};
    // kEstimate (no diagnostics) holds R, G, B, the interval's channels, then the AOVs.
    for (size_t i = 0; i < m_intervalChannels.size() + nAovs; ++i)
        r.from.push_back({kEstimate, 3 + i});
}

void McstatInput::makeDiagnosticsSub(const std::vector<std::string>& estChannels, size_t nAovs,
                                     const std::map<std::string, std::string>& kv) {
    const bool samples = mcstat::readsSamples(*m_op);
    // 2: diagnostics: the estimator's gini/kept/excluded channels plus the sample count, and with
    // adaptive M the map of buffer counts m_p ("M").
    Sub& d = m_subs[kDiagnostics];
    // The diagnostics only: the interval's channels and the AOVs after them are subimage 0's.
    const size_t end = estChannels.size() - nAovs - m_intervalChannels.size();
    std::vector<std::string> diagNames(estChannels.begin() + 3,
                                       estChannels.begin() + std::ptrdiff_t(end));
    for (size_t i = 3; i < end; ++i) d.from.push_back({samples ? kEstimate : kEstimateDiag, i});
    diagNames.push_back("count");
    d.from.push_back({kCounts, 0});
    if (m_header.adaptiveM) {
        diagNames.push_back("M");
        d.from.push_back({kCounts, 1});
    }
    d.spec = makeSpec(diagNames, "diagnostics");
    describeEstimator(d.spec, kv);
}

void McstatInput::makeMeanSub() {
    const std::string meanName = m_op->name == "mean" ? "beauty" : "mean";
    // 1: the plain mean as stored (part "beauty").
    Sub& m = m_subs[kMean];
    m.spec = makeSpec({"R", "G", "B"}, meanName.c_str());
    m.spec.attribute("oiio:ColorSpace", m_header.colorSpace);
    m.from = {{kBeauty, 0}, {kBeauty, 1}, {kBeauty, 2}};
}

void McstatInput::makeFeaturesSub() {
    // 3: first-hit features, only those the file holds (version 3 records absent ones as NaN).
    std::vector<std::string> featureNames;
    Sub& f = m_subs[kFeatures];
    for (size_t i = 0; i < std::size(kFeatureChannels); ++i)
        if (m_header.features & kFeatureChannels[i].feature) {
            featureNames.push_back(kFeatureChannels[i].name);
            f.from.push_back({kFeatureArrays, i});
        }
    if (featureNames.empty()) {
        m_nsubs = kFeatures;  // no features subimage; the specs made above say so too
        for (int i = 0; i < kFeatures; ++i)
            m_subs[size_t(i)].spec.attribute("oiio:subimages", m_nsubs);
        f = Sub();
    } else {
        f.spec = makeSpec(featureNames, "features");
    }
}

std::string McstatInput::cacheKey(Source s) const {
    std::string key = format("{}|{}|{}", m_identity, m_path, int(s));
    if (s == kEstimate || s == kEstimateDiag) {
        key += "|" + m_op->name;
        for (const auto& [k, v] : m_values) key += "|" + k + "=" + v.text;
        key += format("|{:.17g},{:.17g},{:.17g}", m_luma[0], m_luma[1], m_luma[2]);
    }
    return key;
}

const Computed* McstatInput::source(Source s) {
    if (!m_sources[s]) {
        std::string err;
        m_sources[s] = PixelCache::instance().get(
            cacheKey(s), [&](Computed& out, std::string& e) { return computeSource(s, out, e); },
            err);
        if (!m_sources[s]) {
            errorfmt("{}", err);
            return nullptr;
        }
    }
    return m_sources[s].get();
}

bool McstatInput::computeEstimate(Source s, Computed& out, std::string& err) {
    const mcstat::StatsHeader& h = m_header;
    const size_t npix = size_t(h.width) * size_t(h.height);
    // Every operation returns R, G, B first; an estimator over buffer means with diagnostics
    // its gini/kept/excluded channels after them, computed by the same per-pixel call as
    // without them (so subimages 0 and 2 agree).
    // The file as the one seam takes it (image/operation_input.h): on disk for the per-sample
    // operations, streamed by blocks of rows for the others (opened only then).
    mcstat::StatsFileReader reader;
    mcstat::OperationInput in;
    in.name = m_path;
    in.path = m_path;
    in.header = &h;
    in.stream = [&](std::string& e) -> mcstat::StatsBlockSource* {
        if (!reader.open(m_path, e, mcstat::ReadLimits(), threads())) return nullptr;
        if (reader.header().width != h.width || reader.header().height != h.height ||
            reader.header().M != h.M) {
            e = m_path + ": the file changed since it was opened";
            return nullptr;
        }
        return &reader;
    };
    OIIO::ImageBuf img;
    const bool ok =
        mcstat::applyOperation(img, in, *m_op, m_values, m_luma, s == kEstimateDiag, {}, threads());
    if (!ok) {
        // Messages from the file's reader already start with its path.
        err = img.geterror();
        if (err.rfind(m_path, 0) != 0) err = m_path + ": " + err;
        return false;
    }
    const ImageSpec& spec = img.spec();
    const size_t nch = size_t(spec.nchannels);
    if (!img.localpixels() || spec.format != TypeFloat || size_t(spec.image_pixels()) != npix ||
        nch < 3) {
        err = m_path + ": the estimate has an unexpected layout";
        return false;
    }
    out.channels = spec.channelnames;
    out.image.swap(img);  // kept as computed, no copy
    return true;
}

bool McstatInput::computeSource(Source s, Computed& out, std::string& err) {
    ++g_computations;
    if (s == kEstimate || s == kEstimateDiag) return computeEstimate(s, out, err);
    const mcstat::StatsHeader& h = m_header;
    const size_t npix = size_t(h.width) * size_t(h.height);
    // The stored parts, streamed by blocks of rows.
    unsigned parts = 0;
    switch (s) {
        case kCounts:
            out.channels = {"count"};
            if (h.adaptiveM) out.channels.push_back("M");
            parts = mcstat::kStatsPartMoments | (h.adaptiveM ? mcstat::kStatsPartBuffers : 0u);
            break;
        case kBeauty:
            out.channels = {"R", "G", "B"};
            parts = mcstat::kStatsPartBeauty;
            break;
        default:
            for (const FeatureChannel& c : kFeatureChannels) out.channels.push_back(c.name);
            parts = mcstat::kStatsPartFeatures;
            break;
    }
    mcstat::StatsFileReader reader;
    if (!reader.open(m_path, err, mcstat::ReadLimits(), threads())) return false;
    const mcstat::StatsHeader& fh = reader.header();
    if (fh.width != h.width || fh.height != h.height || fh.adaptiveM != h.adaptiveM) {
        err = m_path + ": the file changed since it was opened";
        return false;
    }
    const size_t nch = out.channels.size();
    out.pixels.resize(npix * nch);
    const int rows = reader.blockRows(parts);
    mcstat::StatsImage block;
    for (int y = 0; y < h.height; y += rows) {
        const int n = std::min(rows, h.height - y);
        if (!reader.read(y, n, parts, block, err)) return false;
        float* o = out.pixels.data() + size_t(y) * size_t(h.width) * nch;
        const size_t bp = block.pixelCount();
        if (s == kCounts) {
            for (size_t p = 0; p < bp; ++p, o += nch) {
                o[0] = block.count[p];
                if (h.adaptiveM) o[1] = float(block.buffersOf(p));
            }
        } else if (s == kBeauty) {
            std::copy(block.beauty.begin(), block.beauty.end(), o);
        } else {
            for (size_t p = 0; p < bp; ++p, o += nch)
                for (size_t i = 0; i < nch; ++i) {
                    const FeatureChannel& c = kFeatureChannels[i];
                    o[i] = (block.*(c.array))[p * c.stride + c.offset];
                }
        }
    }
    return true;
}

bool McstatInput::close() {
    guardEntry(
        true,
        [&] {
            lock_guard lock(*this);
            reset();
            return true;
        },
        ignoreError);
    return true;
}

bool McstatInput::seek_subimage(int subimage, int miplevel) {
    return guarded(m_name, [&] {
        lock_guard lock(*this);
        if (m_current < 0 || subimage < 0 || subimage >= m_nsubs || miplevel != 0) return false;
        if (subimage != m_current) {
            m_current = subimage;
            m_spec = m_subs[subimage].spec;
        }
        return true;
    });
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
    // Where each requested channel comes from, its source computed on first use.
    const size_t w = size_t(sp.width), nsel = size_t(chend - chbegin);
    std::vector<const float*> base(nsel);
    std::vector<size_t> stride(nsel);
    for (size_t i = 0; i < nsel; ++i) {
        const ChannelFrom& from = s.from[size_t(chbegin) + i];
        const Computed* c = source(from.source);
        if (!c) return false;
        stride[i] = c->channels.size();
        if (from.index >= stride[i] || c->size() != w * size_t(sp.height) * stride[i]) {
            errorfmt("{}: subimage {} has an unexpected layout", m_name, subimage);
            return false;
        }
        base[i] = c->data() + from.index;
    }
    float* out = static_cast<float*>(data);
    for (int y = ybegin; y < yend; ++y) {
        const size_t row = size_t(y - sp.y) * w;
        for (size_t x = 0; x < w; ++x)
            for (size_t i = 0; i < nsel; ++i) *out++ = base[i][(row + x) * stride[i]];
    }
    return true;
}

bool McstatInput::read_native_scanline(int subimage, int miplevel, int y, int, void* data) {
    return guarded(m_name, [&] { return copyRows(subimage, miplevel, y, y + 1, 0, -1, data); });
}

bool McstatInput::read_native_scanlines(int subimage, int miplevel, int ybegin, int yend, int,
                                        void* data) {
    return guarded(m_name, [&] { return copyRows(subimage, miplevel, ybegin, yend, 0, -1, data); });
}

bool McstatInput::read_native_scanlines(int subimage, int miplevel, int ybegin, int yend, int,
                                        int chbegin, int chend, void* data) {
    return guarded(
        m_name, [&] { return copyRows(subimage, miplevel, ybegin, yend, chbegin, chend, data); });
}

}  // namespace

OIIO_PLUGIN_EXPORTS_BEGIN

OIIO_EXPORT int mcstat_imageio_version = OIIO_PLUGIN_VERSION;

OIIO_EXPORT const char* mcstat_imageio_library_version() { return "mcstat " MCSTAT_VERSION; }

OIIO_EXPORT ImageInput* mcstat_input_imageio_create() {
    return guardEntry<ImageInput*>(
        nullptr, [] { return new McstatInput; }, ignoreError);
}

/// Number of subimage computations this process ran (not an OIIO entry point: for tests and
/// diagnostics, found with dlsym).
OIIO_EXPORT uint64_t mcstat_imageio_computations() { return g_computations.load(); }

OIIO_EXPORT const char* mcstat_input_extensions[] = {mcstat::kStatsExtension, nullptr};

OIIO_PLUGIN_EXPORTS_END

OIIO_PLUGIN_NAMESPACE_END
