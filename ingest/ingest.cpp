// Ingest of renderer output (include/mcstat/ingest.h, docs/ingest.md): many renders of one image,
// one per seed, become one statistics file with one sub-buffer per file.
#include "mcstat/ingest.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <fmt/format.h>
#include <fnmatch.h>
#include <glob.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <set>

#include "mcstat/render_layout.h"

namespace mcstat {

namespace {

using OIIO::ImageInput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

/// OIIO's messages may span lines; ours are one line.
std::string oneLine(const std::string& s) {
    return std::string(OIIO::Strutil::strip(OIIO::Strutil::replace(s, "\n", " ", true)));
}

bool hasGlobChars(const std::string& s) { return s.find_first_of("*?[") != std::string::npos; }

/// Natural order: "s2.exr" before "s10.exr" (glibc's strverscmp).
bool naturalLess(const std::string& a, const std::string& b) {
    return strverscmp(a.c_str(), b.c_str()) < 0;
}

/// Positive integer metadata value (int attribute or decimal string); 0 when absent or not one.
int64_t positiveInt(const ImageSpec& spec, const std::string& name) {
    const OIIO::ParamValue* pv = spec.find_attribute(name);
    if (pv == nullptr) return 0;
    if (pv->type() == TypeDesc::INT) return std::max(0, pv->get_int());
    const std::string text = OIIO::Strutil::strip(pv->get_string());
    if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos ||
        text.size() > 12)
        return 0;
    return std::stoll(text);
}

/// Which renderer wrote a file: its Software attribute, else what its own attributes say
/// (Blender writes no Software but cycles.* statistics and BlenderMultiChannel; Arnold, Karma and
/// RenderMan prefix theirs), else "unknown renderer".
std::string rendererOf(const ImageSpec& spec) {
    for (const char* k : {"Software", "software"})
        if (std::string s = spec.get_string_attribute(k); !s.empty()) return oneLine(s);
    static const std::pair<const char*, const char*> kPrefixes[] = {
        {"cycles.", "Blender/Cycles"}, {"BlenderMultiChannel", "Blender"},
        {"arnold/", "Arnold"},         {"karma", "Karma"},
        {"rman", "RenderMan"},         {"renderman", "RenderMan"}};
    for (const auto& [prefix, name] : kPrefixes)
        for (const OIIO::ParamValue& pv : spec.extra_attribs)
            if (OIIO::Strutil::istarts_with(pv.name().string(), prefix)) return name;
    return "unknown renderer";
}

/// Samples per pixel from a renderer's metadata (docs/ingest.md): mcstat:spp (mcstat-render's
/// plain EXRs), samplesPerPixel (pbrt-v4), cycles.<ViewLayer>.samples (Blender/Cycles).
/// `key` says which attribute was used.
int64_t sppFromMetadata(const ImageSpec& spec, const BeautyChannels& beauty, std::string& key) {
    for (const char* k : {"mcstat:spp", "samplesPerPixel"})
        if (const int64_t v = positiveInt(spec, k)) {
            key = k;
            return v;
        }
    if (!beauty.viewLayerPrefix.empty()) {
        const std::string k = "cycles." + beauty.viewLayerPrefix + "samples";
        if (const int64_t v = positiveInt(spec, k)) {
            key = k;
            return v;
        }
    }
    // A single view layer's Cycles statistics, whatever the layer is called.
    std::vector<std::string> cycles;
    for (const OIIO::ParamValue& pv : spec.extra_attribs) {
        const std::string n = pv.name().string();
        if (OIIO::Strutil::starts_with(n, "cycles.") && OIIO::Strutil::ends_with(n, ".samples"))
            cycles.push_back(n);
    }
    if (cycles.size() == 1)
        if (const int64_t v = positiveInt(spec, cycles[0])) {
            key = cycles[0];
            return v;
        }
    return 0;
}

/// One input file, opened, with the channels mcstat reads from it.
struct InputFile {
    std::string path;
    std::unique_ptr<ImageInput> in;
    ImageSpec spec;  ///< subimage 0
    std::vector<std::string> names;
    std::vector<std::pair<int, int>> where;
    /// Per subimage: its part name when the file has several parts ("" for a one-part file).
    std::vector<std::string> partNames;
    BeautyChannels beauty;
    FeatureChannels features;
    int64_t spp = 0;
    std::string sppKey;
};

/// The channel names of every subimage of `in` (see listChannels); leaves `in` on some subimage.
void channelsOf(ImageInput& in, std::vector<std::string>& names,
                std::vector<std::pair<int, int>>& where,
                std::vector<std::string>* partNames = nullptr) {
    names.clear();
    where.clear();
    if (partNames) partNames->clear();
    for (int sub = 0; in.seek_subimage(sub, 0); ++sub) {
        const ImageSpec& s = in.spec();
        const std::string part = s.get_string_attribute("oiio:subimagename");
        if (partNames) partNames->push_back(part.empty() ? fmt::format("part{}", sub) : part);
        for (int c = 0; c < s.nchannels; ++c) {
            std::string n = s.channel_name(c);
            if (sub > 0 && n.find('.') == std::string::npos && !part.empty()) n = part + "." + n;
            if (std::find(names.begin(), names.end(), n) != names.end()) continue;  // first wins
            names.push_back(n);
            where.emplace_back(sub, c);
        }
        if (sub > 4096) break;  // a sane bound on parts
    }
    if (partNames && partNames->size() == 1) partNames->front().clear();  // one part: no name
}

bool openInput(const std::string& path, InputFile& f, std::string& err) {
    f.path = path;
    if (!OIIO::Filesystem::is_regular(path)) {
        err = fmt::format("{}: {}", path,
                          OIIO::Filesystem::exists(path) ? "not a regular file" : "no such file");
        return false;
    }
    f.in = ImageInput::open(path);
    if (!f.in) {
        err = fmt::format("{}: {}", path, oneLine(OIIO::geterror()));
        return false;
    }
    f.spec = f.in->spec();
    if (f.spec.deep) {
        err = path + ": a deep image; ingest reads flat renders (one image per seed)";
        return false;
    }
    if (f.spec.depth > 1) {
        err = path + ": a volume image; ingest reads flat 2D renders";
        return false;
    }
    channelsOf(*f.in, f.names, f.where, &f.partNames);
    return true;
}

bool globMatch(const std::string& pattern, const std::string& text) {
    return fnmatch(pattern.c_str(), text.c_str(), 0) == 0;
}

/// Every channel of `f` but the beauty's R, G, B, in the file's order, with class and part.
std::vector<int> aovChannelsOf(const InputFile& f, const IngestOptions& opt,
                               std::vector<AovChannel>& aovs) {
    std::vector<int> index;
    aovs.clear();
    for (size_t i = 0; i < f.names.size(); ++i) {
        if (std::find(f.beauty.index.begin(), f.beauty.index.end(), int(i)) != f.beauty.index.end())
            continue;
        AovChannel a;
        a.name = f.names[i];
        a.cls = classifyAov(a.name, f.beauty);
        const size_t dot = a.name.rfind('.');
        const std::string layer = dot == std::string::npos ? std::string() : a.name.substr(0, dot);
        for (const auto& [pattern, cls] : opt.classOverrides)
            if (globMatch(pattern, a.name) || (!layer.empty() && globMatch(pattern, layer)))
                a.cls = cls;
        a.part = f.partNames[size_t(f.where[i].first)];
        aovs.push_back(std::move(a));
        index.push_back(int(i));
    }
    return index;
}

std::string windowText(int x, int y, int w, int h) {
    return fmt::format("({},{})-({},{})", x, y, int64_t(x) + w - 1, int64_t(y) + h - 1);
}

/// Checks that `f` matches the first file: windows and channel names.
bool sameLayout(const InputFile& first, const InputFile& f, std::string& err) {
    const ImageSpec &a = first.spec, &b = f.spec;
    if (a.x != b.x || a.y != b.y || a.width != b.width || a.height != b.height) {
        err = fmt::format("{}: data window {} ({}x{}) differs from {}'s {} ({}x{})", f.path,
                          windowText(b.x, b.y, b.width, b.height), b.width, b.height, first.path,
                          windowText(a.x, a.y, a.width, a.height), a.width, a.height);
        return false;
    }
    if (a.full_x != b.full_x || a.full_y != b.full_y || a.full_width != b.full_width ||
        a.full_height != b.full_height) {
        err = fmt::format("{}: display window {} differs from {}'s {}", f.path,
                          windowText(b.full_x, b.full_y, b.full_width, b.full_height), first.path,
                          windowText(a.full_x, a.full_y, a.full_width, a.full_height));
        return false;
    }
    // The first channel (in name order) of `from` that `in` lacks, or "".
    const auto firstMissing = [](const std::vector<std::string>& from,
                                 const std::vector<std::string>& in) {
        const std::set<std::string> inSet(in.begin(), in.end());
        for (const std::string& n : std::set<std::string>(from.begin(), from.end()))
            if (!inSet.count(n)) return n;
        return std::string();
    };
    const char* kSame = "every render must have the same channels";
    if (const std::string n = firstMissing(first.names, f.names); !n.empty()) {
        err = fmt::format("{}: has no channel '{}' that {} has ({})", f.path, n, first.path, kSame);
        return false;
    }
    if (const std::string n = firstMissing(f.names, first.names); !n.empty()) {
        err = fmt::format("{}: has a channel '{}' that {} has not ({})", f.path, n, first.path,
                          kSame);
        return false;
    }
    return true;
}

/// 64-bit FNV-1a over the bytes of `data`, continuing from `h`.
uint64_t fnv1a(uint64_t h, const void* data, size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) {
        h ^= p[i];
        h *= 1099511628211ull;
    }
    return h;
}

