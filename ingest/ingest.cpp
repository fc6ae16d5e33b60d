// Ingest of renderer output (include/mcstat/ingest.h, docs/ingest.md): many renders of one image,
// one per seed, become one statistics file with one sub-buffer per file.
#include "mcstat/ingest.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <fnmatch.h>
#include <glob.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <set>

#include "mcstat/exr-codec/fd_stream.h"
#include "mcstat/exr-codec/flat_part_reader.h"
#include "mcstat/color.h"
#include "mcstat/core/colour_space.h"
#include "mcstat/core/parallel.h"
#include "mcstat/core/params.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/image/image_spec.h"
#include "mcstat/image/render_layout.h"
#include "mcstat/exr-codec/exr_headers.h"

namespace mcstat {

namespace {

using OIIO::ImageInput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

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
/// RenderMan prefix theirs), else "unknown renderer". Kept as the file says it, like the channel
/// names: what shows it (--info, provenance attributes, the plugin) shows it through printable().
std::string rendererOf(const ImageSpec& spec) {
    for (const char* k : {"Software", "software"})
        if (std::string s = spec.get_string_attribute(k); !s.empty()) return s;
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

/// The file's `chromaticities` attribute (red, green, blue, white xy), when it has one.
bool chromaticitiesOf(const ImageSpec& spec, Chromaticities& xy) {
    const OIIO::ParamValue* c =
        spec.find_attribute("chromaticities", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8));
    if (c == nullptr) return false;
    const float* v = static_cast<const float*>(c->data());
    xy = Chromaticities{v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7]};
    return true;
}

}  // namespace

bool colourSpaceOf(const ImageSpec& spec, std::string& space, std::string& source,
                   std::string& problem) {
    space.clear();
    source.clear();
    // 1. colorInteropID (OpenEXR 3.4; OIIO passes an EXR's unknown attributes by name).
    for (const char* key : {"colorInteropID", "openexr:colorInteropID"}) {
        const std::string id = spec.get_string_attribute(key);
        if (id.empty()) continue;
        const WorkingSpace* ws = findWorkingSpace(id);
        if (!ws) {
            problem = fmt::format(
                "colorInteropID '{}' is not a scene-linear space mcstat knows (known: {})",
                printable(id), knownWorkingSpaceNames());
            return false;
        }
        // chromaticities that say otherwise make the file ambiguous: which one is right?
        if (Chromaticities xy; chromaticitiesOf(spec, xy)) {
            if (matchChromaticities(xy) != ws) {
                problem = fmt::format(
                    "colorInteropID '{}' is {} but the chromaticities ({}) are not: the file "
                    "contradicts itself; fix its metadata",
                    printable(id), ws->name, chromaticitiesText(xy));
                return false;
            }
        }
        space = ws->name;
        source = "colorInteropID " + printable(id);
        return true;
    }
    // 2. chromaticities: red, green, blue, white xy.
    if (Chromaticities xy; chromaticitiesOf(spec, xy)) {
        const WorkingSpace* ws = matchChromaticities(xy);
        if (!ws) {
            problem = fmt::format(
                "chromaticities ({}) are those of no space mcstat knows (known: {}); convert the "
                "renders to one of them",
                chromaticitiesText(xy), knownWorkingSpaceNames());
            return false;
        }
        space = ws->name;
        source = "chromaticities";
        return true;
    }
    // 3. oiio:ColorSpace, which OIIO sets "Linear" for any float EXR (no information).
    const std::string cs = spec.get_string_attribute("oiio:ColorSpace");
    if (cs.empty() || OIIO::Strutil::iequals(cs, "Linear")) return true;
    if (const WorkingSpace* ws = findWorkingSpace(cs)) {
        space = ws->name;
        source = "oiio:ColorSpace " + printable(cs);
        return true;
    }
    problem = fmt::format(
        "oiio:ColorSpace '{}' is not scene-linear (a display encoding such as an sRGB PNG or "
        "JPEG, or a space mcstat does not know): ingest takes scene-linear renders; convert "
        "them first (e.g. oiiotool IN --colorconvert {} lin_rec709 -o OUT.exr)",
        printable(cs), printable(cs));
    return false;
}

