// Each render's header (ingest.h): its layout against the first file's, its beauty, feature and
// AOV channels by name, its samples per pixel and colour space from its metadata; and the header
// of the statistics file they make.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <fnmatch.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <set>

#include "ingest_plan.h"
#include "mcstat/color/color.h"
#include "mcstat/core/color_space.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/detail/exr_headers.h"
#include "mcstat/image/spec/image_spec.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/ingest/ingest.h"

namespace mcstat {

using namespace ingest_detail;
using OIIO::ImageInput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

namespace {

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

std::string shellWord(const std::string& text) {
    if (!text.empty() &&
        text.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789"
                               "_-+.,/:=@%") == std::string::npos)
        return text;
    std::string out = "'";
    for (const char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
}

std::string linearizeCommand(const std::string& path, const std::string& from) {
    // Stock oiiotool without $OCIO uses OIIO's own config, which knows "linear", "sRGB" and
    // "Rec709" (and not lin_rec709): "linear" is scene-linear with Rec.709 primaries. With $OCIO
    // set, oiiotool and mcstat read the same config: its scene-linear space by its name there.
    const char* env = std::getenv("OCIO");
    const std::string to = env == nullptr || *env == '\0' ? "linear" : sceneLinearName();
    std::string in = "IN", out = "OUT.exr";
    if (!path.empty()) {
        in = shellWord(path);
        const std::string ext = OIIO::Filesystem::extension(path);
        out = shellWord(path.substr(0, path.size() - ext.size()) + "_linear.exr");
    }
    return fmt::format("oiiotool {} --colorconvert {} {} -o {}", in, shellWord(from), shellWord(to),
                       out);
}

std::string convertSpaceCommand(const std::string& path, const std::string& from,
                                const std::string& to) {
    const WorkingSpace* a = findWorkingSpace(from);
    const WorkingSpace* b = findWorkingSpace(to);
    std::array<std::array<double, 3>, 3> m{};
    if (!a || !b || !rgbToRgb(a->xy, b->xy, m)) return {};
    // oiiotool's --ccmatrix multiplies a row vector (out = in * M): transpose=1 takes our matrix,
    // which multiplies a column vector, row by row. The README's ACEScg recipe is the same.
    std::vector<std::string> values;
    for (const auto& row : m)
        for (const double v : row) values.push_back(fmt::format("{:.10g}", v));
    std::string in = "IN", out = fmt::format("OUT_{}.exr", b->name);
    if (!path.empty()) {
        in = shellWord(path);
        const std::string ext = OIIO::Filesystem::extension(path);
        out = shellWord(path.substr(0, path.size() - ext.size()) + "_" + b->name + ".exr");
    }
    return fmt::format(
        "oiiotool {} --ccmatrix:transpose=1 {} --eraseattrib chromaticities --attrib "
        "colorInteropID {} -o {}",
        in, fmt::join(values, ","), b->interopID, out);
}

namespace {

/// OIIO's names for linear data that say nothing of the primaries: "Linear" (its OpenEXR reader's
/// label of every float file, and its PNG reader's of gamma 1), "scene_linear" (a role).
bool saysOnlyLinear(const std::string& cs) {
    return OIIO::Strutil::iequals(cs, "Linear") || OIIO::Strutil::iequals(cs, "scene_linear");
}

/// A space read from `tag` ("colorInteropID 'lin_rec709_scene' says") against the file's
/// oiio:ColorSpace when it has one that says more than "linear": they must name the same space.
/// A converted copy shows why: `oiiotool seed.exr --colorconvert linear sRGB -d uint8 -o
/// seed.png` keeps the EXR's colorInteropID beside the PNG's oiio:ColorSpace sRGB.
bool agreesWithOiioColorSpace(const ImageSpec& spec, const WorkingSpace& ws, const std::string& tag,
                              std::string& problem) {
    const std::string cs = spec.get_string_attribute("oiio:ColorSpace");
    if (cs.empty() || saysOnlyLinear(cs)) return true;
    const WorkingSpace* other = findWorkingSpace(cs);
    if (other == &ws) return true;
    problem = fmt::format(
        "{} {} but oiio:ColorSpace says '{}': the file contradicts itself, and which is "
        "right cannot be told from it (a copy converted by oiiotool --colorconvert keeps its "
        "source's tags); fix its metadata, or use the file it was made from",
        tag, ws.name, printable(cs));
    return false;
}

}  // namespace

bool colorSpaceOf(const ImageSpec& spec, std::string& space, std::string& source,
                  std::string& problem, const std::string& path) {
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
        if (!agreesWithOiioColorSpace(spec, *ws, "colorInteropID '" + printable(id) + "' says",
                                      problem))
            return false;
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
        if (!agreesWithOiioColorSpace(spec, *ws, "the chromaticities say", problem)) return false;
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
        "them first, e.g. {}",
        printable(cs), linearizeCommand(path, printable(cs)));
    return false;
}

namespace {

/// The space of an input whose metadata names none (docs/color.md): --ingest:colorspace= when
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

}  // namespace

namespace ingest_detail {

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

/// Refuses a beauty of integer pixels (an 8-bit PNG or JPEG, a 16-bit TIFF, an EXR's uint): a
/// renderer's output is float (half or float), and integer data read as light is quantised and
/// clipped at 1 (a converted PNG's maximum 1.0 against its EXR's 240.6). Other channels may be
/// integers (IDs). `f` is open.
bool checkFloatBeauty(const InputFile& f, std::string& err) {
    for (const int i : f.beauty.index) {
        const auto [sub, chan] = f.where[size_t(i)];
        const ImageSpec spec = sub == 0 ? f.spec : f.in->spec(sub, 0);
        const TypeDesc t = spec.channelformat(chan);
        if (t.is_floating_point()) continue;
        err = fmt::format(
            "{}: its beauty holds {}-bit integer pixels ({}), not a render's float (half or "
            "float) output: as light they are quantised and clipped at 1; ingest the renderer's "
            "own float files (EXR)",
            f.path, t.size() * 8, t.c_str());
        return false;
    }
    return true;
}

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
    if (!checkFloatBeauty(f, err)) return false;
    f.features = findFeatures(f.names, f.beauty);
    if (!seedOf(f, s.opt, err)) return false;
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
    if (!colorSpaceOf(f.spec, f.space, f.spaceSource, problem2, f.path)) {
        err = f.path + ": " + problem2;
        return false;
    }
    if (f.space.empty() && !untaggedSpace(f.path, s.opt, f.space, f.spaceSource, err)) return false;
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

/// 1. Every header first: layouts, channels, spp; nothing is allocated before they agree.
bool readHeaders(const std::vector<std::string>& paths, Ingest& s, std::string& err) {
    s.files.resize(paths.size());
    for (size_t j = 0; j < paths.size(); ++j)
        if (!readHeader(s, j, paths[j], err)) return false;
    s.report.beauty = s.first().beauty;
    s.report.features = s.first().features;
    return checkOneFrame(s, err) && checkSeeds(s, err) && checkImageSize(s, err) &&
           chooseAovs(s, err) && checkTotals(s, err);
}

/// mcstat:seeds: per file its seed in decimal when the file says one (its Note, or its name through
/// --ingest:seed=), else the hash of its RGB, "h" and 16 hex digits. Until a pass has read every
/// row (`hashes` null), each hash is a placeholder of the same length: a statistics file written
/// while its rows are read gets the hashes in place when it is complete (StatsFileWriter::commit).
std::string seedsText(const std::vector<uint64_t>* hashes, const std::vector<InputFile>& files) {
    std::string s;
    for (size_t j = 0; j < files.size(); ++j) {
        if (j) s += ',';
        if (!files[j].seed.empty())
            s += files[j].seed;
        else
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
    h.seeds = seedsText(nullptr, files);
}

}  // namespace ingest_detail

bool listChannels(const std::string& path, std::vector<std::string>& names,
                  std::vector<std::pair<int, int>>& where, std::string& err) {
    auto in = openRender(path, ReadLimits().maxPixels, err);
    if (!in) return false;
    channelsOf(*in, names, where);
    return true;
}

}  // namespace mcstat