constexpr uint64_t kFnvBasis = 14695981039346656037ull;
constexpr double kMaxCount = 16777216.0;  // counts are float32 integers (FORMAT.md)

/// Channels of one subimage that a file's read needs, read as one contiguous range per block.
struct SubimageRead {
    int subimage = 0;
    int chbegin = 0, chend = 0;  ///< range [chbegin, chend) of that subimage's channels
};

/// The (subimage, channel) of every channel index used, grouped into one range per subimage.
std::vector<SubimageRead> readsFor(const InputFile& f, const std::vector<int>& used) {
    std::vector<SubimageRead> reads;
    for (int i : used) {
        if (i < 0) continue;
        // Plain variables, not a structured binding: C++17 lambdas cannot capture those (clang).
        const int sub = f.where[size_t(i)].first, ch = f.where[size_t(i)].second;
        auto it = std::find_if(reads.begin(), reads.end(),
                               [&](const SubimageRead& r) { return r.subimage == sub; });
        if (it == reads.end()) {
            reads.push_back({sub, ch, ch + 1});
        } else {
            it->chbegin = std::min(it->chbegin, ch);
            it->chend = std::max(it->chend, ch + 1);
        }
    }
    return reads;
}

}  // namespace

bool expandInputs(const std::string& pattern, std::vector<std::string>& paths, std::string& err) {
    std::vector<std::string> items;
    if (OIIO::Filesystem::is_regular(pattern))
        items.push_back(pattern);
    else
        items = OIIO::Strutil::splits(pattern, ",");
    std::vector<std::string> out;
    for (const std::string& raw : items) {
        const std::string item = std::string(OIIO::Strutil::strip(raw));
        if (item.empty()) {
            err = fmt::format("'{}': an empty file name in the list", pattern);
            return false;
        }
        if (!hasGlobChars(item) || OIIO::Filesystem::exists(item)) {
            out.push_back(item);  // checked when opened: "no such file"
            continue;
        }
        glob_t g{};
        const int rv = glob(item.c_str(), GLOB_ERR, nullptr, &g);
        if (rv == GLOB_NOMATCH) {
            globfree(&g);
            err = fmt::format("'{}' matches no file", item);
            return false;
        }
        if (rv != 0) {
            globfree(&g);
            err = fmt::format("'{}': cannot list the files it names ({})", item,
                              rv == GLOB_ABORTED ? "a directory cannot be read" : "out of memory");
            return false;
        }
        for (size_t i = 0; i < g.gl_pathc; ++i) out.push_back(g.gl_pathv[i]);
        globfree(&g);
    }
    std::sort(out.begin(), out.end(), naturalLess);
    for (size_t i = 1; i < out.size(); ++i)
        if (out[i] == out[i - 1]) {
            err = fmt::format("{}: named twice (its samples would count twice)", out[i]);
            return false;
        }
    paths = std::move(out);
    return true;
}

