// Reading inputs, writing outputs and --info for the `mcstat` command line.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <set>

#include "cli.h"
#include "mcstat/color/color.h"
#include "mcstat/core/color_space.h"
#include "mcstat/core/progress.h"
#include "mcstat/exr-deep/codec/temp_file.h"
#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/ingest/ingest.h"
#include "mcstat/review/display.h"

namespace mcstat::cli {

namespace {

using OIIO::Strutil::fmt::format;

std::string lowerExtension(const std::string& path) {
    std::string ext = OIIO::Filesystem::extension(path, false);
    return OIIO::Strutil::lower(ext);
}

/// A library's message on one line: line breaks become "; ", trailing blanks go.
std::string oneLineMessage(std::string s) {
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
    for (size_t at = s.find('\n'); at != std::string::npos; at = s.find('\n', at))
        s.replace(at, 1, "; ");
    return s;
}

bool isStatsPath(const std::string& path) { return lowerExtension(path) == kStatsExtension; }

/// Prints "mcstat: note: TEXT" on stderr, once per process for the same text (a reference used
/// by several commands is read several times).
void noteOnce(const std::string& text) {
    static std::set<std::string> said;
    if (said.insert(text).second) note(text);
}

/// Whether `path` is read as a statistics file: decided by its content (probeFileContent: the
/// magic number and the OpenEXR part names, headers only), never by its name. A name that says
/// otherwise gets a note. False with `err` for a directory or damaged OpenEXR headers (checked
/// before any OpenEXR reader sees them). When the content cannot tell (no such file, a pipe, not
/// OpenEXR) the name decides, and the reader it picks says what is wrong, as it always did.
bool readsAsStats(const std::string& path, bool& stats, std::string& err) {
    FileContent c;
    if (!probeFileContent(path, c, err)) return false;
    const bool named = isStatsPath(path);
    stats = named;
    switch (c.kind) {
        case FileContent::Directory:
            err = format("{} is a directory", path);
            return false;
        case FileContent::Stats:
            stats = true;
            if (!named)
                noteOnce(
                    format("{} is a statistics file (by its content) and is read as one; name it "
                           ".{} for OIIO's mcstat plugin, which OIIO chooses by the name",
                           path, kStatsExtension));
            return true;
        case FileContent::PlainExr:
            // Read as the image it is, with a note, rather than refused: oiiotool reads a file by
            // its content when its name's reader refuses it (so `oiiotool x.mcstat` shows this
            // image), and --info, --diff x.mcstat or -o x.exr then work; a command that needs a
            // statistics file still refuses the image, after this note has said why.
            stats = false;
            if (named)
                noteOnce(
                    format("{} is a plain EXR image, not a statistics file (no part 'buffers' or "
                           "'vbuffers'; it has {}); read as an image",
                           path, c.partsText()));
            return true;
        case FileContent::Missing:
        case FileContent::Special:
        case FileContent::NotExr:
            return true;
    }
    return true;
}

/// A reference read for a comparison is made scene-linear, as renders are: one in a display
/// encoding (an sRGB PNG or JPEG: OIIO's "oiio:ColorSpace", which OIIO sets to sRGB for those;
/// integer data without one is taken as sRGB) goes through OCIO to the scene-linear colour space,
/// with a note; one in a colour space the OCIO config does not know is refused. Compared as if
/// linear, an sRGB reference gives other metrics and nothing says so (relMSE 0.27 instead of
/// 0.037: ContentCli.SrgbPngReferenceIsMadeSceneLinearBeforeComparing).
bool makeSceneLinear(const std::string& path, OIIO::ImageBuf& rgb, std::string& err) {
    // The header again (readRenderRGB read it; the channels it returns carry no colour space),
    // with the same checks first.
    if (!checkExrAttributeSizes(path, err)) return false;
    std::unique_ptr<OIIO::ImageInput> in = OIIO::ImageInput::create(path, false);
    OIIO::ImageSpec spec;
    if (!in || !in->open(path, spec)) {
        const std::string why = in ? in->geterror() : OIIO::geterror();
        err = format("{}: {}", path, oneLineMessage(why));
        return false;
    }
    in->close();
    std::string space = spec.get_string_attribute("oiio:ColorSpace");
    const bool integer = !spec.format.is_floating_point();
    // Its working space as ingest reads an input's; the pixels are labelled with it, so that
    // the comparison can refuse a reference in another space.
    std::string known, source, problem;
    const bool placed = colorSpaceOf(spec, known, source, problem, path);
    const bool tagged = spec.find_attribute("chromaticities") ||
                        !spec.get_string_attribute("colorInteropID").empty() ||
                        !spec.get_string_attribute("openexr:colorInteropID").empty();
    if (!placed && tagged) {  // chromaticities or an ID of no space mcstat knows
        err = format("{}: {}", path, problem);
        return false;
    }
    if (placed && !(known.empty() && integer)) {
        rgb.specmod().attribute("oiio:ColorSpace", known.empty() ? kSceneLinear : known);
        if (integer)  // declared linear (a PNG with gamma 1): right, but lossy
            noteOnce(
                format("{} holds {} integer pixels ({}): values are quantised and clipped at 1; "
                       "a float EXR reference is better",
                       path, spec.format.c_str(), space));
        return true;
    }
    const bool assumed = space.empty() && integer;
    if (assumed) space = "sRGB";
    const OIIO::ImageSpec& rs = rgb.spec();
    if (rs.nchannels != 3 || rs.format != OIIO::TypeDesc::FLOAT || !rgb.localpixels()) {
        err = format("{}: internal: the RGB read is not 3 float channels in memory", path);
        return false;
    }
    bool converted = false;
    std::string why;
    if (!toSceneLinear(static_cast<float*>(rgb.localpixels()), long(rs.image_pixels()), space,
                       converted, why)) {
        err = format(
            "{}: {} (its oiio:ColorSpace): cannot make it scene-linear to compare with a render; "
            "convert it to a scene-linear EXR first",
            path, why);
        return false;
    }
    // Now in the config's scene-linear space (or already in it: a name OIIO gives linear data).
    const std::string linear = sceneLinearName();
    const WorkingSpace* ws = findWorkingSpace(linear);
    rgb.specmod().attribute("oiio:ColorSpace", ws ? std::string(ws->name) : linear);
    if (converted)
        noteOnce(format(
            "{} is display-encoded ({}{}); converted to scene-linear {} through OCIO "
            "before comparing{}",
            path, space, assumed ? ", assumed: integer pixels naming no colour space" : "", linear,
            integer ? " (its integer pixels are quantised and clipped at 1: a float "
                      "EXR reference is better)"
                    : ""));
    else if (integer)  // declared linear under a name the config has: right, but lossy
        noteOnce(
            format("{} holds {} integer pixels ({}): values are quantised and clipped at 1; "
                   "a float EXR reference is better",
                   path, spec.format.c_str(), space));
    return true;
}

/// Reads `path` as a statistics file's beauty (`stats`) or as an image through OIIO.
bool readImageAs(const std::string& path, bool stats, OIIO::ImageBuf& out, std::string& err) {
    if (stats) {
        StatsImage img;
        if (!readStatsFile(path, img, err)) return false;
        out = beautyImage(img);
        return true;
    }
    if (!OIIO::Filesystem::exists(path)) {
        err = format("{}: no such file", path);
        return false;
    }
    OIIO::ImageBuf in(path);
    if (!in.read(0, 0, true, OIIO::TypeDesc::FLOAT)) {
        err = format("{}: {}", path, OIIO::Strutil::replace(in.geterror(), "\n", " "));
        return false;
    }
    out = std::move(in);
    return true;
}

/// Formats written for the eye: the pixels go through the OCIO display view first.
bool isDisplayFormat(const std::string& ext) {
    static const char* kDisplay[] = {"png", "jpg", "jpeg", "bmp", "tga", "gif", "webp", "ppm"};
    for (const char* d : kDisplay)
        if (ext == d) return true;
    return false;
}

/// Writes `img` as `path` through a temporary name in the same directory (TemporaryFile), renamed
/// on success, so a failed or interrupted write never leaves a partial file under the target name.
bool writeImageAtomically(const OIIO::ImageBuf& img, const std::string& path,
                          const ImageWriteOptions& opt, std::string& err,
                          size_t* overflow = nullptr) {
    if (!checkOutputTarget(path, err)) return false;
    const std::string ext = lowerExtension(path);
    if (ext.empty()) {
        err = format(
            "{}: no file extension to choose the format by (.exr, .tif, .png, .jpg, ... or "
            ".{})",
            path, kStatsExtension);
        return false;
    }
    if (!OIIO::ImageOutput::create(ext)) {
        (void)OIIO::geterror();  // consumed: the message below says it in one line
        err = format("{}: OpenImageIO has no writer for '.{}' files", path, ext);
        return false;
    }
    OIIO::ImageSpec spec = img.spec();
    if (!applyWriteOptions(spec, opt, ext, err)) {
        err = format("{}: {}", path, err);
        return false;
    }
    if (overflow) *overflow = halfOverflow(img, spec);
    TemporaryFile tmp(path);
    auto out = OIIO::ImageOutput::create(ext);
    if (!out || !out->open(tmp.path(), spec) || !img.write(out.get()) || !out->close()) {
        std::string why = out ? out->geterror() : std::string();
        if (why.empty()) why = img.geterror();
        if (why.empty()) why = OIIO::geterror();
        if (why.empty()) why = "the image writer failed without saying why";
        // OIIO names the temporary; the user knows the target.
        err = format("{}: {}", path,
                     oneLineMessage(OIIO::Strutil::replace(why, tmp.path(), path, true)));
        return false;  // tmp removes the partial file
    }
    return tmp.commit(err);
}

}  // namespace

bool pushFile(State& st, const std::string& path, std::string& err) {
    Item item;
    item.name = path;
    bool stats = false;
    if (!readsAsStats(path, stats, err)) return false;
    if (stats) {
        item.path = path;
        if (!readStatsHeader(path, item.header, err)) return false;
    } else {
        item.image = std::make_shared<OIIO::ImageBuf>();
        if (!readImageAs(path, false, *item.image, err)) return false;
    }
    st.stack.push_back(std::move(item));
    return true;
}

bool openSource(const State& st, const Item& item, ItemSource& src, std::string& err) {
    if (item.stats) {
        src.owned.push_back(std::make_unique<MemoryStatsSource>(item.stats, item.name));
    } else if (item.compactInput) {
        ItemSource in;
        if (!openSource(st, *item.compactInput, in, err)) return false;
        auto compact = std::make_unique<CompactStatsSource>();
        if (!compact->init(*in.root, item.compactRule, err, st.nthreads)) return false;
        for (auto& o : in.owned) src.owned.push_back(std::move(o));
        src.owned.push_back(std::move(compact));
    } else if (item.ingest) {
        src.owned.push_back(item.ingest->clone(st.nthreads));
    } else if (!item.mergeInputs.empty()) {
        std::vector<StatsBlockSource*> inputs;
        std::vector<ItemSource> parts(item.mergeInputs.size());
        for (size_t i = 0; i < parts.size(); ++i) {
            if (!openSource(st, *item.mergeInputs[i], parts[i], err)) return false;
            inputs.push_back(parts[i].root);
        }
        auto merged = std::make_unique<MergedStatsSource>();
        if (!merged->init(inputs, err, st.nthreads)) return false;
        for (ItemSource& part : parts)
            for (auto& o : part.owned) src.owned.push_back(std::move(o));
        src.owned.push_back(std::move(merged));
    } else {
        auto reader = std::make_unique<StatsFileReader>();
        if (!reader->open(item.path, err, ReadLimits(), st.nthreads)) return false;
        src.owned.push_back(std::move(reader));
    }
    src.root = src.owned.back().get();
    return true;
}

bool loadStats(State& st, Item& item, std::string& err) {
    if (item.stats) return true;
    auto img = std::make_shared<StatsImage>();
    if (!item.mergeInputs.empty() || item.ingest || item.compactInput) {
        ItemSource src;
        if (!openSource(st, item, src, err) || !readAll(*src.root, *img, err)) return false;
    } else if (!readStatsFile(item.path, *img, err)) {
        return false;
    }
    item.stats = img;
    item.header = img->header;
    return true;
}

bool settleIngest(State& st, Item& item, std::string& err) {
    if (!item.ingest) return true;
    if (!item.ingest->hashed()) {
        // Only the RGB: the hashes are of the beauty (ZIP chunks hold every channel, so this
        // still decodes them all).
        const std::unique_ptr<IngestSource> src = item.ingest->clone(st.nthreads);
        const int rows = src->blockRows(kStatsPartBeauty);
        StatsImage block;
        for (int y = 0; y < src->header().height; y += rows)
            if (!src->read(y, std::min(rows, src->header().height - y), kStatsPartBeauty, block,
                           err))
                return false;
    }
    item.header = item.ingest->header();
    return true;
}

bool readImage(const std::string& path, OIIO::ImageBuf& out, std::string& err) {
    bool stats = false;
    return readsAsStats(path, stats, err) && readImageAs(path, stats, out, err);
}

bool readRGB(const std::string& path, const std::string& layer, OIIO::ImageBuf& out,
             std::string& err) {
    bool stats = false;
    if (!readsAsStats(path, stats, err)) return false;
    if (stats) {
        if (!layer.empty() && layer != ".") {
            err = format(
                "{}: a statistics file has one RGB layer (its beauty); :layer={} does not "
                "apply",
                path, layer);
            return false;
        }
        return readImageAs(path, true, out, err);
    }
    OIIO::ImageBuf rgb;
    if (!readRenderRGB(path, layer, rgb, nullptr, err) || !makeSceneLinear(path, rgb, err))
        return false;
    out = std::move(rgb);
    return true;
}

bool selectRGB(const OIIO::ImageBuf& src, const std::string& layer, const std::string& what,
               OIIO::ImageBuf& out, std::string& err) {
    BeautyChannels beauty;
    std::string problem;
    if (!findBeauty(src.spec().channelnames, layer, beauty, problem)) {
        err = what + ": " + problem;
        return false;
    }
    const int order[3] = {beauty.index[0], beauty.index[1], beauty.index[2]};
    const std::string names[3] = {"R", "G", "B"};
    OIIO::ImageBuf rgb;
    if (!OIIO::ImageBufAlgo::channels(rgb, src, 3, order, {}, names)) {
        err = format("{}: {}", what, rgb.geterror());
        return false;
    }
    out = std::move(rgb);
    return true;
}

std::vector<ParamSpec> ingestModifiers() { return ingestParams(); }

std::vector<ParamSpec> outputModifiers() {
    return {enumParam("type", {"half", "float"}, "", "this output's data type (as -d)"),
            textParam("compression", "",
                      "this output's compression (as --compression, e.g. -o:compression=dwaa:45)")};
}

bool cmdIngest(State& st, const std::string& cmd, const std::vector<std::string>& args,
               const Modifiers& mods, std::string& err) {
    IngestOptions opt;
    if (!parseIngestOptions(mods, opt, err, cmd)) return false;
    std::vector<std::string> paths;
    if (!expandInputs(args[0], paths, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    // Progress on a terminal only: reading many large renders takes a while. The renders are
    // read when the item is used (-o, an estimator), block by block; each pass shows its line.
    if (showProgress()) {
        auto shown = std::make_shared<std::unique_ptr<Progress>>();
        opt.progress = [shown](int64_t done, int64_t total) {
            if (!*shown) *shown = std::make_unique<Progress>("mcstat: ingest", 1000, true);
            (*shown)->set(double(done) / double(std::max<int64_t>(1, total)));
            if (done >= total) shown->reset();  // the pass is done: its final line
        };
    }
    // The pixels' warnings (NaN/Inf) come when a pass has read every row.
    opt.warning = [](const std::string& w) { warning(w); };
    auto src = std::make_shared<IngestSource>();
    if (!src->init(paths, opt, err, st.nthreads)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    const IngestReport& report = src->report();
    for (const std::string& w : report.warnings) warning(w);
    if (st.verbose) {
        // Names from the renders, through printable() (core/untrusted_text.h).
        std::vector<std::string> sources;
        for (const std::string& s : report.features.sources) sources.push_back(printable(s));
        std::fprintf(stderr, "mcstat: ingest: %zu files, beauty %s (%s), features %s\n",
                     paths.size(),
                     report.beauty.layer.empty() ? "R,G,B" : printable(report.beauty.layer).c_str(),
                     printable(report.beauty.rule).c_str(),
                     report.features.present ? OIIO::Strutil::join(sources, "; ").c_str() : "none");
        for (const AovChannel& a : report.aovs)
            std::fprintf(stderr, "mcstat: ingest:   %-6s %s%s%s\n", aovClassName(a.cls),
                         printable(a.name).c_str(), a.part.empty() ? "" : "  (part ",
                         a.part.empty() ? "" : (printable(a.part) + ")").c_str());
    }
    if (st.verbose && !report.aovs.empty()) {
        size_t count[4] = {0, 0, 0, 0};
        for (const AovChannel& a : report.aovs) ++count[int(a.cls)];
        std::fprintf(stderr,
                     "mcstat: ingest: %zu AOV channels kept (%zu alpha, %zu light, %zu data, %zu "
                     "id)%s\n",
                     report.aovs.size(), count[0], count[1], count[2], count[3], "");
    }
    Item item;
    item.name = format("ingest({})", args[0]);
    item.header = src->header();
    item.ingest = std::move(src);
    item.files = paths;
    st.stack.push_back(std::move(item));
    return true;
}

namespace {

/// The write options of -o: -d and --compression for every output, -o:type= and :compression=
/// for this one, checked against what `top` is and what `path`'s extension `ext` holds.
bool outputOptions(const State& st, const std::string& cmd, const std::string& path,
                   const std::string& ext, const Item& top, const Modifiers& mods,
                   ImageWriteOptions& opt, std::string& err) {
    opt = st.write;
    // Checked against outputModifiers() by the command table (checkModifiers): type is half or
    // float; neither has a default, so each is in `mods` only when given.
    const bool type = mods.count("type") != 0, compression = mods.count("compression") != 0;
    if (type) {
        opt.channelTypes.clear();
        parseWriteType(modifierValue(outputModifiers(), mods, "type").text, opt.type);
    }
    if (compression) {
        opt.compression = modifierValue(outputModifiers(), mods, "compression").text;
        if (opt.compression.empty()) {
            err = format("{}:compression=: an empty compression name", cmd);
            return false;
        }
    }
    if (top.isStats() && (type || compression)) {
        err = format(
            "{} {}: a statistics file is written as its format says (float32, ZIP; "
            "exr-deep/FORMAT.md): -o:type= and :compression= apply to images",
            cmd, path);
        return false;
    }
    if (top.isStats() && st.writeOptionsSet)
        note(path +
             " is a statistics file, written as float32 ZIP whatever -d and "
             "--compression say (they apply to images)");
    if (isDisplayFormat(ext) && (opt.type != OIIO::TypeDesc::FLOAT || !opt.channelTypes.empty())) {
        err = format(
            "{} {}: .{} is written as 8-bit display values; -d half applies to EXR and "
            "TIFF",
            cmd, path, ext);
        return false;
    }
    return true;
}

/// -o of a statistics file: block by block, the four statistics parts.
bool writeStatsItem(State& st, const std::string& cmd, const std::string& path,
                    const std::string& ext, Item& top, std::string& err) {
    if (ext != kStatsExtension) {
        err = format(
            "{} {}: {} is a statistics file; write it as .{} or apply an estimator "
            "first (e.g. --gmon)",
            cmd, path, top.name, kStatsExtension);
        return false;
    }
    const StatsHeader& h = top.header;
    if (h.hasState() || h.hasRecords) {
        // The per-sample parts belong to one render's samples in their order: a merge cannot
        // combine them and this tool holds only the four statistics parts in memory. The file
        // written is the lowest version that holds what remains.
        warning(format("{}: {} of {} are not written (only the four statistics parts are)", path,
                       optionalPartsText(h), top.name));
    }
    // Block by block (a file converted, a merge of files): never the whole image in memory.
    // writeStatsFile over a source writes the four parts in the lowest version for them.
    ItemSource src;
    if (!openSource(st, top, src, err)) return false;
    return writeStatsFile(path, *src.root, err, st.nthreads);
}

/// -o of an image: as it is when display-referred, its display view for a display format, else
/// laid out as the render it was computed from (or as it is).
bool writeImageItem(State& st, const std::string& cmd, const std::string& path,
                    const std::string& ext, Item& top, ImageWriteOptions& opt, std::string& err) {
    size_t overflow = 0;
    auto written = [&](bool ok) {
        if (ok && overflow > 0)
            warning(
                format("{}: {} values exceed half's largest, 65504, and were written as Inf "
                       "(write them as float: -d float, or -d CH=float)",
                       path, overflow));
        return ok;
    };
    if (ext == kStatsExtension) {
        err = format("{} {}: {} is an image, not a statistics file", cmd, path, top.name);
        return false;
    }
    if (top.image->spec().get_int_attribute(kDisplayReferredAttr, 0) == 1) {
        // Already display-referred (a contact sheet, heatmap or plot): written as it is.
        if (isDisplayFormat(ext)) opt.type = OIIO::TypeDesc::UINT8;
        return written(writeImageAtomically(*top.image, path, opt, err, &overflow));
    }
    if (isDisplayFormat(ext)) {
        // The display view of the image's R, G, B found by name (a multilayer file's AO pass
        // may come first).
        OIIO::ImageBuf rgb, disp;
        std::string space;
        if (!selectRGB(*top.image, "", top.name, rgb, err) || !itemSpace(top, space, err)) {
            err = format("{} {}: {}", cmd, path, err);
            return false;
        }
        rgb.specmod().attribute("oiio:ColorSpace", space);
        noteDisplayRoute(space);
        if (!displayTransform(disp, rgb, {}, st.nthreads)) {
            err = format("{} {}: {}", cmd, path, disp.geterror());
            return false;
        }
        opt.type = OIIO::TypeDesc::UINT8;
        return writeImageAtomically(disp, path, opt, err);
    }
    // A result computed from a production render: written as that render was laid out (its
    // channel names, parts and AOVs), a drop-in replacement for one input (docs/aovs.md).
    if (top.layout && needsRenderLayout(*top.layout))
        return written(writeRenderLike(*top.image, *top.layout, path, opt, err, &overflow));
    return written(writeImageAtomically(*top.image, path, opt, err, &overflow));
}

}  // namespace

bool cmdOutput(State& st, const std::string& cmd, const std::vector<std::string>& args,
               const Modifiers& mods, std::string& err) {
    if (st.stack.empty()) {
        err = format(
            "{} {}: nothing on the stack to write (arguments run left to right: name a file or a "
            "command that makes an image before -o, e.g. mcstat FILE --gmon -o {})",
            cmd, args[0], args[0]);
        return false;
    }
    Item& top = st.stack.back();
    const std::string& path = args[0];
    if (path.empty()) {
        err = format("{}: an empty file name", cmd);
        return false;
    }
    if (st.noClobber && OIIO::Filesystem::exists(path)) {
        // oiiotool's --no-clobber: an existing output is kept, and the run goes on.
        warning(path + " exists; not overwritten (--no-clobber)");
        return true;
    }
    const std::string ext = lowerExtension(path);
    ImageWriteOptions opt;
    if (!outputOptions(st, cmd, path, ext, top, mods, opt, err)) return false;
    if (top.isStats()) return writeStatsItem(st, cmd, path, ext, top, err);
    return writeImageItem(st, cmd, path, ext, top, opt, err);
}

/// The state parts an operation keeps in the file, described by their owner's registry entry
/// (OperationState::describe, every value checked), or, for an owner this mcstat does not know
/// (a file from a newer mcstat), by what the format says of them: kept, not read.
bool describeState(const std::string& path, const StatsHeader& h, std::string& text,
                   std::string& err) {
    const Operation* op = findOperation(h.state.operation);
    if (op == nullptr || op->state.describe == nullptr) {
        text = format(
            "  {}, {} (state parts of '{}', an operation this mcstat does not know: "
            "their shapes checked, their meaning not; parameters {})\n",
            printable(h.state.flatPart), printable(h.state.deepPart), printable(h.state.operation),
            printable(h.state.params));
        return true;
    }
    PixelStateParts parts;
    if (!readPixelStateParts(path, parts, err)) return false;
    if (!op->state.describe(parts, h.width, text, err)) {
        err = path + ": " + err;
        return false;
    }
    return true;
}

namespace {

/// --info of an image: its size, channels and pixel type.
void printImageInfo(const Item& top) {
    const OIIO::ImageSpec& s = top.image->spec();
    std::vector<std::string> names;
    for (const std::string& n : s.channelnames) names.push_back(printable(n));
    std::printf("%s: %d x %d, %d channels (%s), %s\n", oneLine(top.name).c_str(), s.width, s.height,
                s.nchannels, OIIO::Strutil::join(names, ",").c_str(), s.format.c_str());
}

/// --info of a statistics file's per-sample records and state parts, when it has them.
bool printOptionalParts(const Item& top, const StatsHeader& h, std::string& err) {
    if (h.hasRecords) {
        SampleRecordsReader records;
        if (!records.open(top.path, err)) return false;
        std::string fields;
        for (const std::string& f : records.fields())
            fields += (fields.empty() ? "" : ",") + printable(f);
        std::printf(
            "  records (deep: every sample in the order taken; fields %s; %lld bytes each)\n",
            fields.c_str(), static_cast<long long>(recordBytesOnDisk(records.available().size())));
    }
    if (h.hasState()) {
        std::string text;
        if (!describeState(top.path, h, text, err)) return false;
        std::fputs(text.c_str(), stdout);
    }
    return true;
}

/// --info of the buffers a compact file keeps, or of adaptive M's per-pixel counts.
void printBufferLayout(const StatsHeader& h, const StatsImage& s) {
    if (h.compact) {  // which pixels kept their buffers (FORMAT.md "Version 6")
        size_t kept = 0;
        for (size_t p = 0; p < s.pixelCount(); ++p) kept += h.M > 1 && s.buffersOf(p) == h.M;
        const double px = double(std::max<size_t>(1, s.pixelCount()));
        std::printf(
            "  compact: %zu of %zu pixels (%.2f %%) keep their %d sub-buffers, the others their "
            "mean; %zu sub-buffers = %.4f image buffers\n",
            kept, s.pixelCount(), 100.0 * double(kept) / px, h.M, s.bufferCount.size(),
            double(s.bufferCount.size()) / px);
    } else if (h.adaptiveM) {  // Jung's adaptive M: the per-pixel buffer counts
        int mmin = h.M, mmax = 0;
        for (size_t p = 0; p < s.pixelCount(); ++p) {
            mmin = std::min(mmin, s.buffersOf(p));
            mmax = std::max(mmax, s.buffersOf(p));
        }
        std::printf(
            "  adaptive M: m_p min %d, mean %.4f, max %d (M_max %d); %zu sub-buffers = %.4f "
            "image buffers\n",
            mmin, double(s.bufferCount.size()) / double(std::max<size_t>(1, s.pixelCount())), mmax,
            h.M, s.bufferCount.size(),
            double(s.bufferCount.size()) / double(std::max<size_t>(1, s.pixelCount())));
    }
}

/// --info -v: the samples per pixel, the empty sub-buffers and the non-finite values.
void printSampleCounts(const StatsImage& s) {
    double nmin = INFINITY, nmax = 0.0, ntotal = 0.0;
    long emptyBuffers = 0, nonFinite = 0;
    for (size_t p = 0; p < s.pixelCount(); ++p) {
        nmin = std::min(nmin, double(s.count[p]));
        nmax = std::max(nmax, double(s.count[p]));
        ntotal += s.count[p];
    }
    for (size_t i = 0; i < s.bufferCount.size(); ++i) emptyBuffers += s.bufferCount[i] == 0.f;
    for (float v : s.bufferMean) nonFinite += !std::isfinite(v);
    std::printf("  samples per pixel: min %.0f, max %.0f, mean %.2f\n", nmin, nmax,
                ntotal / double(std::max<size_t>(1, s.pixelCount())));
    std::printf("  empty sub-buffers: %ld of %zu; non-finite sub-buffer values: %ld\n",
                emptyBuffers, s.bufferCount.size(), nonFinite);
}

}  // namespace

bool cmdInfo(State& st, const std::string& cmd, const std::vector<std::string>&, const Modifiers&,
             std::string& err) {
    if (st.stack.empty()) {
        err = format(
            "{0}: nothing on the stack to describe (arguments run left to right: put the file "
            "first, mcstat FILE {0})",
            cmd);
        return false;
    }
    Item& top = st.stack.back();
    if (!top.isStats()) {
        printImageInfo(top);
        return true;
    }
    if (!settleIngest(st, top, err)) {  // the seeds of renders are their RGB hashes
        err = format("{}: {}", cmd, err);
        return false;
    }
    const StatsHeader& h = top.header;
    // Every string below comes from the file: printable() (core/untrusted_text.h).
    std::printf("%s: mcstat statistics file, format %d\n", oneLine(top.name).c_str(),
                h.formatVersion);
    for (const std::string& line : describeStatsHeader(h)) std::printf("%s\n", line.c_str());
    if (!printOptionalParts(top, h, err)) return false;
    std::printf(
        "  checked: the headers and chunk table only; --check reads and validates every "
        "value\n");
    if (!st.verbose && !h.adaptiveM) return true;
    if (!loadStats(st, top, err)) return false;
    const StatsImage& s = *top.stats;
    // A compact file or adaptive M: its buffers (all that is printed without -v).
    printBufferLayout(h, s);
    if (!st.verbose) return true;
    printSampleCounts(s);
    return true;
}

bool cmdCheck(State& st, const std::string& cmd, const std::vector<std::string>&, const Modifiers&,
              std::string& err) {
    if (st.stack.empty()) {
        err = format(
            "{0}: nothing on the stack to check (arguments run left to right: put the file first, "
            "mcstat FILE {0})",
            cmd);
        return false;
    }
    const Item& top = st.stack.back();
    if (!top.isStats()) {
        err = format(
            "{}: {} is an image, not a statistics file: --check validates a statistics file's "
            "parts, sub-buffers and sample counts, which a plain image does not have (exrcheck "
            "checks an EXR's structure)",
            cmd, top.name);
        return false;
    }
    if (top.path.empty()) {
        err = format(
            "{}: {} is made in memory, not read from a file: --check validates a statistics file "
            "on disk (write it with -o f.{} and check that, or check the files it came from)",
            cmd, top.name, kStatsExtension);
        return false;
    }
    // Progress on a terminal only: a large file takes as long as decoding it.
    Progress progress(top.name + ": checking", 1000, showProgress());
    StatsCheckReport r;
    const bool ok =
        checkStatsFile(top.path, r, err, ReadLimits(), st.nthreads, progress.fractionCallback());
    progress.finish();
    if (!ok) return false;
    const StatsHeader& h = r.header;
    std::string stateText;  // the owner's own check of what its parts mean
    if (r.state && !describeState(top.path, h, stateText, err)) return false;
    std::printf("%s: valid mcstat statistics file, format %d, %d x %d, %s %d\n",
                oneLine(top.name).c_str(), h.formatVersion, h.width, h.height,
                h.adaptiveM ? "adaptive M, M_max" : "M", h.M);
    std::printf(
        "  OpenEXR's checker passed; %lld pixels and %lld sub-buffers decoded, every count "
        "finite, integral, 0..2^24 and summing to the pixel's; %lld non-finite sub-buffer "
        "means (allowed)\n",
        (long long)r.pixels, (long long)r.subBuffers, (long long)r.nonFinite);
    if (h.hasRecords) std::printf("  records: %lld samples decoded\n", (long long)r.records);
    if (r.state) {
        const bool known = findOperation(h.state.operation) != nullptr;
        std::printf("  %s, %s: decoded%s\n", printable(h.state.flatPart).c_str(),
                    printable(h.state.deepPart).c_str(),
                    known ? " and checked" : " (their owner unknown to this mcstat)");
        std::fputs(stateText.c_str(), stdout);
    }
    return true;
}

}  // namespace mcstat::cli