namespace {

/// The space of an input whose metadata names none (docs/colour.md): --ingest:colorspace= when
/// given (the user's word for this ingest), else what a rule of the OCIO config's file rules other
/// than its Default one says of the path, else lin_rec709. A rule naming a space that is not
/// scene-linear, or one mcstat cannot place, is refused as the same tag in the file would be.
bool untaggedSpace(const std::string& path, const IngestOptions& opt, std::string& space,
                   std::string& source, std::string& err) {
    if (!opt.colorSpace.empty()) {
        space = opt.colorSpace;
        source = "untagged, colorspace=" + opt.colorSpace;
        return true;
    }
    std::string ocioName, known, why;
    bool sceneLinear = false;
    if (!fileRuleColorSpace(path, ocioName, known, sceneLinear, why)) {
        err = path + ": " + why;
        return false;
    }
    if (ocioName.empty()) {
        space = kSceneLinear;
        source = "untagged, taken as lin_rec709";
        return true;
    }
    if (known.empty()) {
        err = fmt::format(
            "{}: the OCIO config's file rules say '{}', which is {}: ingest takes scene-linear "
            "renders in a space it knows ({}); convert them first, or give "
            "--ingest:colorspace=NAME",
            path, printable(ocioName),
            sceneLinear ? "a scene-linear space mcstat cannot place"
                        : "not scene-linear (a display encoding or data)",
            knownWorkingSpaceNames());
        return false;
    }
    space = known;
    source = "the OCIO config's file rules: " + printable(ocioName);
    return true;
}

/// One input file, opened, with the channels mcstat reads from it.
struct InputFile {
    std::string path;
    std::unique_ptr<ImageInput> in;
    ImageSpec spec;  ///< subimage 0
    std::vector<std::string> names;
    std::vector<std::pair<int, int>> where;
    std::vector<std::string> rawNames;  ///< each channel's name in its part (names qualify some)
    /// Per subimage: its part name when the file has several parts ("" for a one-part file).
    std::vector<std::string> partNames;
    BeautyChannels beauty;
    FeatureChannels features;
    int64_t spp = 0;
    std::string sppKey;
    std::string space;        ///< its working space (colourSpaceOf, or the assumed one)
    std::string spaceSource;  ///< what said so: "colorInteropID lin_ap1_scene", "untagged: ..."
};

/// The channel names of every subimage of `in` (see listChannels); leaves `in` on some subimage.
void channelsOf(ImageInput& in, std::vector<std::string>& names,
                std::vector<std::pair<int, int>>& where,
                std::vector<std::string>* partNames = nullptr,
                std::vector<std::string>* rawNames = nullptr) {
    names.clear();
    if (rawNames) rawNames->clear();
    where.clear();
    if (partNames) partNames->clear();
    for (int sub = 0; in.seek_subimage(sub, 0); ++sub) {
        const ImageSpec& s = in.spec();
        const std::string part = s.get_string_attribute("oiio:subimagename");
        if (partNames) partNames->push_back(part.empty() ? fmt::format("part{}", sub) : part);
        for (int c = 0; c < s.nchannels; ++c) {
            const std::string raw = s.channel_name(c);
            std::string n = raw;
            if (sub > 0 && n.find('.') == std::string::npos && !part.empty()) n = part + "." + n;
            if (std::find(names.begin(), names.end(), n) != names.end()) continue;  // first wins
            names.push_back(n);
            if (rawNames) rawNames->push_back(raw);
            where.emplace_back(sub, c);
        }
        if (sub > 4096) break;  // a sane bound on parts
    }
    if (partNames && partNames->size() == 1) partNames->front().clear();  // one part: no name
}

/// Opens a render with the reader its name says (OpenEXR for .exr) and no other. OIIO's
/// ImageInput::open tries every format plugin in turn when that reader refuses the file, which
/// loads dozens of libraries (measured under the fuzzer: 11 s and 2 GB for a damaged 2 KB EXR) only
/// to report the file as something else; the named reader's own message says what is wrong.
std::unique_ptr<ImageInput> openRender(const std::string& path, int64_t maxPixels,
                                       std::string& err) {
    // Sizes the header claims, against the file and the pixel limit, before OpenEXR allocates
    // them (its reader sizes line buffers by the data window's width when it opens the file).
    if (!checkExrAttributeSizes(path, err, maxPixels)) return nullptr;
    std::unique_ptr<ImageInput> in = ImageInput::create(path, false);
    if (!in) {
        err = fmt::format("{}: {}", path, libraryMessage(OIIO::geterror()));
        return nullptr;
    }
    ImageSpec spec;
    if (!in->open(path, spec)) {
        const std::string why = in->geterror();
        err = fmt::format("{}: {}", path, libraryMessage(why.empty() ? OIIO::geterror() : why));
        return nullptr;
    }
    return in;
}

bool openInput(const std::string& path, int64_t maxPixels, InputFile& f, std::string& err) {
    f.path = path;
    if (!OIIO::Filesystem::is_regular(path)) {
        err = fmt::format("{}: {}", path,
                          OIIO::Filesystem::exists(path) ? "not a regular file" : "no such file");
        return false;
    }
    f.in = openRender(path, maxPixels, err);
    if (!f.in) return false;
    f.spec = f.in->spec();
    if (f.spec.deep) {
        err = path + ": a deep image; ingest reads flat renders (one image per seed)";
        return false;
    }
    if (f.spec.depth > 1) {
        err = path + ": a volume image; ingest reads flat 2D renders";
        return false;
    }
    channelsOf(*f.in, f.names, f.where, &f.partNames, &f.rawNames);
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
        err = fmt::format("{}: has no channel '{}' that {} has ({})", f.path, printable(n),
                          first.path, kSame);
        return false;
    }
    if (const std::string n = firstMissing(f.names, first.names); !n.empty()) {
        err = fmt::format("{}: has a channel '{}' that {} has not ({})", f.path, printable(n),
                          first.path, kSame);
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
    auto in = openRender(path, ReadLimits().maxPixels, err);
    if (!in) return false;
    channelsOf(*in, names, where);
    return true;
}

bool readRenderRGB(const std::string& path, const std::string& layer, OIIO::ImageBuf& out,
                   BeautyChannels* found, std::string& err) {
    InputFile f;
    if (!openInput(path, ReadLimits().maxPixels, f, err)) return false;
    std::string problem;
    if (!findBeauty(f.names, layer, f.beauty, problem)) {
        err = path + ": " + problem;
        return false;
    }
    OIIO::ImageBuf buf(floatSpec(f.spec.roi(), {"R", "G", "B"}, f.spec.roi_full()));
    const ImageSpec& spec = buf.spec();
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
            err = fmt::format("{}: {}", path, libraryMessage(f.in->geterror()));
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

namespace {

/// Refuses a request no file can satisfy: no files, more than a statistics file's sub-buffers,
/// samples per file out of range.
bool checkRequest(const std::vector<std::string>& paths, const IngestOptions& opt,
                  std::string& err) {
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
    return true;
}

/// What every source over the same renders shares: the files and what their headers settled
/// (phase 1), and once a pass has read every row, each file's RGB hash (the provenance in
/// mcstat:seeds) and what its pixels showed.
struct Ingest {
    IngestOptions opt;
    IngestReport report;
    std::vector<InputFile> files;  ///< headers only: no file is held open
    // Every channel but the beauty, kept per sub-buffer (docs/aovs.md).
    std::vector<AovChannel> aovs;
    std::vector<int> aovIndex;  ///< the channel index in every file of each of `aovs`
    double totalSpp = 0.0;      ///< samples per pixel over every file
    StatsHeader header;         ///< mcstat:seeds a placeholder of the final length until hashed
    bool hashed = false;        ///< a pass read every row: `hashes` and header.seeds are final
    bool aovsTallied = false;   ///< a pass read every row's AOVs: their NaN/Inf warnings given
    std::vector<uint64_t> hashes;

    const InputFile& first() const { return files[0]; }
    /// A warning the pixels give: into the report and to the caller's callback.
    void warnOfPixels(const std::string& w) {
        report.warnings.push_back(w);
        if (opt.warning) opt.warning(w);
    }
    int width() const { return files[0].spec.width; }
    int height() const { return files[0].spec.height; }
    int buffers() const { return int(files.size()); }  ///< M: one sub-buffer per file
};

/// Opens file j and reads its header: its layout against the first file's, its beauty and
/// feature channels, its samples per pixel.
bool readHeader(Ingest& s, size_t j, const std::string& path, std::string& err) {
    InputFile& f = s.files[j];
    // A statistics file (by its content, whatever its name) is not one render: read as an image,
    // it is its mean, and its sub-buffers would be lost (two files of M = 21 gave M = 2).
    FileContent content;
    std::string damaged;  // left to openInput, whose checks say what is wrong
    if (probeFileContent(path, content, damaged) && content.kind == FileContent::Stats) {
        err = path + " is a statistics file: combine statistics files with --merge";
        return false;
    }
    if (!openInput(path, s.opt.limits.maxPixels, f, err)) return false;
    std::string problem;
    // Every file uses the first file's beauty layer, so a file cannot switch layers.
    const std::string layer =
        j == 0 ? s.opt.layer
               : (s.files[0].beauty.layer.empty() ? std::string(".") : s.files[0].beauty.layer);
    if (j > 0 && !sameLayout(s.files[0], f, err)) return false;
    if (!findBeauty(f.names, layer, f.beauty, problem)) {
        err = f.path + ": " + problem;
        return false;
    }
    f.features = findFeatures(f.names, f.beauty);
    f.spp = s.opt.spp > 0 ? s.opt.spp : sppFromMetadata(f.spec, f.beauty, f.sppKey);
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
    std::string problem2;
    if (!colourSpaceOf(f.spec, f.space, f.spaceSource, problem2)) {
        err = f.path + ": " + problem2;
        return false;
    }
    if (f.space.empty() && !untaggedSpace(f.path, s.opt, f.space, f.spaceSource, err))
        return false;
    if (j > 0 && f.space != s.files[0].space) {
        err = fmt::format(
            "{} is {} ({}) but {} is {} ({}): the renders of one statistics file share one colour "
            "space (convert them, or give untagged ones --ingest:colorspace=)",
            s.files[0].path, s.files[0].space, s.files[0].spaceSource, f.path, f.space,
            f.spaceSource);
        return false;
    }
    s.report.spp.push_back(f.spp);
    f.in.reset();  // closed until its pixels are read: 999 inputs must not hold 999 files open
    return true;
}

/// Refuses an empty image or one larger than the limit of pixels.
bool checkImageSize(const Ingest& s, std::string& err) {
    const int W = s.width(), H = s.height();
    const int64_t pixels = int64_t(W) * int64_t(H);
    if (W <= 0 || H <= 0) {
        err = fmt::format("{}: empty image {}x{}", s.first().path, W, H);
        return false;
    }
    if (pixels > s.opt.limits.maxPixels) {
        err = fmt::format("{}: image {}x{} exceeds the limit of {} pixels", s.first().path, W, H,
                          s.opt.limits.maxPixels);
        return false;
    }
    return true;
}

/// Chooses the AOVs (every channel but the beauty, unless :aovs=0) within the format's limits.
bool chooseAovs(Ingest& s, std::string& err) {
    const InputFile& first = s.first();
    if (s.opt.aovs) s.aovIndex = aovChannelsOf(first, s.opt, s.aovs);
    if (s.aovs.size() > size_t(kMaxAovs)) {
        err = fmt::format("{}: {} channels besides the beauty; a statistics file holds at most {}",
                          first.path, s.aovs.size(), kMaxAovs);
        return false;
    }
    for (const AovChannel& a : s.aovs)
        if (a.name.size() > kMaxAovNameBytes) {
            err = fmt::format("{}: channel name '{}' is longer than {} bytes", first.path,
                              printable(a.name, 40), kMaxAovNameBytes);
            return false;
        }
    s.report.aovs = s.aovs;
    if (!s.opt.aovs && first.names.size() > 3)
        s.report.warnings.push_back(
            fmt::format("{}: {} channels besides the beauty's R, G, B left out as asked (:aovs=0)",
                        first.path, first.names.size() - 3));
    return true;
}

/// Refuses a result larger than the limit of bytes or with more samples than a count holds, and
/// warns about unequal samples per file and about a single file.
bool checkTotals(Ingest& s, std::string& err) {
    const InputFile& first = s.first();
    const int W = s.width(), H = s.height(), M = s.buffers();
    const int64_t pixels = int64_t(W) * int64_t(H);
    // The statistics image, plus 10 doubles per pixel for the feature sums when there are any.
    const double featureBytes = first.features.present != 0 ? 80.0 : 0.0;
    const double bytes = double(pixels) * (double(3 + 4 * M + 7 + 11) * 4.0 +
                                           double(M) * double(s.aovs.size()) * 4.0 + featureBytes);
    if (bytes > double(s.opt.limits.maxBytes)) {
        err = fmt::format("{} renders of {}x{} need {:.0f} bytes, exceeding the limit of {} bytes",
                          M, W, H, bytes, s.opt.limits.maxBytes);
        return false;
    }
    for (int64_t spp : s.report.spp) s.totalSpp += double(spp);
    if (s.totalSpp > kMaxCount) {
        err = fmt::format("{} samples per pixel in all exceed 2^24 (counts are float32 integers)",
                          s.totalSpp);
        return false;
    }
    const std::vector<InputFile>& files = s.files;
    for (size_t j = 1; j < files.size(); ++j)
        if (files[j].spp != files[0].spp) {
            s.report.warnings.push_back(fmt::format(
                "samples per file differ ({} in {}, {} in {}): sub-buffers of unequal counts; "
                "median-of-means estimators assume equal ones",
                files[0].spp, files[0].path, files[j].spp, files[j].path));
            break;
        }
    if (M == 1)
        s.report.warnings.push_back(fmt::format(
            "{}: only one file, so M = 1: every robust estimator returns the plain mean, and the "
            "variance is unknown",
            first.path));
    return true;
}

/// The frame a render belongs to, by its name (`name.0042.exr`: the number between the last two
/// dots) and by its metadata (Blender's `Frame`, a `frame` attribute); -1 in `name` / `meta` when
/// it does not say.
void frameOf(const InputFile& f, long long& name, long long& meta) {
    name = meta = -1;
    // The text between the last two dots, when it is a whole integer.
    const std::string file = OIIO::Filesystem::filename(f.path);
    const size_t last = file.rfind('.');
    const size_t before =
        last == std::string::npos || last == 0 ? std::string::npos : file.rfind('.', last - 1);
    if (before != std::string::npos) {
        const std::string digits = file.substr(before + 1, last - before - 1);
        int64_t v = 0;
        if (parseIntegerText(digits, v)) name = v;
    }
    for (const char* key : {"Frame", "frame"}) {
        const OIIO::ParamValue* p = f.spec.find_attribute(key);
        if (!p) continue;
        const std::string text = p->get_string();
        char* end = nullptr;
        const long long v = std::strtoll(text.c_str(), &end, 10);
        if (end != text.c_str() && *end == '\0') meta = v;
    }
}

/// Renders of one image are one frame: a glob that matched several frames (by name or by
/// metadata) would merge them into one image. Refused, naming the frames found.
bool checkOneFrame(const Ingest& s, std::string& err) {
    std::set<long long> byName, byMeta;
    for (const InputFile& f : s.files) {
        long long name = -1, meta = -1;
        frameOf(f, name, meta);
        if (name >= 0) byName.insert(name);
        if (meta >= 0) byMeta.insert(meta);
    }
    for (const auto& [frames, how] :
         {std::pair(&byName, "by their names"), std::pair(&byMeta, "by their Frame metadata")}) {
        if (frames->size() < 2) continue;
        std::vector<std::string> list;
        for (long long v : *frames) list.push_back(std::to_string(v));
        err = fmt::format(
            "the {} files are renders of {} frames ({}: {}), not of one image: "
            "ingest each frame by itself, e.g. --ingest 'shot_s*.#.exr' -o "
            "'shot.#.mcstat' (docs/ingest.md)",
            s.files.size(), frames->size(), how, fmt::join(list, ", "));
        return false;
    }
    return true;
}

/// 1. Every header first: layouts, channels, spp; nothing is allocated before they agree.
bool readHeaders(const std::vector<std::string>& paths, Ingest& s, std::string& err) {
    s.files.resize(paths.size());
    for (size_t j = 0; j < paths.size(); ++j)
        if (!readHeader(s, j, paths[j], err)) return false;
    s.report.beauty = s.first().beauty;
    s.report.features = s.first().features;
    return checkOneFrame(s, err) && checkImageSize(s, err) && chooseAovs(s, err) &&
           checkTotals(s, err);
}

/// mcstat:seeds of renders known by the hashes of their RGB: "h" and 16 hex digits per file. Until
/// a pass has read every row (`hashes` null), a placeholder of the same length: a statistics file
/// written while its rows are read gets the hashes in place when it is complete
/// (StatsFileWriter::commit).
std::string seedsText(const std::vector<uint64_t>* hashes, size_t files) {
    std::string s;
    for (size_t j = 0; j < files; ++j) {
        if (j) s += ',';
        s += hashes ? fmt::format("h{:016x}", (*hashes)[j]) : "h" + std::string(16, '-');
    }
    return s;
}

/// The result's header: its size and buffers, where its samples came from and (version 5) what
/// the render looked like.
void fillHeader(Ingest& s) {
    const InputFile& first = s.first();
    const std::vector<InputFile>& files = s.files;
    const int M = s.buffers();
    StatsHeader& h = s.header;
    h.formatVersion = kStatsFormatVersionProvenance;
    h.width = s.width();
    h.height = s.height();
    h.originX = first.spec.x;
    h.originY = first.spec.y;
    h.M = M;
    h.spp = int64_t(s.totalSpp);
    h.assignment = kAssignmentPerFile;
    h.variance = M >= 2 ? kVarianceBuffers : kVarianceUnknown;
    h.features = first.features.present;
    h.renderer = rendererOf(first.spec) + " via mcstat --ingest";
    h.colorSpace = first.space;
    for (size_t j = 0; j < files.size(); ++j)
        h.sources += (j ? "," : "") + OIIO::Filesystem::filename(files[j].path);
    // Version 5: what the render looked like, so that a result can replace one input.
    h.aovs = s.aovs;
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
    h.seeds = seedsText(nullptr, files.size());
}

/// Rows per chunk of a render as its compression stores them (OpenEXR: ZIPS, RLE and NONE 1, ZIP
/// and PXR24 16, PIZ, B44 and DWAA 32, DWAB 256; a tiled file its tile height): blocks of rows
/// that start on a multiple of it never decode a chunk twice.
int chunkRowsOf(const ImageSpec& spec) {
    if (spec.tile_height > 0) return spec.tile_height;
    const std::string c = OIIO::Strutil::lower(spec.get_string_attribute("compression"));
    using OIIO::Strutil::starts_with;
    if (starts_with(c, "zips") || starts_with(c, "rle") || starts_with(c, "none")) return 1;
    if (starts_with(c, "zip") || starts_with(c, "pxr24")) return 16;
    if (starts_with(c, "dwab")) return 256;
    if (starts_with(c, "piz") || starts_with(c, "b44") || starts_with(c, "dwaa")) return 32;
    return 16;
}

/// A render open for its pixels: through OpenEXR's Core API when it reads every channel used
/// (scan-line parts of the image's data window, FLOAT or HALF, ZIP and ZIPS inflated by libdeflate,
/// exr-deep/flat_part_reader.h), else through OIIO (tiled files, B44 and DWA, other formats).
/// MCSTAT_EXR_READER=cpp in the environment takes OIIO's reader always (tests compare the two).
struct OpenRender {
    detail::Fd fd;
    std::unique_ptr<detail::FlatPartReader> core;  ///< or
    std::unique_ptr<ImageInput> oiio;
};

/// Whether the environment asks for OIIO's reader (OpenEXR's C++ API) for renders.
bool oiioReaderForced() {
    const char* v = std::getenv("MCSTAT_EXR_READER");
    return v != nullptr && std::string(v) == "cpp";
}

/// Opens `f` through the Core API when it can read every channel of `used`; false leaves `r`
/// for OIIO (no error: OIIO's reader judges what the Core one does not take).
bool openCore(const InputFile& f, const std::vector<int>& used, OpenRender& r) {
    if (oiioReaderForced()) return false;
    detail::Fd fd(::open(f.path.c_str(), O_RDONLY | O_CLOEXEC));
    struct stat st {};
    if (fd.get() < 0 || ::fstat(fd.get(), &st) != 0 || !S_ISREG(st.st_mode)) return false;
    std::string problem;
    unsigned char magic[4] = {};
    if (detail::preadFull(fd.get(), magic, 4, 0) != 4 || magic[0] != 0x76 || magic[1] != 0x2f ||
        magic[2] != 0x31 || magic[3] != 0x01)
        return false;  // not OpenEXR
    auto core = std::make_unique<detail::FlatPartReader>();
    if (!detail::checkExrAttributeSizes(fd.get(), uint64_t(st.st_size), f.path, problem) ||
        !core->open(fd.get(), uint64_t(st.st_size), f.path, f.spec.x, f.spec.y, f.spec.width,
                    f.spec.height, problem))
        return false;
    for (int i : used)
        if (i >= 0 && !core->readsAsFloat(f.where[size_t(i)].first, f.rawNames[size_t(i)]))
            return false;
    r.fd = std::move(fd);
    r.core = std::move(core);
    return true;
}

/// Reopens `f` for the pixels of channels `used` into `r`, refusing it if it changed since its
/// header was read.
bool reopenInput(const InputFile& f, const std::vector<int>& used, OpenRender& r,
                 std::string& err) {
    if (openCore(f, used, r)) return true;
    r.oiio = openRender(f.path, ReadLimits().maxPixels, err);
    if (!r.oiio) return false;
    const ImageSpec& now = r.oiio->spec();
    if (now.x != f.spec.x || now.y != f.spec.y || now.width != f.spec.width ||
        now.height != f.spec.height || now.nchannels != f.spec.nchannels) {
        err = f.path + ": changed while being ingested";
        r.oiio.reset();
        return false;
    }
    return true;
}

/// The channels read from `f`: the beauty, and when asked the features and the AOVs (-1 for an
/// absent one).
std::vector<int> usedChannels(const InputFile& f, const std::vector<int>& aovIndex, bool features,
                              bool aovs) {
    std::vector<int> used(f.beauty.index.begin(), f.beauty.index.end());
    if (features) {
        for (int i : f.features.normal) used.push_back(i);
        for (int i : f.features.position) used.push_back(i);
        for (int i : f.features.albedo) used.push_back(i);
        used.push_back(f.features.depth);
    }
    if (aovs)
        for (int i : aovIndex) used.push_back(i);
    return used;
}

/// Rows [y0, y1) of one file's channels as read (one contiguous read per subimage, read r at
/// `base[r]`).
struct RowBlock {
    const InputFile& f;
    std::vector<SubimageRead> reads;
    std::vector<float> rows;
    std::vector<size_t> base;
    size_t pixels = 0;
};

/// Reads rows [y0, y1) (0-based) of channels `used` (grouped as b.reads) from `in` into b.rows,
/// pixel-interleaved per subimage as OIIO's read_scanlines gives them.
bool readBlock(OpenRender& in, const std::vector<int>& used, RowBlock& b, int y0, int y1, int W,
               std::string& err) {
    b.pixels = size_t(y1 - y0) * size_t(W);
    b.base.assign(b.reads.size(), 0);
    size_t total = 0;
    for (size_t r = 0; r < b.reads.size(); ++r) {
        b.base[r] = total;
        total += b.pixels * size_t(b.reads[r].chend - b.reads[r].chbegin);
    }
    b.rows.resize(total);
    if (in.core) {
        // Every channel used by name into its place of the same layout, once (a feature channel
        // is an AOV too).
        std::vector<detail::PartSlices> parts(b.reads.size());
        for (size_t r = 0; r < b.reads.size(); ++r) parts[r].part = b.reads[r].subimage;
        std::vector<int> once(used);
        std::sort(once.begin(), once.end());
        once.erase(std::unique(once.begin(), once.end()), once.end());
        for (int i : once) {
            if (i < 0) continue;
            const auto [sub, ch] = b.f.where[size_t(i)];
            for (size_t r = 0; r < b.reads.size(); ++r) {
                if (b.reads[r].subimage != sub) continue;
                const size_t nch = size_t(b.reads[r].chend - b.reads[r].chbegin);
                char* base = reinterpret_cast<char*>(b.rows.data() + b.base[r] +
                                                     size_t(ch - b.reads[r].chbegin));
                parts[r].slices.push_back({b.f.rawNames[size_t(i)], base, nch * sizeof(float),
                                           nch * sizeof(float) * size_t(W)});
            }
        }
        std::string problem;
        if (in.core->read(parts, y0, y1 - y0, 1, problem) != detail::FlatPartReader::Result::Ok) {
            err = fmt::format("{}: {}", b.f.path, problem);
            return false;
        }
        return true;
    }
    for (size_t r = 0; r < b.reads.size(); ++r)
        if (!in.oiio->read_scanlines(b.reads[r].subimage, 0, b.f.spec.y + y0, b.f.spec.y + y1, 0,
                                     b.reads[r].chbegin, b.reads[r].chend, TypeDesc::FLOAT,
                                     b.rows.data() + b.base[r])) {
            err = fmt::format("{}: {}", b.f.path, libraryMessage(in.oiio->geterror()));
            return false;
        }
    return true;
}

/// Where channel i lands in the block read of its subimage: `off` of block pixel 0 and `stride`
/// from one pixel to the next.
void locate(const RowBlock& b, int i, size_t& off, size_t& stride) {
    const auto [sub, ch] = b.f.where[size_t(i)];
    for (size_t r = 0; r < b.reads.size(); ++r)
        if (b.reads[r].subimage == sub) {
            stride = size_t(b.reads[r].chend - b.reads[r].chbegin);
            off = b.base[r] + size_t(ch - b.reads[r].chbegin);
        }
}

/// What one file's pixels showed over the rows hashed so far: the hash of its RGB (the same
/// render twice), its NaN/Inf.
struct FileTally {
    uint64_t hash = kFnvBasis;
    int64_t nonFinite = 0, nonFinitePixels = 0, nonFiniteAov = 0;
};

constexpr int kFeatureSlots = 10;  ///< N xyz, P xyz, albedo rgb, Z

}  // namespace

// ---- the pixels, by blocks of rows
// ----------------------------------------------------------------

struct IngestSource::Impl {
    std::shared_ptr<Ingest> plan;
    std::string name;
    int nthreads = 0;
    /// Files held open between reads (at most kKeepOpen files; more are opened per block).
    std::vector<std::unique_ptr<OpenRender>> open;
    std::vector<FileTally> tallies;
    int hashedRows = 0;  ///< rows [0, hashedRows) of every file hashed by this source
    int aovRows = 0;     ///< rows [0, aovRows) of every file's AOVs tallied by this source
    bool passDone = false;
    int64_t blocksDone = 0;
    std::vector<float> featureRaw;  ///< a block's features, [(j * pixels + q) * 10 + slot]
    std::vector<double> featureSum;

    static constexpr size_t kKeepOpen = 64;

    bool readFile(size_t j, int y0, int y1, int blockRow0, bool features, bool aovs,
                  StatsImage& block, std::string& err);
    bool finishPass(std::string& err);
    void finishAovPass();
    void moments(StatsImage& block, size_t q0, size_t q1, bool features);
};

IngestSource::IngestSource() : impl_(std::make_unique<Impl>()) {}
IngestSource::~IngestSource() = default;

bool IngestSource::init(const std::vector<std::string>& paths, const IngestOptions& opt,
                        std::string& err, int nthreads) {
    impl_ = std::make_unique<Impl>();
    auto plan = std::make_shared<Ingest>();
    plan->opt = opt;
    if (!checkRequest(paths, opt, err) || !readHeaders(paths, *plan, err)) return false;
    fillHeader(*plan);
    impl_->plan = std::move(plan);
    impl_->nthreads = nthreads;
    impl_->name = paths.size() == 1 ? paths[0]
                                    : fmt::format("ingest of {} renders ({}, ..., {})",
                                                  paths.size(), paths.front(), paths.back());
    impl_->tallies.assign(paths.size(), FileTally());
    return true;
}

std::unique_ptr<IngestSource> IngestSource::clone(int nthreads) const {
    auto c = std::make_unique<IngestSource>();
    c->impl_->plan = impl_->plan;
    c->impl_->name = impl_->name;
    c->impl_->nthreads = nthreads;
    if (impl_->plan) c->impl_->tallies.assign(impl_->plan->files.size(), FileTally());
    return c;
}

const StatsHeader& IngestSource::header() const {
    static const StatsHeader kNone;
    return impl_->plan ? impl_->plan->header : kNone;
}
const std::string& IngestSource::name() const { return impl_->name; }
const IngestReport& IngestSource::report() const {
    static const IngestReport kNone;
    return impl_->plan ? impl_->plan->report : kNone;
}
bool IngestSource::hashed() const { return impl_->plan && impl_->plan->hashed; }
int IngestSource::chunkRows() const {
    return impl_->plan ? chunkRowsOf(impl_->plan->first().spec) : 1;
}
int IngestSource::decodeThreads() const {
    return impl_->plan ? std::max(1, std::min(threadCount(impl_->nthreads), impl_->plan->buffers()))
                       : 1;
}
int IngestSource::blocksHeld() const {
    // The features of every file are held per block before they are summed (10 floats per
    // buffer, about as much as the sub-buffers' 4): counted as a second block.
    return impl_->plan && impl_->plan->first().features.present != 0 ? 2 : 1;
}

/// Reads rows [y0, y1) of file j into `block` (whose row 0 is image row blockRow0): its RGB as
/// sub-buffer j with the file's count, hashed and tallied over the rows not hashed yet; its
/// features into featureRaw; its AOVs into sub-buffer j's.
bool IngestSource::Impl::readFile(size_t j, int y0, int y1, int blockRow0, bool features, bool aovs,
                                  StatsImage& block, std::string& err) {
    const Ingest& s = *plan;
    const InputFile& f = s.files[j];
    std::unique_ptr<OpenRender> once;
    std::unique_ptr<OpenRender>& in = j < open.size() ? open[j] : once;
    // Opened for every channel a read may ask for, so that a kept file serves any parts.
    if (!in) {
        in = std::make_unique<OpenRender>();
        if (!reopenInput(f, usedChannels(f, s.aovIndex, true, true), *in, err)) {
            in.reset();
            return false;
        }
    }
    const int W = s.width();
    const std::vector<int> used = usedChannels(f, s.aovIndex, features, aovs);
    RowBlock b{f, readsFor(f, used), {}, {}, 0};
    if (!readBlock(*in, used, b, y0, y1, W, err)) return false;
    const size_t M = size_t(s.buffers()), A = s.aovs.size();
    const size_t q0 = size_t(y0 - blockRow0) * size_t(W);  // the rows' first pixel in `block`
    const float n = float(f.spp);
    FileTally& t = tallies[j];
    // RGB: stored, and hashed and tallied over the rows this source has not hashed yet (a
    // window filter reads a block's halo rows twice; a pass that skips rows hashes nothing more).
    size_t rgbOff[3], rgbStride[3];
    for (int c = 0; c < 3; ++c) locate(b, f.beauty.index[size_t(c)], rgbOff[c], rgbStride[c]);
    const size_t hashFrom =
        y0 <= hashedRows && hashedRows < y1 ? size_t(hashedRows - y0) * size_t(W) : b.pixels;
    for (size_t q = 0; q < b.pixels; ++q) {
        float rgb[3];
        for (int c = 0; c < 3; ++c) rgb[c] = b.rows[rgbOff[c] + q * rgbStride[c]];
        const size_t k = (q0 + q) * M + j;
        for (int c = 0; c < 3; ++c) block.bufferMean[k * 3 + size_t(c)] = rgb[c];
        block.bufferCount[k] = n;
        if (q < hashFrom) continue;
        bool finite = true;
        for (int c = 0; c < 3; ++c)
            if (!std::isfinite(rgb[c])) {
                ++t.nonFinite;
                finite = false;
            }
        t.nonFinitePixels += !finite;
        t.hash = fnv1a(t.hash, rgb, sizeof rgb);
    }
    if (features) {
        const auto take = [&](int i, size_t slot) {
            if (i < 0) return;
            size_t off = 0, stride = 1;
            locate(b, i, off, stride);
            float* raw = featureRaw.data() + (j * block.pixelCount() + q0) * kFeatureSlots;
            for (size_t q = 0; q < b.pixels; ++q)
                raw[q * kFeatureSlots + slot] = b.rows[off + q * stride];
        };
        for (size_t c = 0; c < 3; ++c) {
            take(f.features.normal[c], c);
            take(f.features.position[c], 3 + c);
            take(f.features.albedo[c], 6 + c);
        }
        take(f.features.depth, 9);
    }
    if (aovs) {
        const size_t tallyFrom =
            y0 <= aovRows && aovRows < y1 ? size_t(aovRows - y0) * size_t(W) : b.pixels;
        for (size_t a = 0; a < A; ++a) {
            size_t off = 0, stride = 1;
            locate(b, s.aovIndex[a], off, stride);
            for (size_t q = 0; q < b.pixels; ++q) {
                const float v = b.rows[off + q * stride];
                if (q >= tallyFrom) t.nonFiniteAov += !std::isfinite(v);
                block.aov[((q0 + q) * M + j) * A + a] = v;
            }
        }
    }
    if (j >= open.size()) in.reset();  // more files than are kept open: closed after each block
    return true;
}

/// Moments of block pixels [q0, q1) from the buffers, in double; features from featureRaw,
/// count-weighted over the files in their order; absent ones NaN.
void IngestSource::Impl::moments(StatsImage& img, size_t q0, size_t q1, bool features) {
    const Ingest& s = *plan;
    const size_t M = size_t(s.buffers()), npix = img.pixelCount();
    const unsigned present = features ? s.first().features.present : 0u;
    const double N = s.totalSpp;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (size_t p = q0; p < q1; ++p) {
        img.count[p] = float(N);
        for (size_t c = 0; c < 3; ++c) {
            double sum = 0.0;
            for (size_t j = 0; j < M; ++j) {
                const size_t k = p * M + j;
                sum += double(img.bufferCount[k]) * double(img.bufferMean[k * 3 + c]);
            }
            const double mean = sum / N;
            img.mean[p * 3 + c] = float(mean);
            img.beauty[p * 3 + c] = float(mean);
            img.variance[p * 3 + c] = float(bufferVariance(img, p, c, mean));
        }
        img.coverage[p] = nan;
        if (present == 0) {
            for (size_t c = 0; c < 3; ++c)
                img.normal[p * 3 + c] = img.position[p * 3 + c] = img.albedo[p * 3 + c] = nan;
            img.depth[p] = nan;
            continue;
        }
        double fs[kFeatureSlots] = {};
        for (size_t j = 0; j < M; ++j) {
            const double n = double(s.files[j].spp);
            const float* raw = featureRaw.data() + (j * npix + p) * kFeatureSlots;
            for (int slot = 0; slot < kFeatureSlots; ++slot) fs[slot] += n * double(raw[slot]);
        }
        for (size_t c = 0; c < 3; ++c) {
            img.normal[p * 3 + c] = present & kFeatureNormal ? float(fs[c] / N) : nan;
            img.position[p * 3 + c] = present & kFeaturePosition ? float(fs[3 + c] / N) : nan;
            img.albedo[p * 3 + c] = present & kFeatureAlbedo ? float(fs[6 + c] / N) : nan;
        }
        img.depth[p] = present & kFeatureDepth ? float(fs[9] / N) : nan;
    }
}

/// After a pass over every row: refuses a second copy of a render, records the hashes (the
/// header's seeds) and the NaN/Inf warnings, once per set of renders; a later pass must find the
/// same hashes (a render that changed in between is refused).
bool IngestSource::Impl::finishPass(std::string& err) {
    Ingest& s = *plan;
    const size_t M = s.files.size();
    if (s.hashed) {
        for (size_t j = 0; j < M; ++j)
            if (tallies[j].hash != s.hashes[j]) {
                err = s.files[j].path + ": changed while being ingested";
                return false;
            }
        return true;
    }
    std::vector<uint64_t> hashes(M);
    for (size_t j = 0; j < M; ++j) {
        hashes[j] = tallies[j].hash;
        for (size_t i = 0; i < j; ++i)
            if (hashes[i] == hashes[j]) {
                err = fmt::format("{}: holds the same RGB pixels as {} (the same render twice?)",
                                  s.files[j].path, s.files[i].path);
                return false;
            }
    }
    std::vector<std::string> warnings;
    for (size_t j = 0; j < M; ++j) {
        const FileTally& t = tallies[j];
        if (t.nonFinite) {
            s.report.nonFiniteValues += t.nonFinite;
            warnings.push_back(fmt::format(
                "{}: {} non-finite RGB values (NaN/Inf) in {} pixels: the stored mean (part "
                "beauty) there is non-finite; --mean and the robust estimators leave that "
                "sub-buffer out",
                s.files[j].path, t.nonFinite, t.nonFinitePixels));
        }
    }
    s.hashes = std::move(hashes);
    s.header.seeds = seedsText(&s.hashes, M);
    s.hashed = true;
    for (const std::string& w : warnings) s.warnOfPixels(w);
    return true;
}

/// After a pass over every row's AOVs, the first of any source (a pass that read RGB only, such as
/// --info's, settles the hashes but not these): the AOVs' NaN/Inf warnings, once per set of
/// renders.
void IngestSource::Impl::finishAovPass() {
    Ingest& s = *plan;
    if (s.aovsTallied) return;
    s.aovsTallied = true;
    for (size_t j = 0; j < s.files.size(); ++j) {
        const FileTally& t = tallies[j];
        if (!t.nonFiniteAov) continue;
        s.report.nonFiniteAovValues += t.nonFiniteAov;
        s.warnOfPixels(fmt::format(
            "{}: {} non-finite AOV values (NaN/Inf): each is left out of its channel alone, the "
            "other sub-buffers' weights renormalised (docs/aovs.md)",
            s.files[j].path, t.nonFiniteAov));
    }
}

bool IngestSource::read(int firstRow, int rows, unsigned parts, StatsImage& block,
                        std::string& err) {
    Impl& im = *impl_;
    if (!im.plan) {
        err = "ingest: no renders to read from";
        return false;
    }
    const Ingest& s = *im.plan;
    const int W = s.width(), H = s.height();
    if (rows < 1 || firstRow < 0 || firstRow > H - rows || (parts & ~kStatsAllParts)) {
        err = fmt::format("{}: cannot read rows {}..{} of parts {:#x} (the image has {} rows)",
                          im.name, firstRow, int64_t(firstRow) + rows - 1, parts, H);
        return false;
    }
    if (im.open.empty() && s.files.size() <= Impl::kKeepOpen) im.open.resize(s.files.size());
    // The RGB of every file is read whatever `parts` asks: the beauty and the moments are its
    // mean and variance. Features and AOVs are read only when asked.
    const bool features = (parts & kStatsPartFeatures) && s.first().features.present != 0;
    const bool aovs = (parts & kStatsPartAovs) && !s.aovs.empty();
    const size_t M = size_t(s.buffers()), A = s.aovs.size();
    StatsImage& img = block;
    img.header = s.header;
    img.header.height = rows;
    img.header.originY = s.header.originY + firstRow;
    const size_t npix = size_t(rows) * size_t(W);
    try {
        img.beauty.resize(npix * 3);
        img.bufferMean.resize(npix * M * 3);
        img.bufferCount.resize(npix * M);
        img.bufferOffset.clear();
        img.count.resize(npix);
        img.mean.resize(npix * 3);
        img.variance.resize(npix * 3);
        img.normal.resize(npix * 3);
        img.position.resize(npix * 3);
        img.albedo.resize(npix * 3);
        img.depth.resize(npix);
        img.coverage.resize(npix);
        img.aov.resize(aovs ? npix * M * A : 0);
        im.featureRaw.resize(features ? npix * M * kFeatureSlots : 0);
    } catch (const std::exception& e) {
        err = fmt::format("{}: cannot allocate rows {}..{} ({}x{}, M = {}): {}", im.name, firstRow,
                          firstRow + rows - 1, W, rows, M, e.what());
        return false;
    }
    // Rows in steps of opt.rowsPerBlock: each step reads every file (in parallel, one file per
    // task), so a whole-image read holds one step of each file's channels at a time.
    const int step = std::max(1, s.opt.rowsPerBlock);
    const int64_t stepsPerPass = (H + step - 1) / step;
    std::vector<std::string> errs(M);
    for (int y0 = firstRow; y0 < firstRow + rows; y0 += step) {
        const int y1 = std::min(firstRow + rows, y0 + step);
        parallelFor(0, int64_t(M), 1, im.nthreads, [&](int64_t b, int64_t e) {
            for (int64_t j = b; j < e; ++j)
                if (errs[size_t(j)].empty())
                    im.readFile(size_t(j), y0, y1, firstRow, features, aovs, img, errs[size_t(j)]);
        });
        for (const std::string& e : errs)  // the first file's error, whatever the thread count
            if (!e.empty()) {
                err = e;
                return false;
            }
        if (y0 <= im.hashedRows && im.hashedRows < y1) im.hashedRows = y1;
        if (aovs && y0 <= im.aovRows && im.aovRows < y1) im.aovRows = y1;
        ++im.blocksDone;
        if (s.opt.progress) s.opt.progress(std::min(im.blocksDone, stepsPerPass), stepsPerPass);
    }
    parallelFor(0, int64_t(rows), 0, im.nthreads, [&](int64_t b, int64_t e) {
        im.moments(img, size_t(b) * size_t(W), size_t(e) * size_t(W), features);
    });
    if (im.hashedRows == H && !im.passDone) {
        im.passDone = true;
        if (!im.finishPass(err)) return false;
        img.header.seeds = s.header.seeds;  // final now
    }
    if (im.aovRows == H && !s.aovs.empty()) im.finishAovPass();
    // The arrays of the parts not asked for are empty, as a file reader leaves them.
    if (!(parts & kStatsPartBeauty)) img.beauty.clear();
    if (!(parts & kStatsPartBuffers)) img.bufferMean.clear(), img.bufferCount.clear();
    if (!(parts & kStatsPartMoments)) img.count.clear(), img.mean.clear(), img.variance.clear();
    if (!features && !(parts & kStatsPartFeatures)) {
        img.normal.clear(), img.position.clear(), img.albedo.clear(), img.depth.clear();
        img.coverage.clear();
    }
    return true;
}

bool ingestRenders(const std::vector<std::string>& paths, const IngestOptions& opt, StatsImage& out,
                   IngestReport& report, std::string& err) {
    report = IngestReport();
    IngestSource src;
    if (!src.init(paths, opt, err)) {
        report = src.report();
        return false;
    }
    StatsImage img;
    const bool ok = readAll(src, img, err);
    report = src.report();
    if (!ok) return false;
    out = std::move(img);
    return true;
}

const std::vector<ParamSpec>& ingestParams() {
    static const std::vector<ParamSpec> params = [] {
        std::vector<ParamSpec> m = {
            textParam("layer", "",
                      "the beauty layer, e.g. ViewLayer.Combined; default: plain R,G,B, else "
                      "Blender's <ViewLayer>.Combined, else an AOV named RGBA/beauty/Ci/C"),
            intParam("spp", 1, double(1 << 24), "",
                     "samples per file; default: the files' metadata (mcstat:spp, samplesPerPixel, "
                     "cycles.<ViewLayer>.samples)"),
            textParam("colorspace", "",
                      "the working space of untagged renders (no colorInteropID, chromaticities or "
                      "oiio:ColorSpace): lin_rec709 (default), ACEScg, ACES2065-1, lin_p3d65, "
                      "lin_rec2020 or their colorInteropID (docs/colour.md)"),
            flagParam("aovs", "1",
                      "1 keeps alpha, light groups, passes, data and ID mattes per sub-buffer "
                      "(docs/aovs.md); 0 leaves out every channel but the beauty's R,G,B"),
        };
        for (const char* cls : {"alpha", "light", "data", "id"})
            m.push_back(
                textParam(cls, "",
                          std::string("GLOB,...: the matching channels or layers are of class ") +
                              cls + ", overriding the naming rules"));
        return m;
    }();
    return params;
}

bool parseIngestOptions(const std::map<std::string, std::string>& kv, IngestOptions& opt,
                        std::string& err, const std::string& context) {
    std::map<std::string, std::string> mods = kv;
    if (!checkModifiers(context, ingestParams(), mods, err)) return false;
    for (const auto& [k, v] : mods) {
        ParamValue value;  // checked above; parsed again for its typed value
        for (const ParamSpec& p : ingestParams())
            if (p.name == k && !parseParamValue(context, p, v, value, err)) return false;
        if (k == "layer") {
            opt.layer = v;
        } else if (k == "spp") {
            opt.spp = v.empty() ? 0 : value.integer;
        } else if (k == "aovs") {
            opt.aovs = value.integer != 0;
        } else if (k == "colorspace" && !v.empty()) {
            const WorkingSpace* ws = findWorkingSpace(v);
            if (!ws) {
                err = fmt::format("{}: colorspace '{}' is unknown (known: {})", context,
                                  printable(v), knownWorkingSpaceNames());
                return false;
            }
            opt.colorSpace = ws->name;
        } else if (AovClass cls; parseAovClass(k, cls)) {
            // :id=GLOB,GLOB  :data=...  :light=...  :alpha=...  (docs/aovs.md, "Classes")
            for (const std::string& g : OIIO::Strutil::splits(v, ","))
                if (!g.empty()) opt.classOverrides.emplace_back(g, cls);
        }
    }
    return true;
}

}  // namespace mcstat