bool listChannels(const std::string& path, std::vector<std::string>& names,
                  std::vector<std::pair<int, int>>& where, std::string& err) {
    auto in = ImageInput::open(path);
    if (!in) {
        err = fmt::format("{}: {}", path, oneLine(OIIO::geterror()));
        return false;
    }
    channelsOf(*in, names, where);
    return true;
}

bool readRenderRGB(const std::string& path, const std::string& layer, OIIO::ImageBuf& out,
                   BeautyChannels* found, std::string& err) {
    InputFile f;
    if (!openInput(path, f, err)) return false;
    std::string problem;
    if (!findBeauty(f.names, layer, f.beauty, problem)) {
        err = path + ": " + problem;
        return false;
    }
    ImageSpec spec(f.spec.width, f.spec.height, 3, TypeDesc::FLOAT);
    spec.x = f.spec.x;
    spec.y = f.spec.y;
    spec.full_x = f.spec.full_x;
    spec.full_y = f.spec.full_y;
    spec.full_width = f.spec.full_width;
    spec.full_height = f.spec.full_height;
    spec.channelnames = {"R", "G", "B"};
    OIIO::ImageBuf buf(spec);
    std::vector<float> rows;
    const std::vector<int> used(f.beauty.index.begin(), f.beauty.index.end());
    const auto reads = readsFor(f, used);
    float* dst = static_cast<float*>(buf.localpixels());
    const int w = spec.width;
    for (const SubimageRead& r : reads) {
        const int nch = r.chend - r.chbegin;
        rows.resize(size_t(w) * size_t(spec.height) * size_t(nch));
        if (!f.in->read_scanlines(r.subimage, 0, spec.y, spec.y + spec.height, 0, r.chbegin,
                                  r.chend, TypeDesc::FLOAT, rows.data())) {
            err = fmt::format("{}: {}", path, oneLine(f.in->geterror()));
            return false;
        }
        for (int c = 0; c < 3; ++c) {
            const auto [sub, ch] = f.where[size_t(f.beauty.index[size_t(c)])];
            if (sub != r.subimage) continue;
            const size_t off = size_t(ch - r.chbegin);
            for (size_t p = 0; p < size_t(w) * size_t(spec.height); ++p)
                dst[p * 3 + size_t(c)] = rows[p * size_t(nch) + off];
        }
    }
    if (found) *found = f.beauty;
    out = std::move(buf);
    return true;
}

