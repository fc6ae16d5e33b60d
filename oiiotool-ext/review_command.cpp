// Pictures for review tools (docs/review.md): --contactsheet, --errormap, --heatmap, --qualityplot.
// The image operations live in review/review_pictures.cpp
// (include/mcstat/review/review_pictures.h); this file parses modifiers, reads the reference,
// computes the estimates and metrics, and for the plot writes the CSV and the gnuplot script
// (plot.cpp runs gnuplot).
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <utility>

#include "cli.h"
#include "mcstat/color/color.h"
#include "mcstat/compare/compare.h"
#include "mcstat/exr-deep/codec/temp_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/keep_light_image.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/review/display.h"
#include "mcstat/review/review_pictures.h"
#include "plot.h"

namespace mcstat::cli {

namespace {

using OIIO::Strutil::fmt::format;

// ---- modifiers ----------------------------------------------------------------------------------

// Each command's modifiers, declared once: the command table checks them (checkModifiers) and
// generates --help from them, and the commands read them through them (modifierValue).

/// :scale=N, the integer upscaling of the review pictures.
ParamSpec scaleModifier() {
    return intParam("scale", 1, 64, "", "integer tile upscaling; default: tiles >= 256 px wide");
}

/// :layer=, REF's RGB layer.
ParamSpec layerModifier() { return diffModifiers(false).back(); }

const std::vector<ParamSpec>& contactSheetModifiers() {
    static const std::vector<ParamSpec> specs = {
        textParam("estimators", "gmon", "registry names, comma-separated"),
        scaleModifier(),
        layerModifier(),
        textParam("compare", "",
                  "FILE.mcstat: a last tile, --compare of FILE against the top file (z-scores, "
                  "verdict)"),
        [] {  // the estimators' own :keeplight modifier (keep_light_image.h)
            ParamSpec keep = keepLightModifiers().front();
            keep.help =
                "1: every listed estimator and 3D filter gives the light it removed back "
                "(docs/keep-light.md); the mean's tile is the mean";
            return keep;
        }(),
        [] {  // the estimators' own :ci modifier (one declaration of the level, imageops.h)
            ParamSpec ci = confidenceModifiers().front();
            ci.help =
                "LEVEL in (0, 1): a tile of the relative width of the last listed "
                "estimator's confidence interval at LEVEL (docs/confidence.md)";
            return ci;
        }()};
    return specs;
}

const std::vector<ParamSpec>& heatmapModifiers() {
    static const std::vector<ParamSpec> specs = {
        textParam("channel", "",
                  "default: relerr if present, else the first; ciwidth: the relative width of "
                  "the confidence interval of an estimator's result with :ci=LEVEL (log scale, "
                  "docs/confidence.md)"),
        textParam("map", "",
                  "OIIO colour map or cool-warm (diverging); default inferno, cool-warm for the "
                  "signed maps of --compare (z, effect)"),
        realParam("min", -HUGE_VAL, HUGE_VAL, false, "", "default: the data range"),
        realParam("max", -HUGE_VAL, HUGE_VAL, false, "", "default: the data range"),
        enumParam("log", {"auto", "0", "1"}, "auto", "auto: log10 for relerr*, else linear",
                  {{"on", "1"}, {"off", "0"}}),
        scaleModifier()};
    return specs;
}

const std::vector<ParamSpec>& qualityPlotModifiers() {
    static const std::vector<ParamSpec> specs = {
        textParam("estimators", "mean,mon,gmon", "registry names, comma-separated"),
        [] {
            ParamSpec k = intParam("buffers", 1, kMaxBuffers, "",
                                   "one file: the values of k, comma-separated, each at most M; "
                                   "default 1,3,...,M");
            k.list = true;
            return k;
        }(),
        textParam("csv", "",
                  "FILE: spp,buffers,estimator,relMSE,SSIM,PSNR,fireflies,bytesPerPixel"),
        enumParam("x", {"spp", "bytes"}, "spp",
                  "the x axis: samples per pixel, or (several files) each file's bytes per pixel "
                  "on disk, e.g. full against compact (docs/compact.md)"),
        layerModifier()};
    return specs;
}

/// The registry estimators named in `list` (comma-separated), in order, each once.
bool estimatorList(const std::string& list, const std::string& cmd,
                   std::vector<const Operation*>& out, std::string& err) {
    out.clear();
    for (const std::string& name : OIIO::Strutil::splits(list, ",")) {
        const std::string n(OIIO::Strutil::strip(name));
        if (n.empty()) continue;
        const Operation* e = findEstimator(n);
        if (!e) {
            std::vector<std::string> known;
            for (const Operation& r : estimatorRegistry()) known.push_back(r.name);
            err = format("{}: unknown estimator '{}' (known: {})", cmd, n,
                         OIIO::Strutil::join(known, ", "));
            return false;
        }
        if (std::find(out.begin(), out.end(), e) == out.end()) out.push_back(e);
    }
    if (out.empty()) {
        err = format("{}: modifier estimators names no estimator", cmd);
        return false;
    }
    return true;
}

/// --diff's thresholds (docs/metrics.md) from :eps= :ratio= :floor=, luma from the OCIO config.
bool diffOptions(const Modifiers& mods, const std::string& cmd, const Item& item, DiffOptions& opt,
                 std::string& err) {
    if (!itemSpace(item, opt.space, err) || !itemLuma(item, opt.luma, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    readDiffOptions(mods, opt);
    return true;
}

bool readReference(const std::string& path, const Modifiers& mods, const std::string& cmd,
                   OIIO::ImageBuf& ref, std::string& err) {
    if (!readRGB(path, modifierValue(diffModifiers(false), mods, "layer").text, ref, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    return true;
}

/// Refuses a reference (read by readReference, which labels its space) in another working space
/// than `space`, the space of `what`: one luminance and one display for both (docs/color.md).
bool referenceInSpace(const std::string& cmd, const std::string& what, const std::string& space,
                      const std::string& refName, const OIIO::ImageBuf& ref, std::string& err) {
    std::string refSpace;
    if (!imageSpace(ref.spec(), refName, refSpace, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    return sameSpace(cmd, what, space, refName, refSpace, err, false, true);
}

/// Runs `est` with its default parameters (luma from the OCIO config) on `stats`, and `extra`
/// (keeplight) beside them.
bool runEstimator(const StatsImage& stats, const Operation& est, int nthreads, OIIO::ImageBuf& out,
                  const std::string& cmd, std::string& err, const ParamValues& extra = {}) {
    ParamValues defaults;
    if (!parseOperationParams(est, {}, defaults, err, cmd)) return false;
    defaults.insert(extra.begin(), extra.end());
    std::array<double, 3> luma{};
    if (!spaceLuma(stats.header.colorSpace, cmd, luma, err)) return false;
    if (!applyOperation(out, stats, est, defaults, luma, false, {}, nthreads)) {
        err = format("{}: {}: {}", cmd, est.name, out.geterror());
        return false;
    }
    return true;
}

void setDouble(OIIO::ImageSpec& spec, const std::string& name, double v) {
    spec.attribute(name, OIIO::TypeDesc::DOUBLE, &v);
}

bool topStats(State& st, const std::string& cmd, std::string& err) {
    if (st.stack.empty() || !st.stack.back().isStats()) {
        err = st.stack.empty()
                  ? format("{}: needs a statistics file (.{}) on the stack", cmd, kStatsExtension)
                  : format(
                        "{}: the top of the stack must be a statistics file (.{}), not the "
                        "image {}",
                        cmd, kStatsExtension, st.stack.back().name);
        return false;
    }
    return true;
}

bool topImage(State& st, const std::string& cmd, std::string& err) {
    if (st.stack.empty()) {
        err = format("{}: needs an image on the stack", cmd);
        return false;
    }
    if (st.stack.back().isStats()) {
        err = format("{}: {} is a statistics file; apply an estimator first (e.g. --gmon)", cmd,
                     st.stack.back().name);
        return false;
    }
    return true;
}

// ---- --contactsheet -----------------------------------------------------------------------------

/// One --contactsheet run: what it was asked, and the tiles made so far.
struct ContactSheet {
    std::string cmd;
    std::string refName;                   ///< the reference as given (the argument)
    std::vector<const Operation*> listed;  ///< modifier estimators, in order
    std::vector<const Operation*> shown;   ///< the mean, then the listed ones
    OIIO::ImageBuf ref;
    DiffOptions opt;
    SheetOptions layout;  ///< the sheet's tile scale and style
    std::vector<SheetTile> tiles;
    std::vector<DiffMetrics> metrics;  ///< per estimator's tile
    std::vector<std::string> names;    ///< per estimator's tile: "estimator(file)"
    OIIO::ImageBuf last;               ///< the last listed estimator's image, for the difference
    std::string lastName;
    bool keepLight = false;  ///< :keeplight=1: the estimators give their removed light back
};

/// Checks --contactsheet's modifiers into `q`, loads the statistics file on top of the stack and
/// reads the reference.
bool parseContactSheet(State& st, const Modifiers& mods, ContactSheet& q, std::string& err) {
    const std::string& cmd = q.cmd;
    if (!topStats(st, cmd, err)) return false;
    Item& top = st.stack.back();
    const std::vector<ParamSpec>& specs = contactSheetModifiers();
    if (!estimatorList(modifierValue(specs, mods, "estimators").text, cmd, q.listed, err))
        return false;
    q.keepLight = modifierValue(specs, mods, "keeplight").integer != 0;
    q.layout.scale = int(mods.count("scale") ? modifierValue(specs, mods, "scale").integer
                                             : defaultReviewScale(top.header.width));
    if (!loadStats(st, top, err)) return false;
    if (!readReference(q.refName, mods, cmd, q.ref, err)) return false;
    // The mean first, then the listed estimators (the mean once even when listed).
    const Operation* mean = findEstimator("mean");
    q.shown = {mean};
    for (const Operation* e : q.listed)
        if (e != mean) q.shown.push_back(e);
    if (!itemSpace(top, q.opt.space, err) || !itemLuma(top, q.opt.luma, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    if (!referenceInSpace(cmd, top.name, q.opt.space, q.refName, q.ref, err)) return false;
    noteDisplayRoute(q.opt.space);
    return true;
}

/// Runs `e` on the statistics file and measures it against the reference: prints --diff's line
/// (to check the sheet's numbers against) and adds its tile, labelled with relMSE, SSIM and
/// fireflies.
bool estimatorTile(State& st, const Operation& e, ContactSheet& q, std::string& err) {
    const Item& top = st.stack.back();
    OIIO::ImageBuf img;
    // keeplight where the operation takes it (not the mean, which keeps all its light, nor an
    // image filter); its tile says so.
    ParamValues extra;
    if (q.keepLight && e.name != "mean") {
        std::map<std::string, std::string> kv = {{"keeplight", "1"}};
        if (!takeKeepLightModifiers(q.cmd, kv, extra, err)) return false;
        if (!keepLightRefusal(e, extra).empty()) extra.clear();
    }
    const bool keep = keepLightAsked(extra);
    if (!runEstimator(*top.stats, e, st.nthreads, img, q.cmd, err, extra)) return false;
    DiffMetrics m;
    if (!diffImages(img, q.ref, q.opt, m, err)) {
        err = format("{}: {}({}) vs {}: {}", q.cmd, e.name, top.name, q.refName, err);
        return false;
    }
    const std::string name = format("{}{}({})", e.name, keep ? ":keeplight=1" : "", top.name);
    printDiffLine(name, m);
    SheetTile t;
    if (!displayTransform(t.image, img, {}, st.nthreads)) {
        err = format("{}: {}", q.cmd, t.image.geterror());
        return false;
    }
    t.title = keep ? e.title + " + light kept" : e.title;
    t.lines = {format("relMSE {:.4g}", m.relMSE), format("SSIM {:.4f}", m.ssim),
               format("fireflies {}", m.fireflies)};
    q.tiles.push_back(std::move(t));
    q.metrics.push_back(m);
    q.names.push_back(name);
    if (&e == q.listed.back()) {
        q.last = std::move(img);
        q.lastName = name;
    }
    return true;
}

/// The reference's tile, labelled with its file name.
bool referenceTile(State& st, ContactSheet& q, std::string& err) {
    SheetTile refTile;
    if (!displayTransform(refTile.image, q.ref, {}, st.nthreads)) {
        err = format("{}: {}", q.cmd, refTile.image.geterror());
        return false;
    }
    refTile.title = "reference";
    refTile.lines = {OIIO::Filesystem::filename(q.refName)};
    q.tiles.push_back(std::move(refTile));
    return true;
}

/// The difference's tile: relerr of the last listed estimator as a heatmap, its colour bar under
/// it.
bool differenceTile(State& st, ContactSheet& q, std::string& err) {
    SheetTile diffTile;
    OIIO::ImageBuf errImg;
    if (!errorImage(errImg, q.last, q.ref, q.opt, {}, st.nthreads)) {
        err = format("{}: {}", q.cmd, errImg.geterror());
        return false;
    }
    HeatmapOptions hopt;
    hopt.channel = "relerr";
    hopt.colorBar = false;
    int channel = 0;
    ColorScale cs;
    if (!resolveColorScale(errImg, hopt, channel, cs, err) ||
        !heatmap(diffTile.image, errImg, hopt, {}, st.nthreads)) {
        err = format("{}: {}", q.cmd, err.empty() ? diffTile.image.geterror() : err);
        return false;
    }
    cs.label = "relerr (log scale)";
    const int barWidth = st.stack.back().header.width * q.layout.scale;
    if (!colorBar(diffTile.footer, barWidth, cs, q.layout.style)) {
        err = format("{}: {}", q.cmd, diffTile.footer.geterror());
        return false;
    }
    diffTile.title = "rel. error: " + q.listed.back()->title;
    q.tiles.push_back(std::move(diffTile));
    return true;
}

/// With :ci=LEVEL, a tile of the relative width of the last listed estimator's confidence interval
/// at LEVEL (log scale), its colour bar under it.
bool intervalTile(State& st, ContactSheet& q, const ParamValue& level, std::string& err) {
    const Item& top = st.stack.back();
    const Operation& e = *q.listed.back();
    if (!hasIntervals(e)) {
        err = format("{}: ci: {} has no confidence interval (docs/confidence.md)", q.cmd, e.name);
        return false;
    }
    ParamValues values;
    if (!parseOperationParams(e, {}, values, err, q.cmd)) return false;
    values["ci"] = level;
    OIIO::ImageBuf img, width;
    if (!applyOperation(img, *top.stats, e, values, q.opt.luma, false, {}, st.nthreads) ||
        !intervalWidthImage(width, img)) {
        err = format("{}: {}: {}", q.cmd, e.name,
                     img.has_error() ? img.geterror() : width.geterror());
        return false;
    }
    HeatmapOptions hopt;
    hopt.channel = kCiWidthChannel;
    hopt.log = 1;
    hopt.colorBar = false;
    int channel = 0;
    ColorScale cs;
    SheetTile tile;
    if (!resolveColorScale(width, hopt, channel, cs, err) ||
        !heatmap(tile.image, width, hopt, {}, st.nthreads)) {
        err = format("{}: {}", q.cmd, err.empty() ? tile.image.geterror() : err);
        return false;
    }
    cs.label = "interval width / value (log scale)";
    if (!colorBar(tile.footer, top.header.width * q.layout.scale, cs, q.layout.style)) {
        err = format("{}: {}", q.cmd, tile.footer.geterror());
        return false;
    }
    tile.title = format("{} CI: {}", level.text, e.title);
    q.tiles.push_back(std::move(tile));
    return true;
}

/// With :compare=FILE, the last tile: --compare of FILE (a) against the top statistics file (b),
/// its z-scores on a diverging map with their colour bar, titled with the verdict's first word. The
/// verdict line is printed as --compare prints it; the exit status is --compare's to give.
bool compareTile(State& st, ContactSheet& q, const std::string& other, std::string& err) {
    const Item& top = st.stack.back();
    StatsFileReader reader;
    if (!reader.open(other, err, ReadLimits(), st.nthreads)) {
        err = format("{}: {}", q.cmd, err);
        return false;
    }
    MemoryStatsSource mine(top.stats, top.name);
    CompareOptions opt;
    opt.luma = q.opt.luma;
    opt.nthreads = st.nthreads;
    CompareResult r;
    if (!compareStats(reader, mine, opt, r, err)) {
        err = format("{}: compare: {}", q.cmd, err);
        return false;
    }
    std::printf("%s vs %s: %s\n", other.c_str(), top.name.c_str(), compareVerdict(r, opt).c_str());
    HeatmapOptions hopt;
    hopt.channel = "z";
    hopt.map = "cool-warm";
    hopt.symmetric = true;
    hopt.colorBar = false;
    int channel = 0;
    ColorScale cs;
    SheetTile tile;
    if (!resolveColorScale(r.maps, hopt, channel, cs, err) ||
        !heatmap(tile.image, r.maps, hopt, {}, st.nthreads)) {
        err = format("{}: {}", q.cmd, err.empty() ? tile.image.geterror() : err);
        return false;
    }
    cs.label = "z (standard errors)";
    if (!colorBar(tile.footer, top.header.width * q.layout.scale, cs, q.layout.style)) {
        err = format("{}: {}", q.cmd, tile.footer.geterror());
        return false;
    }
    tile.title = std::string("compare: ") + (r.identical ? "IDENTICAL"
                                             : r.fail    ? "DIFFERENT"
                                                         : "SAME");
    tile.lines = {format("{} px, {} tiles differ", r.pixelsRejected, r.tilesRejected),
                  "vs " + OIIO::Filesystem::filename(other)};
    q.tiles.push_back(std::move(tile));
    return true;
}

/// The sheet's metadata, tile by tile: the estimators' names and metrics, then the reference and
/// the difference, so that scripts read the numbers the labels show.
void labelSheet(const ContactSheet& q, OIIO::ImageSpec& spec) {
    spec.attribute(kDisplayReferredAttr, 1);
    for (size_t i = 0; i < q.metrics.size(); ++i) {
        const std::string p = format("mcstat:tile{}:", i + 1);
        spec.attribute(p + "name", q.names[i]);
        setDouble(spec, p + "relMSE", q.metrics[i].relMSE);
        setDouble(spec, p + "SSIM", q.metrics[i].ssim);
        setDouble(spec, p + "PSNR", q.metrics[i].psnr);
        spec.attribute(p + "fireflies", int(q.metrics[i].fireflies));
    }
    spec.attribute(format("mcstat:tile{}:name", q.metrics.size() + 1), "reference");
    spec.attribute(format("mcstat:tile{}:name", q.metrics.size() + 2),
                   "relerr(" + q.lastName + ")");
}

bool cmdContactSheet(State& st, const std::string& cmd, const std::vector<std::string>& args,
                     const Modifiers& mods, std::string& err) {
    ContactSheet q;
    q.cmd = cmd;
    q.refName = args[0];
    if (!parseContactSheet(st, mods, q, err)) return false;
    for (const Operation* e : q.shown)
        if (!estimatorTile(st, *e, q, err)) return false;
    std::fflush(stdout);
    if (!referenceTile(st, q, err) || !differenceTile(st, q, err)) return false;
    if (mods.count("ci") &&
        !intervalTile(st, q, modifierValue(contactSheetModifiers(), mods, "ci"), err))
        return false;
    const std::string other = modifierValue(contactSheetModifiers(), mods, "compare").text;
    if (!other.empty() && !compareTile(st, q, other, err)) return false;
    auto sheet = std::make_shared<OIIO::ImageBuf>();
    if (!contactSheet(*sheet, q.tiles, q.layout, {}, st.nthreads)) {
        err = format("{}: {}", cmd, sheet->geterror());
        return false;
    }
    labelSheet(q, sheet->specmod());
    replaceWithImage(st.stack.back(), "contactsheet", sheet);
    return true;
}

// ---- --errormap and --heatmap -------------------------------------------------------------------

bool cmdErrorMap(State& st, const std::string& cmd, const std::vector<std::string>& args,
                 const Modifiers& mods, std::string& err) {
    if (!topImage(st, cmd, err)) return false;
    Item& top = st.stack.back();
    DiffOptions opt;
    if (!diffOptions(mods, cmd, top, opt, err)) return false;
    OIIO::ImageBuf ref, rgb;
    if (!readReference(args[0], mods, cmd, ref, err) ||
        !referenceInSpace(cmd, top.name, opt.space, args[0], ref, err))
        return false;
    if (!selectRGB(*top.image, "", top.name, rgb, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    auto out = std::make_shared<OIIO::ImageBuf>();
    if (!errorImage(*out, rgb, ref, opt, {}, st.nthreads)) {
        err = format("{}: {} vs {}: {}", cmd, top.name, args[0], out->geterror());
        return false;
    }
    // errorImage kept the estimate's provenance; what it was measured against, and the item it
    // was made from (naming the statistics file), go with it for a heatmap's caption.
    const std::string p = kProvenancePrefix;
    out->specmod().attribute(p + "errormap.reference", args[0]);
    out->specmod().attribute(p + "errormap.image", top.name);
    replaceWithImage(top, "errormap", out);
    return true;
}

/// The file an item was made from: the innermost name of "op(op(file))" (items are named
/// "op(input)" as they are computed).
std::string innermostName(std::string name) {
    while (!name.empty() && name.back() == ')') {
        const size_t open = name.find('(');
        if (open == std::string::npos || open == 0) break;
        name = name.substr(open + 1, name.size() - open - 2);
    }
    return name;
}

bool cmdHeatmap(State& st, const std::string& cmd, const std::vector<std::string>&,
                const Modifiers& mods, std::string& err) {
    if (!topImage(st, cmd, err)) return false;
    Item& top = st.stack.back();
    HeatmapOptions opt;
    const std::vector<ParamSpec>& specs = heatmapModifiers();
    opt.channel = modifierValue(specs, mods, "channel").text;
    // The maps of --compare: the signed effect in standard errors on a diverging map centred on
    // 0, the verdict written above it.
    const OIIO::ImageSpec& src = top.image->spec();
    const std::string verdict =
        src.get_string_attribute(std::string(kProvenancePrefix) + "compare.verdict");
    if (!verdict.empty()) {
        opt.caption = verdict;
        if (opt.channel.empty()) {
            for (const std::string& c : src.channelnames)
                if (c == "z" || (opt.channel.empty() && OIIO::Strutil::starts_with(c, "z.")))
                    opt.channel = c;
        }
        const std::string& c = opt.channel;
        if (OIIO::Strutil::starts_with(c, "z") || OIIO::Strutil::starts_with(c, "tile.z") ||
            OIIO::Strutil::starts_with(c, "effect")) {
            opt.map = "cool-warm";
            opt.symmetric = true;
        }
    } else {
        // What the picture is of, from the image's provenance: the operation, the statistics file
        // (an error map names the item it was made from), M and spp, the reference.
        const std::string of =
            src.get_string_attribute(std::string(kProvenancePrefix) + "errormap.image", top.name);
        opt.caption = provenanceCaption(src, OIIO::Filesystem::filename(innermostName(of)));
    }
    if (mods.count("map")) opt.map = modifierValue(specs, mods, "map").text;
    if (mods.count("min")) opt.min = modifierValue(specs, mods, "min").real;
    if (mods.count("max")) opt.max = modifierValue(specs, mods, "max").real;
    const std::string log = modifierValue(specs, mods, "log").text;  // canonical: auto, 0, 1
    opt.log = log == "1" ? 1 : log == "0" ? 0 : -1;
    opt.scale = int(mods.count("scale") ? modifierValue(specs, mods, "scale").integer
                                        : defaultReviewScale(top.image->spec().width));
    // The confidence interval's relative width (its channels ci_low.*, ci_high.*), on a log scale
    // unless asked otherwise: widths span decades between flat and noisy regions.
    const OIIO::ImageBuf* of = top.image.get();
    OIIO::ImageBuf width;
    if (opt.channel == kCiWidthChannel && src.channelindex(kCiWidthChannel) < 0) {
        if (!intervalWidthImage(width, *top.image)) {
            err = format("{}: {}: {}", cmd, top.name, width.geterror());
            return false;
        }
        of = &width;
        if (opt.log < 0) opt.log = 1;
    }
    auto out = std::make_shared<OIIO::ImageBuf>();
    if (!heatmap(*out, *of, opt, {}, st.nthreads)) {
        err = format("{}: {}: {}", cmd, top.name, out->geterror());
        return false;
    }
    out->specmod().attribute(kDisplayReferredAttr, 1);
    replaceWithImage(top, "heatmap", out);
    return true;
}

// ---- --qualityplot ------------------------------------------------------------------------------

struct QualityRow {
    double spp = 0.0;
    int buffers = 0;
    double bytes = 0.0;  ///< the file's bytes per pixel (x=bytes; several files only)
    const Operation* est = nullptr;
    DiffMetrics m;
};

double meanCount(const StatsImage& s) {
    double total = 0.0;
    for (float c : s.count) total += c;
    return s.pixelCount() ? total / double(s.pixelCount()) : 0.0;
}

/// The first k buffers of every pixel of fixed-M `src` as a fixed-M image with M = k (the moments
/// count and the beauty recomputed from those buffers; features left empty: no estimator reads
/// them).
bool bufferSubset(const StatsImage& src, int k, StatsImage& out, std::string& err) {
    out = StatsImage();
    out.header = src.header;
    out.header.M = k;
    if (!out.allocate(err)) return false;
    const size_t M = size_t(src.header.M);
    double total = 0.0;
    for (size_t p = 0; p < src.pixelCount(); ++p) {
        double n = 0.0, sum[3] = {0.0, 0.0, 0.0};
        for (size_t j = 0; j < size_t(k); ++j) {
            const size_t a = p * M + j, b = p * size_t(k) + j;
            const float c = src.bufferCount[a];
            out.bufferCount[b] = c;
            for (size_t ch = 0; ch < 3; ++ch) {
                out.bufferMean[b * 3 + ch] = src.bufferMean[a * 3 + ch];
                if (c > 0.f) sum[ch] += double(c) * double(src.bufferMean[a * 3 + ch]);
            }
            n += c;
        }
        out.count[p] = float(n);
        for (size_t ch = 0; ch < 3; ++ch)
            out.beauty[p * 3 + ch] = out.mean[p * 3 + ch] = n > 0.0 ? float(sum[ch] / n) : 0.f;
        total += n;
    }
    out.header.spp = std::llround(total / double(std::max<size_t>(1, src.pixelCount())));
    return true;
}

std::string qualityScript(const std::vector<const Operation*>& ests, bool logRelMSE,
                          const std::string& title, bool bytes) {
    std::string s =
        "set terminal pngcairo noenhanced size 1200,480 font 'DejaVu Sans,11'\n"
        "set output 'plot.png'\n"
        "set datafile separator ' '\n"
        "set multiplot layout 1,2 title '" +
        plotSafe(title) +
        "'\n"
        "set grid\n"
        "set logscale x\n"
        "set xlabel '" +
        std::string(bytes ? "bytes per pixel (the file on disk)" : "samples per pixel") + "'\n";
    auto curves = [&](int column) {
        std::string p = "plot";
        for (size_t i = 0; i < ests.size(); ++i)
            p += format("{} 'data.txt' index {} using 1:{} with linespoints lw 2 pt 7 title '{}'",
                        i ? "," : "", i, column, plotSafe(ests[i]->title));
        return p + "\n";
    };
    s += std::string(logRelMSE ? "set logscale y\n" : "unset logscale y\n") +
         "set ylabel 'relMSE'\nset key top right\n" + curves(2);
    s += "unset logscale y\nset ylabel 'SSIM'\nset key bottom right\n" + curves(3);
    s += "unset multiplot\n";
    return s;
}

/// One --qualityplot run: what it was asked, and the points measured.
struct QualityPlot {
    std::string cmd;
    std::string refName;  ///< the reference as given (the command's argument)
    size_t nfiles = 0;    ///< statistics files at the top of the stack
    std::vector<const Operation*> ests;
    std::string csvPath;
    bool bytes = false;  ///< x=bytes: x is each file's size per pixel instead of its spp
    DiffOptions opt;
    OIIO::ImageBuf ref;
    std::vector<QualityRow> rows;
    std::string title;
};

/// Checks --qualityplot's modifiers into `q` and reads the reference.
bool parseQualityPlot(const Modifiers& mods, QualityPlot& q, std::string& err) {
    const std::string& cmd = q.cmd;
    const std::vector<ParamSpec>& specs = qualityPlotModifiers();
    if (!estimatorList(modifierValue(specs, mods, "estimators").text, cmd, q.ests, err))
        return false;
    q.csvPath = modifierValue(specs, mods, "csv").text;
    q.bytes = modifierValue(specs, mods, "x").text == "bytes";
    if (q.bytes && q.nfiles < 2) {
        err = format(
            "{}: x=bytes plots files of different sizes, one point each; the stack holds {} (push "
            "the files to compare, e.g. FULL.mcstat SMALL.mcstat)",
            cmd, q.nfiles);
        return false;
    }
    if (q.nfiles > 1 && mods.count("buffers")) {
        err = format("{}: modifier buffers applies to a single statistics file; the stack holds {}",
                     cmd, q.nfiles);
        return false;
    }
    if (!haveGnuplot(err)) {  // before the work, not after it
        err = format("{}: {}", cmd, err);
        return false;
    }
    return readReference(q.refName, mods, cmd, q.ref, err);
}

/// Measures every estimator over `s` against the reference: one printed line and row each.
bool measureQuality(State& st, QualityPlot& q, const StatsImage& s, const std::string& what,
                    double spp, int buffers, std::string& err) {
    if (!spaceLuma(s.header.colorSpace, what, q.opt.luma, err)) {
        err = format("{}: {}", q.cmd, err);
        return false;
    }
    q.opt.space = s.header.colorSpace;
    if (!referenceInSpace(q.cmd, what, q.opt.space, q.refName, q.ref, err)) return false;
    for (const Operation* e : q.ests) {
        OIIO::ImageBuf img;
        if (!runEstimator(s, *e, st.nthreads, img, q.cmd, err)) return false;
        QualityRow r{spp, buffers, 0.0, e, {}};
        if (!diffImages(img, q.ref, q.opt, r.m, err)) {
            err = format("{}: {}({}) vs {}: {}", q.cmd, e->name, what, q.refName, err);
            return false;
        }
        std::printf(
            "%-10s spp %-10.6g buffers %-3d relMSE %.6g  SSIM %.5f  PSNR %.3f dB  "
            "fireflies %ld / %ld\n",
            e->name.c_str(), spp, buffers, r.m.relMSE, r.m.ssim, r.m.psnr, r.m.fireflies,
            r.m.pixels);
        q.rows.push_back(r);
    }
    return true;
}

/// The buffer counts k of the nested subsets: modifier buffers, else 1, 3, 5, ... and M.
bool subsetSizes(const Modifiers& mods, int M, const std::string& cmd, std::vector<long>& ks,
                 std::string& err) {
    if (mods.count("buffers")) {
        // Each k checked by the command table against [1, kMaxBuffers]; here against this M.
        for (const ParamValue& k : modifierList(qualityPlotModifiers(), mods, "buffers")) {
            if (k.integer > M) {
                err = format("{}: modifier buffers must be an integer in 1..{}, not '{}'", cmd, M,
                             k.text);
                return false;
            }
            ks.push_back(long(k.integer));
        }
    } else {
        for (long k = 1; k <= M; k += 2) ks.push_back(k);
        ks.push_back(M);
    }
    std::sort(ks.begin(), ks.end());
    ks.erase(std::unique(ks.begin(), ks.end()), ks.end());
    if (ks.empty()) {
        err = format("{}: modifier buffers names no buffer count", cmd);
        return false;
    }
    return true;
}

/// One statistics file: a point per nested buffer subset (its first k buffers).
bool measureSubsets(State& st, const Modifiers& mods, QualityPlot& q, std::string& err) {
    Item& top = st.stack.back();
    if (top.header.adaptiveM) {
        err = format(
            "{}: {} has {} (1..{} buffers per pixel); nested buffer subsets need a fixed-M file "
            "(or push several files for one point each)",
            q.cmd, top.name, top.header.compact ? "been compacted" : "adaptive M", top.header.M);
        return false;
    }
    const int M = top.header.M;
    std::vector<long> ks;
    if (!subsetSizes(mods, M, q.cmd, ks, err)) return false;
    if (!loadStats(st, top, err)) return false;
    for (long k : ks) {
        StatsImage sub;
        if (!bufferSubset(*top.stats, int(k), sub, err)) {
            err = format("{}: {}: {}", q.cmd, top.name, err);
            return false;
        }
        if (!measureQuality(st, q, sub, format("{} buffers of {}", k, top.name), meanCount(sub),
                            int(k), err))
            return false;
    }
    q.title = format("{}: first k of {} buffers vs {}", top.name, M, q.refName);
    return true;
}

/// Several statistics files: a point each.
bool measureFiles(State& st, QualityPlot& q, std::string& err) {
    for (size_t i = st.stack.size() - q.nfiles; i < st.stack.size(); ++i) {
        Item& it = st.stack[i];
        double bytes = 0.0;
        if (q.bytes) {
            if (it.path.empty()) {
                err = format(
                    "{}: x=bytes needs files on disk; {} is computed (write it with -o "
                    "first)",
                    q.cmd, it.name);
                return false;
            }
            bytes = double(OIIO::Filesystem::file_size(it.path)) /
                    double(std::max<int64_t>(1, int64_t(it.header.width) * it.header.height));
        }
        if (!loadStats(st, it, err)) return false;
        const size_t first = q.rows.size();
        if (!measureQuality(st, q, *it.stats, it.name, meanCount(*it.stats), it.header.M, err))
            return false;
        for (size_t r = first; r < q.rows.size(); ++r) q.rows[r].bytes = bytes;
        it.stats.reset();  // one file in memory at a time
    }
    q.title = format("{} files vs {}", q.nfiles, q.refName);
    return true;
}

/// Writes every point to the CSV file modifier csv names.
bool writeQualityCsv(const QualityPlot& q, std::string& err) {
    std::string csv = "spp,buffers,estimator,relMSE,SSIM,PSNR,fireflies,bytesPerPixel\n";
    for (const QualityRow& r : q.rows)
        csv += format("{:.17g},{},{},{:.17g},{:.17g},{:.17g},{},{:.6g}\n", r.spp, r.buffers,
                      r.est->name, r.m.relMSE, r.m.ssim, r.m.psnr, r.m.fireflies, r.bytes);
    if (writeTextAtomically(q.csvPath, csv, err)) return true;
    err = format("{}: {}", q.cmd, err);
    return false;
}

/// gnuplot's data: one block per estimator; `logRelMSE` says whether a log axis can show relMSE.
std::string qualityData(const QualityPlot& q, bool& logRelMSE) {
    // One data block per estimator (gnuplot's "index"): spp, relMSE, SSIM, sorted by spp.
    std::string data;
    logRelMSE = true;
    for (size_t i = 0; i < q.ests.size(); ++i) {
        std::vector<const QualityRow*> pts;
        for (const QualityRow& r : q.rows)
            if (r.est == q.ests[i]) pts.push_back(&r);
        const auto x = [&q](const QualityRow* r) { return q.bytes ? r->bytes : r->spp; };
        std::stable_sort(pts.begin(), pts.end(),
                         [&x](const QualityRow* a, const QualityRow* b) { return x(a) < x(b); });
        data += format("# {}\n", q.ests[i]->name);
        for (const QualityRow* r : pts) {
            // gnuplot takes NaN as a missing point; a log axis cannot show relMSE <= 0.
            logRelMSE = logRelMSE && r->m.relMSE > 0.0;
            data += format("{:.17g} {:.17g} {:.17g}\n", x(r), r->m.relMSE, r->m.ssim);
        }
        data += "\n\n";
    }
    return data;
}

/// Draws the plot with gnuplot and puts it in place of the statistics files on the stack.
bool drawQualityPlot(State& st, const QualityPlot& q, std::string& err) {
    bool logRelMSE = true;
    const std::string data = qualityData(q, logRelMSE);
    auto plot = std::make_shared<OIIO::ImageBuf>();
    if (!runGnuplot(qualityScript(q.ests, logRelMSE, q.title, q.bytes), {{"data.txt", data}},
                    "plot.png", *plot, err)) {
        err = format("{}: {}", q.cmd, err);
        return false;
    }
    plot->specmod().attribute(kDisplayReferredAttr, 1);
    plot->specmod().attribute("mcstat:qualityplot:points", int(q.rows.size()));
    Item out;
    out.name = format("qualityplot({})",
                      q.nfiles == 1 ? st.stack.back().name : format("{} files", q.nfiles));
    out.image = plot;
    st.stack.resize(st.stack.size() - q.nfiles);
    st.stack.push_back(std::move(out));
    return true;
}

bool cmdQualityPlot(State& st, const std::string& cmd, const std::vector<std::string>& args,
                    const Modifiers& mods, std::string& err) {
    QualityPlot q;
    q.cmd = cmd;
    q.refName = args[0];
    // The statistics files at the top of the stack: one gives nested buffer subsets, several one
    // point each.
    while (q.nfiles < st.stack.size() && st.stack[st.stack.size() - 1 - q.nfiles].isStats())
        ++q.nfiles;
    if (q.nfiles == 0) return topStats(st, cmd, err);
    if (!parseQualityPlot(mods, q, err)) return false;
    const bool measured =
        q.nfiles == 1 ? measureSubsets(st, mods, q, err) : measureFiles(st, q, err);
    if (!measured) return false;
    std::fflush(stdout);
    if (!q.csvPath.empty() && !writeQualityCsv(q, err)) return false;
    return drawQualityPlot(st, q, err);
}

}  // namespace

void appendReviewCommands(std::vector<Command>& t) {
    t.push_back({"--contactsheet", 1, "REF",
                 "Contact sheet of the top statistics file: mean | each estimator | REF | "
                 "relative error of the last estimator, labelled, with relMSE, SSIM, fireflies "
                 "(docs/review.md)",
                 contactSheetModifiers(), &cmdContactSheet, ""});
    t.push_back({"--errormap", 1, "REF",
                 "Replace the top image by its per-pixel error against REF: channels relerr "
                 "(relMSE's per-pixel term) and firefly (1/0)",
                 diffModifiers(false), &cmdErrorMap, ""});
    t.push_back({"--heatmap", 0, "",
                 "Replace the top image by a heatmap of one channel with a colour bar "
                 "(display-referred; NaN/Inf magenta)",
                 heatmapModifiers(), &cmdHeatmap, ""});
    t.push_back({"--qualityplot", 1, "REF",
                 "Plot relMSE and SSIM against spp (gnuplot): the first k buffers of the top "
                 "statistics file, or one point per statistics file on top of the stack",
                 qualityPlotModifiers(), &cmdQualityPlot, ""});
}

}  // namespace mcstat::cli