bool ingestRenders(const std::vector<std::string>& paths, const IngestOptions& opt, StatsImage& out,
                   IngestReport& report, std::string& err) {
    report = IngestReport();
    if (paths.empty()) {
        err = "no input files";
        return false;
    }
    if (paths.size() > size_t(std::min(opt.limits.maxBuffers, kMaxBuffers))) {
        err = fmt::format("{} files, but a statistics file holds at most {} sub-buffers",
                          paths.size(), std::min(opt.limits.maxBuffers, kMaxBuffers));
        return false;
    }
    if (opt.spp < 0 || double(opt.spp) > kMaxCount) {
        err = fmt::format("samples per file {} out of range 1..2^24", opt.spp);
        return false;
    }
    // 1. Every header first: layouts, channels, spp; nothing is allocated before they agree.
    std::vector<InputFile> files(paths.size());
    for (size_t j = 0; j < paths.size(); ++j) {
        InputFile& f = files[j];
        if (!openInput(paths[j], f, err)) return false;
        std::string problem;
        // Every file uses the first file's beauty layer, so a file cannot switch layers.
        const std::string layer =
            j == 0 ? opt.layer
                   : (files[0].beauty.layer.empty() ? std::string(".") : files[0].beauty.layer);
        if (j > 0 && !sameLayout(files[0], f, err)) return false;
        if (!findBeauty(f.names, layer, f.beauty, problem)) {
            err = f.path + ": " + problem;
            return false;
        }
        f.features = findFeatures(f.names, f.beauty);
        f.spp = opt.spp > 0 ? opt.spp : sppFromMetadata(f.spec, f.beauty, f.sppKey);
        if (f.spp <= 0) {
            err = fmt::format(
                "{}: the file does not say how many samples per pixel it holds (looked for "
                "mcstat:spp, samplesPerPixel, cycles.<ViewLayer>.samples); give "
                "--ingest:spp=N",
                f.path);
            return false;
        }
        if (double(f.spp) > kMaxCount) {
            err = fmt::format("{}: {} samples per pixel exceeds 2^24", f.path, f.spp);
            return false;
        }
        report.spp.push_back(f.spp);
        f.in.reset();  // closed until its pixels are read: 999 inputs must not hold 999 files open
    }
    const InputFile& first = files[0];
    report.beauty = first.beauty;
    report.features = first.features;
    const int W = first.spec.width, H = first.spec.height, M = int(files.size());
    const int64_t pixels = int64_t(W) * int64_t(H);
    if (W <= 0 || H <= 0) {
        err = fmt::format("{}: empty image {}x{}", first.path, W, H);
        return false;
    }
    if (pixels > opt.limits.maxPixels) {
        err = fmt::format("{}: image {}x{} exceeds the limit of {} pixels", first.path, W, H,
                          opt.limits.maxPixels);
        return false;
    }
    // Every channel but the beauty, kept per sub-buffer (docs/aovs.md).
    std::vector<AovChannel> aovs;
    std::vector<int> aovIndex;
    if (opt.aovs) aovIndex = aovChannelsOf(first, opt, aovs);
    if (aovs.size() > size_t(kMaxAovs)) {
        err = fmt::format("{}: {} channels besides the beauty; a statistics file holds at most {}",
                          first.path, aovs.size(), kMaxAovs);
        return false;
    }
    for (const AovChannel& a : aovs)
        if (a.name.size() > kMaxAovNameBytes) {
            err = fmt::format("{}: channel name '{}...' is longer than {} bytes", first.path,
                              a.name.substr(0, 40), kMaxAovNameBytes);
            return false;
        }
    const size_t A = aovs.size();
    report.aovs = aovs;
    if (!opt.aovs && first.names.size() > 3)
        report.warnings.push_back(
            fmt::format("{}: {} channels besides the beauty's R, G, B left out as asked (:aovs=0)",
                        first.path, first.names.size() - 3));
    // The statistics image, plus 10 doubles per pixel for the feature sums when there are any.
    const double featureBytes = first.features.present != 0 ? 80.0 : 0.0;
    const double bytes = double(pixels) * (double(3 + 4 * M + 7 + 11) * 4.0 +
                                           double(M) * double(A) * 4.0 + featureBytes);
    if (bytes > double(opt.limits.maxBytes)) {
        err = fmt::format("{} renders of {}x{} need {:.0f} bytes, exceeding the limit of {} bytes",
                          M, W, H, bytes, opt.limits.maxBytes);
        return false;
    }
    double totalSpp = 0.0;
    for (int64_t s : report.spp) totalSpp += double(s);
    if (totalSpp > kMaxCount) {
        err = fmt::format("{} samples per pixel in all exceed 2^24 (counts are float32 integers)",
                          totalSpp);
        return false;
    }
    for (size_t j = 1; j < files.size(); ++j)
        if (files[j].spp != files[0].spp) {
            report.warnings.push_back(fmt::format(
                "samples per file differ ({} in {}, {} in {}): sub-buffers of unequal counts; "
                "median-of-means estimators assume equal ones",
                files[0].spp, files[0].path, files[j].spp, files[j].path));
            break;
        }
    if (M == 1)
        report.warnings.push_back(fmt::format(
            "{}: only one file, so M = 1: every robust estimator returns the plain mean, and the "
            "variance is unknown",
            first.path));
    const unsigned features = first.features.present;

    StatsImage img;
    StatsHeader& h = img.header;
    h.formatVersion = kStatsFormatVersionProvenance;
    h.width = W;
    h.height = H;
    h.originX = first.spec.x;
    h.originY = first.spec.y;
    h.M = M;
    h.spp = int64_t(totalSpp);
    h.assignment = kAssignmentPerFile;
    h.variance = M >= 2 ? kVarianceBuffers : kVarianceUnknown;
    h.features = features;
    h.renderer = rendererOf(first.spec) + " via mcstat --ingest";
    for (size_t j = 0; j < files.size(); ++j)
        h.sources += (j ? "," : "") + OIIO::Filesystem::filename(files[j].path);
    // Version 5: what the render looked like, so that a result can replace one input.
    h.aovs = aovs;
    for (size_t c = 0; c < 3; ++c) h.beautyNames[c] = first.names[size_t(first.beauty.index[c])];
    h.beautyPart = first.partNames[size_t(first.where[size_t(first.beauty.index[0])].first)];
    const ImageSpec& fsp = first.spec;
    if (fsp.full_x != fsp.x || fsp.full_y != fsp.y || fsp.full_width != fsp.width ||
        fsp.full_height != fsp.height) {
        h.displayX = fsp.full_x;
        h.displayY = fsp.full_y;
        h.displayWidth = fsp.full_width;
        h.displayHeight = fsp.full_height;
    }
    h.sourceMetadata = sourceMetadataJson(fsp);
    h.formatVersion = std::max(kStatsFormatVersionProvenance, requiredFormatVersion(h));
    if (!img.allocate(err)) return false;
    try {
        img.aov.assign(img.pixelCount() * size_t(M) * A, 0.f);
    } catch (const std::exception& e) {
        err = fmt::format("cannot allocate the AOVs of {}x{}: {}", W, H, e.what());
        return false;
    }
    const size_t npix = size_t(pixels);
    std::vector<double> featureSum;  // N xyz, P xyz, Albedo rgb, Z; only when a feature exists
    try {
        if (features != 0) featureSum.assign(npix * 10, 0.0);
    } catch (const std::exception& e) {
        err = fmt::format("cannot allocate the feature sums for {}x{}: {}", W, H, e.what());
        return false;
    }

    // 2. Pixels, file by file, in blocks of rows (memory: one block per file at a time).
    const int rowsPerBlock = std::max(1, opt.rowsPerBlock);
    const int64_t blocksPerFile = (H + rowsPerBlock - 1) / rowsPerBlock;
    int64_t blocksDone = 0;
    std::vector<uint64_t> hashes;
    std::vector<float> rows;
    for (size_t j = 0; j < files.size(); ++j) {
        InputFile& f = files[j];
        f.in = ImageInput::open(f.path);
        if (!f.in || f.in->spec().x != f.spec.x || f.in->spec().y != f.spec.y ||
            f.in->spec().width != f.spec.width || f.in->spec().height != f.spec.height ||
            f.in->spec().nchannels != f.spec.nchannels) {
            err = f.in ? f.path + ": changed while being ingested"
                       : fmt::format("{}: {}", f.path, oneLine(OIIO::geterror()));
            return false;
        }
        const double n = double(f.spp);
        std::vector<int> used(f.beauty.index.begin(), f.beauty.index.end());
        for (int i : f.features.normal) used.push_back(i);
        for (int i : f.features.position) used.push_back(i);
        for (int i : f.features.albedo) used.push_back(i);
        used.push_back(f.features.depth);
        for (int i : aovIndex) used.push_back(i);
        const std::vector<SubimageRead> reads = readsFor(f, used);
        int64_t nonFiniteAov = 0;
        // Where each used channel lands in the block read of its subimage.
        uint64_t hash = kFnvBasis;
        int64_t nonFinite = 0, nonFinitePixels = 0;
        for (int y0 = 0; y0 < H; y0 += rowsPerBlock) {
            const int y1 = std::min(H, y0 + rowsPerBlock);
            const size_t bpix = size_t(y1 - y0) * size_t(W);
            // One contiguous read per subimage; `value(i, q)` is channel i at block pixel q.
            std::vector<size_t> base(reads.size());
            size_t total = 0;
            for (size_t r = 0; r < reads.size(); ++r) {
                base[r] = total;
                total += bpix * size_t(reads[r].chend - reads[r].chbegin);
            }
            rows.resize(total);
            for (size_t r = 0; r < reads.size(); ++r)
                if (!f.in->read_scanlines(reads[r].subimage, 0, f.spec.y + y0, f.spec.y + y1, 0,
                                          reads[r].chbegin, reads[r].chend, TypeDesc::FLOAT,
                                          rows.data() + base[r])) {
                    err = fmt::format("{}: {}", f.path, oneLine(f.in->geterror()));
                    return false;
                }
            const auto locate = [&](int i, size_t& off, size_t& stride) {
                const auto [sub, ch] = f.where[size_t(i)];
                for (size_t r = 0; r < reads.size(); ++r)
                    if (reads[r].subimage == sub) {
                        stride = size_t(reads[r].chend - reads[r].chbegin);
                        off = base[r] + size_t(ch - reads[r].chbegin);
                    }
            };
            size_t rgbOff[3], rgbStride[3];
            for (int c = 0; c < 3; ++c) locate(f.beauty.index[size_t(c)], rgbOff[c], rgbStride[c]);
            for (size_t q = 0; q < bpix; ++q) {
                const size_t p = size_t(y0) * size_t(W) + q;
                float rgb[3];
                bool finite = true;
                for (int c = 0; c < 3; ++c) {
                    rgb[c] = rows[rgbOff[c] + q * rgbStride[c]];
                    if (!std::isfinite(rgb[c])) {
                        ++nonFinite;
                        finite = false;
                    }
                }
                nonFinitePixels += !finite;
                hash = fnv1a(hash, rgb, sizeof rgb);
                const size_t k = p * size_t(M) + j;
                for (int c = 0; c < 3; ++c) img.bufferMean[k * 3 + size_t(c)] = rgb[c];
                img.bufferCount[k] = float(n);
            }
            // Features: count-weighted sums in double (the file's value stands for its n samples).
            const auto addFeature = [&](int i, size_t slot) {
                if (i < 0) return;
                size_t off = 0, stride = 1;
                locate(i, off, stride);
                for (size_t q = 0; q < bpix; ++q)
                    featureSum[(size_t(y0) * size_t(W) + q) * 10 + slot] +=
                        n * double(rows[off + q * stride]);
            };
            for (size_t c = 0; c < 3; ++c) {
                addFeature(f.features.normal[c], c);
                addFeature(f.features.position[c], 3 + c);
                addFeature(f.features.albedo[c], 6 + c);
            }
            addFeature(f.features.depth, 9);
            // AOVs: file j's values are sub-buffer j's, as the beauty's are.
            for (size_t a = 0; a < A; ++a) {
                size_t off = 0, stride = 1;
                locate(aovIndex[a], off, stride);
                for (size_t q = 0; q < bpix; ++q) {
                    const size_t k = (size_t(y0) * size_t(W) + q) * size_t(M) + j;
                    const float v = rows[off + q * stride];
                    nonFiniteAov += !std::isfinite(v);
                    img.aov[k * A + a] = v;
                }
            }
            ++blocksDone;
            if (opt.progress) opt.progress(blocksDone, blocksPerFile * int64_t(files.size()));
        }
        for (size_t i = 0; i < hashes.size(); ++i)
            if (hashes[i] == hash) {
                err = fmt::format("{}: holds the same RGB pixels as {} (the same render twice?)",
                                  f.path, files[i].path);
                return false;
            }
        hashes.push_back(hash);
        h.seeds += fmt::format("{}h{:016x}", j ? "," : "", hash);
        if (nonFinite) {
            report.nonFiniteValues += nonFinite;
            report.warnings.push_back(fmt::format(
                "{}: {} non-finite RGB values (NaN/Inf) in {} pixels: the plain mean there is "
                "non-finite; the robust estimators leave that sub-buffer out",
                f.path, nonFinite, nonFinitePixels));
        }
        if (nonFiniteAov) {
            report.nonFiniteAovValues += nonFiniteAov;
            report.warnings.push_back(fmt::format(
                "{}: {} non-finite AOV values (NaN/Inf): each is left out of its channel alone, "
                "the other sub-buffers' weights renormalised (docs/aovs.md)",
                f.path, nonFiniteAov));
        }
        f.in.reset();  // close each file once read
    }

    // 3. Moments from the buffers, in double; features normalised; absent ones NaN.
    const double N = totalSpp;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (size_t p = 0; p < npix; ++p) {
        img.count[p] = float(N);
        for (size_t c = 0; c < 3; ++c) {
            double sum = 0.0;
            for (size_t j = 0; j < size_t(M); ++j) {
                const size_t k = p * size_t(M) + j;
                sum += double(img.bufferCount[k]) * double(img.bufferMean[k * 3 + c]);
            }
            const double mean = sum / N;
            img.mean[p * 3 + c] = float(mean);
            img.beauty[p * 3 + c] = float(mean);
            img.variance[p * 3 + c] = float(bufferVariance(img, p, c, mean));
        }
        img.coverage[p] = nan;
        if (features == 0) {
            for (size_t c = 0; c < 3; ++c)
                img.normal[p * 3 + c] = img.position[p * 3 + c] = img.albedo[p * 3 + c] = nan;
            img.depth[p] = nan;
            continue;
        }
        const double* fs = &featureSum[p * 10];
        for (size_t c = 0; c < 3; ++c) {
            img.normal[p * 3 + c] = features & kFeatureNormal ? float(fs[c] / N) : nan;
            img.position[p * 3 + c] = features & kFeaturePosition ? float(fs[3 + c] / N) : nan;
            img.albedo[p * 3 + c] = features & kFeatureAlbedo ? float(fs[6 + c] / N) : nan;
        }
        img.depth[p] = features & kFeatureDepth ? float(fs[9] / N) : nan;
    }
    out = std::move(img);
    return true;
}

}  // namespace mcstat
