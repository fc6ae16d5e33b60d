// Command table, argument loop and the commands that compute (estimators, --diff, --merge, stack
// operations). Reading, writing and --info live in io.cpp.
#include "cli.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <OpenImageIO/timer.h>
#include <unistd.h>

#include <array>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <set>

#include "mcstat/color/color.h"
#include "mcstat/core/progress.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/keep_light_image.h"
#include "mcstat/image/operation_input.h"
#include "mcstat/image/removed_light_layers.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/ingest/ingest.h"
#include "mcstat/review/display.h"
#include "mcstat/version.h"

namespace mcstat::cli {

using OIIO::Strutil::fmt::format;

std::vector<ParamSpec> diffModifiers(bool neps) {
    std::vector<ParamSpec> m = {
        realParam("ratio", 0.0, HUGE_VAL, false, "2",
                  "firefly: Y > ratio*Yref and Y - Yref > floor (Y: luminance)"),
        realParam("floor", 0.0, HUGE_VAL, false, "0.1", "firefly: Y - Yref > floor"),
        realParam("eps", 0.0, HUGE_VAL, false, "0.01", "relMSE denominator r^2 + eps"),
    };
    if (neps)
        m.push_back(realParam("neps", 0.0, HUGE_VAL, true, "0.01",
                              "normalised error denominator max(|Yref|, neps)"));
    m.push_back(textParam("layer", "",
                          "REF's RGB layer, e.g. ViewLayer.Combined; default: its beauty "
                          "(docs/ingest.md)"));
    return m;
}

void readDiffOptions(const Modifiers& mods, DiffOptions& opt) {
    // Checked against diffModifiers() by the command table (checkModifiers), defaults filled in.
    const std::vector<ParamSpec> specs = diffModifiers(true);
    const std::pair<const char*, double*> metrics[] = {{"ratio", &opt.fireflyRatio},
                                                       {"floor", &opt.fireflyFloor},
                                                       {"eps", &opt.relmseEpsilon},
                                                       {"neps", &opt.normEpsilon}};
    for (const auto& [key, target] : metrics)
        if (mods.count(key)) *target = modifierValue(specs, mods, key).real;
}

void printDiffLine(const std::string& name, const DiffMetrics& m) {
    std::printf("%-28s relMSE %.6g  SSIM %.5f  PSNR %.3f dB  fireflies %ld / %ld", name.c_str(),
                m.relMSE, m.ssim, m.psnr, m.fireflies, m.pixels);
    // Jung's normalised error (eq. 5.25-5.27), on luminance
    std::printf("  nbias %.5g  nnoise %.5g", m.normBias, m.normNoise);
    // Pixel-scale detail kept (a blur lowers it; noise does not), docs/metrics.md
    std::printf("  detail %.4f", m.detail);
    // The light it holds against the reference's (sum of luminance), docs/metrics.md
    std::printf("  energy %+.4f", m.energy);
    if (m.nonFinite) std::printf("  non-finite %ld", m.nonFinite);
    std::printf("\n");
    std::fflush(stdout);
}

namespace {

bool needStack(State& st, size_t n, const std::string& cmd, std::string& err) {
    if (st.stack.size() >= n) return true;
    err = format("{} needs {} image{} on the stack, there {} {}", cmd, n, n > 1 ? "s" : "",
                 st.stack.size() == 1 ? "is" : "are", st.stack.size());
    return false;
}

// ---- operation commands, one per registry entry ------------------------------------------------

bool needStatsOnTop(State& st, const std::string& cmd, std::string& err) {
    if (!needStack(st, 1, cmd, err)) return false;
    const Item& top = st.stack.back();
    if (top.isStats()) return true;
    err = format(
        "{}: {} is an image, not a statistics file (.{}); renders of one image (one EXR "
        "per seed) become one with --ingest 'render_*.exr'",
        cmd, top.name, kStatsExtension);
    return false;
}

/// The operation's input from the top of the stack: a statistics file (in memory, or streamed by
/// blocks of rows from disk), or for the operations that filter an image (MIF, WMIF) the top image.
/// Per-sample operations read the file from disk themselves.
bool checkOperationInput(State& st, const std::string& cmd, const Operation& op, std::string& err) {
    if (st.stack.empty()) {
        err = format("{} needs {} on the stack", cmd,
                     takesImage(op) ? "an image" : "a statistics file");
        return false;
    }
    const Item& top = st.stack.back();
    if (takesImage(op) && top.isStats()) {
        err = format("{}: {} is a statistics file; apply an estimator first (e.g. --median)", cmd,
                     top.name);
        return false;
    }
    if (!takesImage(op) && !needStatsOnTop(st, cmd, err)) return false;
    if (readsSamples(op) && top.path.empty()) {
        err = format(
            "{} reads the per-sample records of a statistics file on disk; {} was "
            "computed (write it with -o and read it back)",
            cmd, top.name);
        return false;
    }
    return true;
}

/// Runs `op` with `values` on the top of the stack into `img` through the dispatcher.
/// A streamed source that reports the rows read to a progress line: a streamed operation reads
/// every row once (plus a window filter's halo rows), so the rows read are its progress.
class ProgressSource final : public StatsBlockSource {
  public:
    ProgressSource(StatsBlockSource& src, Progress& progress) : src_(src), progress_(progress) {}
    const StatsHeader& header() const override { return src_.header(); }
    const std::string& name() const override { return src_.name(); }
    int chunkRows() const override { return src_.chunkRows(); }
    int decodeThreads() const override { return src_.decodeThreads(); }
    bool read(int firstRow, int rows, unsigned parts, StatsImage& block,
              std::string& err) override {
        if (!src_.read(firstRow, rows, parts, block, err)) return false;
        rowsRead_ += rows;
        const int h = std::max(1, header().height);
        progress_.set(std::min(1.0, double(rowsRead_) / h));
        return true;
    }

  private:
    StatsBlockSource& src_;
    Progress& progress_;
    int64_t rowsRead_ = 0;
};

bool applyToTop(State& st, const std::string& cmd, const Operation& op, const ParamValues& values,
                bool diag, OIIO::ImageBuf& img, std::string& err) {
    Item& top = st.stack.back();
    std::array<double, 3> luma{};
    if (!itemLuma(top, luma, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    // What the top holds, described once (image/operation_input.h); the operation takes what its
    // kind needs. Progress on a terminal only: a large file or RPF takes a while.
    Progress progress("mcstat: " + cmd, 1000, showProgress());
    OperationInput in;
    in.name = top.name;
    in.imageOperationsFilterTheMean = false;  // `--mean --mif` says which image MIF filters
    OIIO::ImageBuf rgb;
    ItemSource src;
    std::unique_ptr<ProgressSource> shown;
    if (top.isStats()) {
        in.stats = top.stats.get();
        in.path = top.path;
        in.header = &top.header;
        in.progress = progress.fractionCallback();
        // A file on disk (or a merge of files) is streamed by blocks of rows.
        in.stream = [&](std::string& e) -> StatsBlockSource* {
            if (!openSource(st, top, src, e)) return nullptr;
            shown = std::make_unique<ProgressSource>(*src.root, progress);
            return shown.get();
        };
    } else {
        // An image filter works on R, G, B found by name; an estimator's result over a file with
        // AOVs (R, G, B first, then its AOVs, kAttrFirstAov) goes whole: the filter gives each
        // window pixel's AOVs the beauty's weights.
        const bool withAovs = top.image->spec().get_int_attribute(kAttrFirstAov, -1) == 3;
        if (!withAovs && !selectRGB(*top.image, "", top.name, rgb, err)) {
            err = format("{}: {}", cmd, err);
            return false;
        }
        in.image = withAovs ? top.image.get() : &rgb;
    }
    const bool ok = applyOperation(img, in, op, values, luma, diag, {}, st.nthreads);
    if (!ok) err = format("{}: {}", cmd, img.geterror());
    return ok;
}

/// Appends layers computed again from the top statistics file to `img`, an operation's result
/// over it: `append(img, source, luma)` over the file in memory, or over a new stream of it from
/// its first row (a streamed source is read once more).
template <class Append>
bool appendFromTop(State& st, const std::string& cmd, OIIO::ImageBuf& img, std::string& err,
                   Append append) {
    Item& top = st.stack.back();
    std::array<double, 3> luma{};
    if (!itemLuma(top, luma, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    ItemSource again;
    if (!top.stats && !openSource(st, top, again, err)) return false;
    if (!(top.stats ? append(img, *top.stats, luma) : append(img, *again.root, luma))) {
        err = format("{}: {}", cmd, img.geterror());
        return false;
    }
    return true;
}

/// Appends the residual channels (mean - robust) to `img`.
bool appendTopResidual(State& st, const std::string& cmd, OIIO::ImageBuf& img, std::string& err) {
    return appendFromTop(st, cmd, img, err, [&](OIIO::ImageBuf& i, auto& src, const auto& luma) {
        return appendResidual(i, src, luma, st.nthreads);
    });
}

/// Appends the removed-light layers (removed_light_layers.h) to `img`, before any residual.
bool appendTopRemovedLight(State& st, const std::string& cmd, const RemovedLightOptions& opt,
                           OIIO::ImageBuf& img, std::string& err) {
    return appendFromTop(st, cmd, img, err, [&](OIIO::ImageBuf& i, auto& src, const auto& luma) {
        return appendRemovedLight(i, src, luma, opt, st.nthreads);
    });
}

/// Every registry operation's command: its parameters from the modifiers, then the dispatcher
/// over the top of the stack, which the result replaces.
bool cmdOperation(State& st, const std::string& cmd, const std::vector<std::string>&,
                  const Modifiers& mods, std::string& err) {
    const Operation& op = *findOperation(cmd.substr(2));
    if (!checkOperationInput(st, cmd, op, err)) return false;
    Modifiers opMods = mods;
    // Checked against the same specs by the command table (checkModifiers), defaults filled in.
    const std::vector<ParamSpec> specs = operationModifiers(op);
    const auto flag = [&](const char* key) { return modifierValue(specs, mods, key).integer != 0; };
    const bool diag = flag("diag"), residual = flag("residual"), removed = flag("removed");
    RemovedLightOptions removedOpt;
    if (removed) {
        removedOpt.radius = int(modifierValue(specs, mods, "removedradius").integer);
        removedOpt.zLimit = modifierValue(specs, mods, "removedz").real;
    }
    for (const char* k : {"diag", "residual", "removed", "removedradius", "removedz"})
        opMods.erase(k);
    ParamValues ci;  // ci, ciaovs: the interval layers (docs/confidence.md)
    if (!takeConfidenceModifiers(cmd, opMods, ci, err)) return false;
    ParamValues keep;  // keeplight: the removed light given back (docs/keep-light.md)
    if (!takeKeepLightModifiers(cmd, opMods, keep, err)) return false;
    ParamValues values;
    if (!parseOperationParams(op, opMods, values, err, cmd)) return false;
    values.insert(ci.begin(), ci.end());
    values.insert(keep.begin(), keep.end());
    auto img = std::make_shared<OIIO::ImageBuf>();
    // A per-pixel estimator computes the removed-light layers in its own pass over the buffers;
    // the others' layers are appended from a second read (removed_light_pass.h).
    const bool removedInPass = removed && removedLightInPass(op, keepLightAsked(values));
    ParamValues runValues = values;
    if (removedInPass) setRemovedLightValues(runValues, removedOpt);
    if (!applyToTop(st, cmd, op, runValues, diag, *img, err)) return false;
    if (removed && !removedInPass && !appendTopRemovedLight(st, cmd, removedOpt, *img, err))
        return false;
    if (residual && !appendTopResidual(st, cmd, *img, err)) return false;
    // The operation and every parameter (given, default or fixed) as the result's metadata.
    img->specmod().attribute("mcstat:estimator", op.name);
    for (const ParamSpec& p : op.params)
        img->specmod().attribute("mcstat:" + p.name, values.at(p.name).text);
    Item& top = st.stack.back();
    if (top.isStats() || top.layout) describeOperationResult(top, op, values, *img);
    replaceWithImage(top, op.name, img, true);
    return true;
}

// ---- comparison and merging ---------------------------------------------------------------------

bool cmdDiff(State& st, const std::string& cmd, const std::vector<std::string>& args,
             const Modifiers& mods, std::string& err) {
    if (!needStack(st, 1, cmd, err)) return false;
    const Item& top = st.stack.back();
    if (top.isStats()) {
        err = format("{}: {} is a statistics file; apply an estimator first (e.g. --mean)", cmd,
                     top.name);
        return false;
    }
    DiffOptions opt;
    if (!itemLuma(top, opt.luma, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    readDiffOptions(mods, opt);
    // R, G, B by name on both sides: a multilayer reference whose AO layer sorts before its
    // Combined pass must not be compared with AO.
    OIIO::ImageBuf ref, img;
    std::string refSpace;
    if (!readRGB(args[0], modifierValue(diffModifiers(false), mods, "layer").text, ref, err) ||
        !selectRGB(*top.image, "", top.name, img, err) || !itemSpace(top, opt.space, err) ||
        !imageSpace(ref.spec(), args[0], refSpace, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    // One luminance and one display for both sides: the same working space (docs/color.md).
    if (!sameSpace(cmd, top.name, opt.space, args[0], refSpace, err, isImageFile(top), true))
        return false;
    DiffMetrics m;
    if (!diffImages(img, ref, opt, m, err)) {
        err = format("{}: {} vs {}: {}", cmd, top.name, args[0], err);
        return false;
    }
    printDiffLine(top.name, m);
    return true;
}

std::vector<ParamSpec> mergeModifiers() {
    return {intParam("fanin", 2, kMaxBuffers, std::to_string(kDefaultMergeFanIn),
                     "inputs per node of the merge tree (its depth is ceil(log_fanin N)); a farm "
                     "that merges in jobs uses the same value to get the same bytes"),
            intParam("n", 0, 1 << 20, "0", "merge the top n entries of the stack; 0: all"),
            flagParam("force", "0",
                      "merge renders of different scenes (mcstat:scene) all the same; the result "
                      "names every scene")};
}

/// "merge(a, b, c)", or for many inputs "merge of N files (first, ..., last)".
std::string mergeName(const std::vector<std::shared_ptr<const Item>>& in) {
    if (in.size() <= 4) {
        std::string s = "merge(" + in[0]->name;
        for (size_t i = 1; i < in.size(); ++i) s += ", " + in[i]->name;
        return s + ")";
    }
    return format("merge of {} files ({}, ..., {})", in.size(), in.front()->name, in.back()->name);
}

/// --merge: the statistics files on the stack (every entry, or the top :n=) in one file. The
/// inputs are sorted by their seeds (mergeOrder), then merged by a fixed tree: consecutive groups
/// of :fanin= inputs, each merged in one pass, the groups' results grouped again, until one is
/// left (FORMAT.md "Merge of N files"). The tree depends only on the inputs, so any input order
/// gives the same bytes, and a farm that runs the same groups as separate jobs gets the same file.
bool cmdMerge(State& st, const std::string& cmd, const std::vector<std::string>&,
              const Modifiers& mods, std::string& err) {
    const size_t fanin = size_t(modifierValue(mergeModifiers(), mods, "fanin").integer);
    const int64_t nGiven = modifierValue(mergeModifiers(), mods, "n").integer;
    const size_t n = nGiven > 0 ? size_t(nGiven) : st.stack.size();
    if (!needStack(st, std::max<size_t>(n, 2), cmd, err)) return false;
    if (n < 2) {
        err = format("{}:n={} merges nothing; give at least 2", cmd, n);
        return false;
    }
    const size_t first = st.stack.size() - n;
    std::vector<std::shared_ptr<const Item>> leaves;
    std::vector<const StatsHeader*> headers;
    std::vector<std::string> names;
    for (size_t i = first; i < st.stack.size(); ++i) {
        // An ingest's seeds are its renders' RGB hashes: the merge's seed check needs them.
        if (!settleIngest(st, st.stack[i], err)) {
            err = format("{}: {}", cmd, err);
            return false;
        }
        const Item& it = st.stack[i];
        if (!it.isStats()) {
            err = nGiven > 0 ? format("{} merges statistics files; {} is an image", cmd, it.name)
                             : format(
                                   "{} merges every statistics file on the stack; {} is an "
                                   "image (merge only the top N with {}:n=N)",
                                   cmd, it.name, cmd);
            return false;
        }
        for (size_t j = first; j < i; ++j)
            if (!it.path.empty() && st.stack[j].path == it.path) {
                err = format("{}: {} is given twice (its samples would be counted twice)", cmd,
                             it.path);
                return false;
            }
        leaves.push_back(std::make_shared<const Item>(it));
    }
    for (const auto& leaf : leaves) {
        headers.push_back(&leaf->header);
        names.push_back(leaf->name);
    }
    // Renders of different scenes (by what their renderer recorded) sum to nothing meaningful.
    // Inputs that record no scene agree with any; the others must all record the first one's.
    if (modifierValue(mergeModifiers(), mods, "force").integer == 0) {
        size_t j = 0;
        while (j < headers.size() && headers[j]->scene.empty()) ++j;
        for (size_t i = j + 1; i < headers.size(); ++i)
            if (!headers[i]->scene.empty() && headers[i]->scene != headers[j]->scene) {
                err = format(
                    "{}: {} and {} are renders of different scenes ('{}' vs '{}'); merge "
                    "renders of one scene, or give {}:force=1 if they are one",
                    cmd, names[j], names[i], printable(headers[j]->scene),
                    printable(headers[i]->scene), cmd);
                return false;
            }
    }
    // Every input against the first, and seeds across all inputs, before any grouping: the
    // message names the two files involved.
    StatsHeader whole;
    if (!mergeHeaders(headers, whole, err, names)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    std::vector<std::shared_ptr<const Item>> level;
    for (size_t i : mergeOrder(headers)) level.push_back(leaves[i]);
    while (level.size() > 1) {
        std::vector<std::shared_ptr<const Item>> next;
        for (size_t g = 0; g < level.size(); g += fanin) {
            const size_t end = std::min(level.size(), g + fanin);
            if (end - g == 1) {  // a group of one passes through unchanged
                next.push_back(level[g]);
                continue;
            }
            Item node;
            node.mergeInputs.assign(level.begin() + ptrdiff_t(g), level.begin() + ptrdiff_t(end));
            std::vector<const StatsHeader*> h;
            for (const auto& in : node.mergeInputs) h.push_back(&in->header);
            if (!mergeHeaders(h, node.header, err)) {
                err = format("{}: {}", cmd, err);
                return false;
            }
            node.name = mergeName(node.mergeInputs);
            next.push_back(std::make_shared<const Item>(std::move(node)));
        }
        level = std::move(next);
    }
    Item out = *level[0];
    out.name = mergeName(leaves);
    st.stack.resize(first);
    st.stack.push_back(std::move(out));
    return true;
}

std::vector<ParamSpec> compactModifiers() {
    return {realParam("margin", 0.0, 1.0, false, "0",
                      "also keep the buffers of pixels whose Gini coefficient G is within this "
                      "fraction of G-MoN's threshold: G * floor(M/2) >= 1 - margin"),
            realParam("z", 0.0, HUGE_VAL, false, "0",
                      "also keep the buffers of pixels with a buffer more than z robust sigmas "
                      "(1.4826 MAD of the luminances) from their median; 0: off")};
}

/// --compact: the top statistics file as a compact one (FORMAT.md "Version 6"), computed block by
/// block when used (-o, an operation), so a large file never sits in memory whole.
bool cmdCompact(State& st, const std::string& cmd, const std::vector<std::string>&,
                const Modifiers& mods, std::string& err) {
    if (!needStatsOnTop(st, cmd, err)) return false;
    Item& top = st.stack.back();
    // An ingest's seeds are its renders' RGB hashes, known once read: the header needs them.
    if (!settleIngest(st, top, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    CompactRule rule;
    if (!itemLuma(top, rule.luma, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    rule.margin = modifierValue(compactModifiers(), mods, "margin").real;
    rule.z = modifierValue(compactModifiers(), mods, "z").real;
    Item out;
    // The header, and every refusal (adaptive M, already compact), before any pixel is read.
    if (!compactHeader(top.header, top.name, rule, out.header, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    out.compactInput = std::make_shared<const Item>(top);
    out.compactRule = rule;
    if (top.header.hasState() || top.header.hasRecords)
        warning(
            format("{}: {} of {} are not kept in the compact file (resume or re-estimate "
                   "from the full file)",
                   cmd, optionalPartsText(top.header), top.name));
    out.name = "compact(" + top.name + ")";
    top = std::move(out);
    return true;
}

// ---- stack and global options -------------------------------------------------------------------

bool cmdDup(State& st, const std::string& cmd, const std::vector<std::string>&, const Modifiers&,
            std::string& err) {
    if (!needStack(st, 1, cmd, err)) return false;
    st.stack.push_back(st.stack.back());  // shares pixels; every command replaces, never mutates
    return true;
}

bool cmdPop(State& st, const std::string& cmd, const std::vector<std::string>&, const Modifiers&,
            std::string& err) {
    if (!needStack(st, 1, cmd, err)) return false;
    st.stack.pop_back();
    return true;
}

bool cmdSwap(State& st, const std::string& cmd, const std::vector<std::string>&, const Modifiers&,
             std::string& err) {
    if (!needStack(st, 2, cmd, err)) return false;
    std::swap(st.stack[st.stack.size() - 1], st.stack[st.stack.size() - 2]);
    return true;
}

bool cmdThreads(State& st, const std::string& cmd, const std::vector<std::string>& args,
                const Modifiers&, std::string& err) {
    int64_t n = 0;
    if (!parseInt(args[0], cmd, 0, 4096, n, err)) {
        err = format("{}: expected a thread count 0..4096 (0 = all cores), not '{}'", cmd, args[0]);
        return false;
    }
    st.nthreads = int(n);
    OIIO::attribute("threads", int(n));
    return true;
}

bool cmdColorConfig(State&, const std::string& cmd, const std::vector<std::string>& args,
                    const Modifiers&, std::string& err) {
    if (!setColorConfig(args[0], err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    return true;
}

bool cmdVerbose(State& st, const std::string&, const std::vector<std::string>&, const Modifiers&,
                std::string&) {
    st.verbose = true;
    return true;
}

bool cmdHelp(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
             std::string&);

bool cmdDataType(State& st, const std::string& cmd, const std::vector<std::string>& args,
                 const Modifiers&, std::string& err) {
    const std::string& a = args[0];
    const size_t eq = a.find('=');
    OIIO::TypeDesc type;
    if (!parseWriteType(eq == std::string::npos ? a : a.substr(eq + 1), type) || eq == 0) {
        err =
            format("{}: TYPE must be half or float, or CH=TYPE for one channel, not '{}'", cmd, a);
        return false;
    }
    if (eq == std::string::npos) {
        st.write.type = type;
        st.write.channelTypes.clear();
    } else {
        st.write.channelTypes[a.substr(0, eq)] = type;
    }
    st.writeOptionsSet = true;
    return true;
}

bool cmdCompression(State& st, const std::string& cmd, const std::vector<std::string>& args,
                    const Modifiers&, std::string& err) {
    if (args[0].empty()) {
        err = format("{}: an empty compression name", cmd);
        return false;
    }
    // The syntax now; the codec against the format when -o knows it.
    if (!checkCompression(args[0], "", err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    st.write.compression = args[0];
    st.writeOptionsSet = true;
    return true;
}

/// The frame options reach no command: runFrames takes them out of a command line with a frame
/// pattern, so here they stand alone.
bool cmdFrameOption(State&, const std::string& cmd, const std::vector<std::string>&,
                    const Modifiers&, std::string& err) {
    err = format("{}: no file name holds a frame pattern (#, @, %0Nd; e.g. shot.#.exr)", cmd);
    return false;
}

bool cmdNoClobber(State& st, const std::string&, const std::vector<std::string>&, const Modifiers&,
                  std::string&) {
    st.noClobber = true;
    return true;
}

/// -q is read before the commands run (run()); here it has nothing left to do.
bool cmdQuiet(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
              std::string&) {
    return true;
}

bool cmdVersion(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
                std::string&) {
    std::printf("mcstat %s\n", MCSTAT_VERSION);
    std::exit(0);
}

std::vector<Command> buildTable() {
    std::vector<Command> t = {
        {"--help",
         0,
         "",
         "Print this help and exit; --help COMMAND (or COMMAND --help) prints that command's "
         "modifiers with their ranges and defaults",
         {},
         &cmdHelp,
         ""},
        {"-h", 0, "", "Same as --help", {}, &cmdHelp, ""},
        {"--version", 0, "", "Print the version and exit", {}, &cmdVersion, ""},
        {"-q",
         0,
         "",
         "Quiet: no warnings, notes or progress lines (errors and results still print)",
         {},
         &cmdQuiet,
         ""},
        {"-v",
         0,
         "",
         "Verbose, wherever it stands on the line (as -q): report each command and its time on "
         "stderr; --info adds counts",
         {},
         &cmdVerbose,
         ""},
        {"--colorconfig",
         1,
         "FILE",
         "The OCIO config for every later command, as oiiotool's (instead of $OCIO or mcstat's "
         "own); ocio:// URIs need OpenColorIO 2.2 (docs/color.md)",
         {},
         &cmdColorConfig,
         ""},
        {"--threads",
         1,
         "N",
         "Threads for every later command (0 = all cores)",
         {},
         &cmdThreads,
         ""},
        {"--info",
         0,
         "",
         "Describe the top of the stack (a statistics file: size, M, spp, parts; from its headers, "
         "which are checked, and with -v its counts)",
         {},
         &cmdInfo,
         ""},
        {"--check",
         0,
         "",
         "Validate the top statistics file completely, as exrcheck does and more: OpenEXR's own "
         "checker, then every value of every part decoded by blocks and every count checked; "
         "exit status 1 with the first problem",
         {},
         &cmdCheck,
         ""},
        {"-o", 1, "FILE",
         "Write the top image: EXR/TIFF as scene-linear float (or as -d says); PNG/JPEG through "
         "the OCIO display view; a statistics file as ." +
             std::string(kStatsExtension),
         outputModifiers(), &cmdOutput, ""},
        {"-d",
         1,
         "TYPE",
         "Data type of every later image output: half or float; CH=TYPE for one channel "
         "(e.g. -d half -d Z=float); half warns when values exceed 65504",
         {},
         &cmdDataType,
         ""},
        {"--compression",
         1,
         "NAME[:LEVEL]",
         "Compression of every later image output (EXR: none, rle, zips, zip, piz, pxr24, b44, "
         "b44a, dwaa, dwab; LEVEL 1..9 for zip/zips, 1..1000000 for dwaa/dwab, e.g. dwaa:45; "
         "other formats 0..100, e.g. jpeg:90), checked",
         {},
         &cmdCompression,
         ""},
        {"--no-clobber",
         0,
         "",
         "Keep existing files from here on: every later -o skips a target that exists, with a "
         "warning (outputs before it still replace theirs)",
         {},
         &cmdNoClobber,
         ""},
        {"--frames",
         1,
         "RANGE",
         "Frames of a sequence: N, A-B, A-BxSTEP, comma-separated (default: the frames whose "
         "files exist for the first input pattern); file names hold # (4 digits), @ (1 digit) "
         "or %0Nd, and the command line runs once per frame",
         {},
         &cmdFrameOption,
         ""},
        {"--framepadding",
         1,
         "N",
         "Digits of # in frame patterns (default 4)",
         {},
         &cmdFrameOption,
         ""},
        {"--parallel-frames",
         0,
         "",
         "Run the frames as processes in parallel on the cores (output printed in frame order, "
         "files identical to a serial run)",
         {},
         &cmdFrameOption,
         ""},
        {"--skip-bad-frames",
         0,
         "",
         "Go on past a frame that fails (the exit status is still 1, naming the frames)",
         {},
         &cmdFrameOption,
         ""},
    };
    // Every registry operation is a command; its modifiers are the operation's parameters (and
    // diag, residual: operationModifiers).
    for (const Operation& op : operationRegistry()) {
        t.push_back(
            {"--" + op.name, 0, "", op.help, operationModifiers(op), &cmdOperation, op.name});
    }
    t.push_back(
        {"--diff", 1, "REF",
         "Print relMSE, SSIM, PSNR, the firefly-pixel count and Jung's normalised bias and noise "
         "(eq. 5.25-5.27) of the top image against REF (R, G, B found by name in both)",
         diffModifiers(true), &cmdDiff, ""});
    t.push_back({"--compare", 0, "",
                 "Are the top two renders the same image up to their noise? Per pixel and tile "
                 "tests on the sub-buffers of two statistics files (or one and a reference "
                 "image), false discovery rate controlled; prints the verdict and evidence, "
                 "replaces both by the maps p, z, effect, differs; exit status 2 when they "
                 "differ (docs/compare.md)",
                 compareModifiers(), &cmdCompare, ""});
    t.push_back({"--ingest", 1, "FILES",
                 "Push one statistics file built from renders of one image, one EXR per seed "
                 "(glob or comma-separated list; one sub-buffer per file, docs/ingest.md)",
                 ingestModifiers(), &cmdIngest, ""});
    t.push_back({"--merge", 0, "",
                 "Merge the statistics files on the stack (renders of one image with different "
                 "seeds) into one, as if one render had taken all their samples: sorted by seed, "
                 "then merged by a fixed tree, so any input order gives the same bytes",
                 mergeModifiers(), &cmdMerge, ""});
    t.push_back({"--compact", 0, "",
                 "Make the top statistics file compact: a pixel keeps its sub-buffers only where "
                 "G-MoN would trim one (luminance or channel mode), else their mean, so G-MoN is "
                 "bit for bit the full file's (FORMAT.md, docs/compact.md)",
                 compactModifiers(), &cmdCompact, ""});
    t.push_back({"--plan", 0, "",
                 "Jung's error-rate planner: buffers M, windows and spp for fewer than one "
                 "overestimated pixel (docs/planner.md); needs no input",
                 planParams(), &cmdPlan, ""});
    appendReviewCommands(t);  // review_command.cpp: contact sheet, heatmaps, quality-vs-spp plot
    appendTradeCommands(t);   // trade_plot.cpp: the speed/accuracy trade
    t.push_back({"--dup", 0, "", "Duplicate the top of the stack", {}, &cmdDup, ""});
    t.push_back({"--pop", 0, "", "Remove the top of the stack", {}, &cmdPop, ""});
    t.push_back({"--swap", 0, "", "Exchange the top two stack entries", {}, &cmdSwap, ""});
    return t;
}

/// " (did you mean X?)" when a candidate is near `name`, else "".
std::string didYouMean(const std::string& name, const std::vector<std::string>& candidates) {
    const std::string n = nearestName(name, candidates);
    return n.empty() ? std::string() : format(" (did you mean {}?)", n);
}

/// The one check of a command's modifiers (core/params.h), defaults filled in, so that a command
/// reads every value from `mods`.
bool checkModifiers(const Command& c, Modifiers& mods, std::string& err) {
    return mcstat::checkModifiers(c.name, c.modifiers, mods, err);
}

const std::vector<Command>& table() {
    static const std::vector<Command> t = buildTable();
    return t;
}

/// One help line per parameter: ":name=default (what it accepts; help)"; text needs no "what".
std::string paramHelp(const ParamSpec& p) {
    if (p.type == ParamType::Text)
        return format("\n        :{}={} ({})", p.name, p.defaultValue, p.help);
    return format("\n        :{}={} ({}; {})", p.name, p.defaultValue, describeParam(p), p.help);
}

std::string modifierHelp(const Command& c) {
    std::string s;
    for (const ParamSpec& p : c.modifiers)
        if (!p.fixed) s += paramHelp(p);
    return s;
}

void printCommandHelp(const Command& c) {
    std::string head = c.name + (c.argHelp.empty() ? "" : " " + c.argHelp);
    std::printf("  %-16s %s%s\n", head.c_str(), c.help.c_str(), modifierHelp(c).c_str());
}

std::vector<std::string> commandNames() {
    std::vector<std::string> names;
    for (const Command& c : table()) names.push_back(c.name);
    return names;
}

/// The command a help topic names: "gmon", "--gmon", "--gmon:mode=channel"; null if none.
const Command* helpTopic(std::string topic) {
    topic = topic.substr(0, topic.find(':'));
    for (const Command& c : table())
        if (c.name == topic || c.name == "--" + topic || c.name == "-" + topic) return &c;
    return nullptr;
}

/// `--help` anywhere on the command line: the whole help, or one command's when it names one
/// (`--help gmon`, `--gmon --help`). Runs before any other argument, as oiiotool's does. Returns
/// -1 when the line asks for no help, else the exit status.
int helpRequest(int argc, const char* const* argv) {
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a != "--help" && a != "-h") continue;
        std::string topic;
        if (i + 1 < argc && argv[i + 1][0] != '\0') topic = argv[i + 1];
        if (!topic.empty() && !helpTopic(topic) && topic[0] != '-' &&
            topic.find('.') == std::string::npos && topic.find('/') == std::string::npos) {
            std::fprintf(stderr, "mcstat: --help %s: no such command%s (see mcstat --help)\n",
                         topic.c_str(), didYouMean("--" + topic, commandNames()).c_str());
            return 1;
        }
        if (!helpTopic(topic) && i > 1 && argv[i - 1][0] == '-') topic = argv[i - 1];
        if (const Command* c = helpTopic(topic)) {
            printCommandHelp(*c);
            return 0;
        }
        State st;
        std::string err;
        cmdHelp(st, a, {}, {}, err);
    }
    return -1;
}

bool cmdHelp(State&, const std::string&, const std::vector<std::string>&, const Modifiers&,
             std::string&) {
    std::printf(
        "mcstat %s: robust images from Monte Carlo statistics files (.%s)\n"
        "Usage: mcstat [FILE | COMMAND[:mod=value...] [ARGS]]...\n"
        "Arguments run left to right. A FILE pushes a statistics file or an image on the stack;\n"
        "commands replace the top of the stack; -o writes it.\n"
        "Example: mcstat scene.%s --gmon -o gmon.exr -o gmon.png --diff ref.exr\n\n"
        "Commands:\n",
        MCSTAT_VERSION, kStatsExtension, kStatsExtension);
    for (const Command& c : table()) printCommandHelp(c);
    std::exit(0);
}

/// Splits "--gmon:mode=channel:diag=1" into "--gmon" and {mode: channel, diag: 1}, the modifiers
/// by the one grammar of parameter text (core/params.h parseNamedParams: "-o:compression=dwaa:45"
/// gives {compression: dwaa:45}; a modifier given twice is refused).
bool splitModifiers(const std::string& arg, std::string& name, Modifiers& mods, std::string& err) {
    std::string problem;
    if (!parseNamedParams(arg, name, mods, problem)) {
        err = format("{}: modifier {}", name, problem);
        return false;
    }
    return true;
}

}  // namespace

void replaceWithImage(Item& top, const std::string& op, std::shared_ptr<OIIO::ImageBuf> img,
                      bool keepLayout) {
    Item out;
    out.name = format("{}({})", op, top.name);
    out.image = std::move(img);
    if (keepLayout)
        out.layout = top.isStats() ? std::make_shared<const StatsHeader>(top.header) : top.layout;
    top = std::move(out);
}

void describeOperationResult(const Item& top, const Operation& op, const ParamValues& values,
                             OIIO::ImageBuf& img) {
    const StatsHeader& h = top.isStats() ? top.header : *top.layout;
    std::string said;
    describeResult(img.specmod(), op, values, h, &said);
    if (!said.empty()) warning(format("{}: {}", top.name, said));
    if (!h.adaptiveM) {
        const int minM = smallestRobustM(op, values);
        if (minM > 1 && h.M < minM)
            warning(
                format("--{} over M = {} sub-buffers is the plain mean (it trims nothing "
                       "below M = {}); render or ingest at least {} seeds, or see mcstat "
                       "--plan for the M a target error needs",
                       op.name, h.M, minM, minM));
    }
    // Confidence intervals over too few buffers for their level are the buffers' range.
    // A compact file's pixels have all M buffers or their spread (the mean's t interval there).
    if (const int ciM = smallestIntervalM(op, values);
        ciM > 0 && ((h.adaptiveM && !h.compact) || h.M < ciM))
        warning(
            format("--{}:ci={}{}: the interval reaches its level only from {} valid "
                   "sub-buffers; below that it is their full range ([-inf, inf] for one), of "
                   "lower coverage (docs/confidence.md)",
                   op.name, values.at("ci").text,
                   h.adaptiveM && !h.compact ? " with adaptive M"
                                             : format(" over M = {} sub-buffers", h.M),
                   ciM));
    // Operations that do not carry AOVs yet say so rather than drop them silently.
    const int carried = img.nchannels();
    size_t missing = 0;
    for (const AovChannel& a : h.aovs)
        if (img.spec().channelindex(a.name) < 0) ++missing;
    if (missing > 0 && carried > 0)
        warning(
            format("--{} does not carry AOVs yet: {} of the file's {} AOV channels (alpha, "
                   "light groups, passes) are not in its result",
                   op.name, missing, h.aovs.size()));
}

namespace {
bool quietMode = false;
}

bool quiet() { return quietMode; }

// Every message is one line whatever an input put into it: oneLine() is the backstop behind the
// printable() each message gives the strings it quotes from a file (core/untrusted_text.h).
void warning(const std::string& text) {
    if (!quietMode) std::fprintf(stderr, "mcstat: warning: %s\n", oneLine(text).c_str());
}

bool imageSpace(const OIIO::ImageSpec& spec, const std::string& what, std::string& space,
                std::string& err) {
    std::string source, problem;
    if (!colorSpaceOf(spec, space, source, problem, what)) {
        err = what + ": " + problem;
        return false;
    }
    if (space.empty()) space = kSceneLinear;
    return true;
}

bool isImageFile(const Item& item) {
    return !item.isStats() && OIIO::Filesystem::is_regular(item.name);
}

bool itemSpace(const Item& item, std::string& space, std::string& err) {
    if (item.isStats()) {
        space = item.header.colorSpace;
        return true;
    }
    return imageSpace(item.image->spec(), item.name, space, err);
}

bool sameSpace(const std::string& cmd, const std::string& a, const std::string& spaceA,
               const std::string& b, const std::string& spaceB, std::string& err, bool aFile,
               bool bFile) {
    if (spaceA == spaceB) return true;
    // The conversion as stock oiiotool runs it without an OCIO config (whose built-in one knows
    // neither space): the matrix between the two, the image's tags set to its new space.
    const bool toA = bFile || !aFile;
    const std::string command = convertSpaceCommand(bFile   ? b
                                                    : aFile ? a
                                                            : std::string(),
                                                    toA ? spaceB : spaceA, toA ? spaceA : spaceB);
    std::string what;
    if (command.empty())
        what = "convert one to the other's space first (docs/color.md)";
    else if (bFile || aFile)
        what = format("convert {} to {} first: {}", bFile ? b : a, toA ? spaceA : spaceB, command);
    else
        what = format(
            "re-ingest one side's renders converted to the other's space, each with {} "
            "(docs/color.md)",
            command);
    err = format("{}: {} is in {} but {} is in {}: {}", cmd, a, printable(spaceA), b,
                 printable(spaceB), what);
    return false;
}

void noteDisplayRoute(const std::string& space) {
    static std::set<std::string> said;
    const std::string text = displayNote(space);
    if (!text.empty() && said.insert(text).second) note(text);
}

bool spaceLuma(const std::string& space, const std::string& what, std::array<double, 3>& luma,
               std::string& err) {
    std::string warn;
    if (!lumaCoefficients(space, luma, err, &warn)) {
        err = what + ": " + err;
        return false;
    }
    if (!warn.empty()) warning(warn);
    return true;
}

bool itemLuma(const Item& item, std::array<double, 3>& luma, std::string& err) {
    std::string space;
    return itemSpace(item, space, err) && spaceLuma(space, item.name, luma, err);
}

void note(const std::string& text) {
    if (!quietMode) std::fprintf(stderr, "mcstat: note: %s\n", oneLine(text).c_str());
}

bool showProgress() { return !quietMode && Progress::onTerminal(); }

int runOnce(const std::vector<std::string>& argv, const std::string& context) {
    State st;
    std::string err;
    const int argc = int(argv.size());
    // -v holds for the whole line wherever it stands, as -q does: "mcstat f --info -v" means it.
    st.verbose = std::find(argv.begin(), argv.end(), "-v") != argv.end();
    auto fail = [&](const std::string& message) {
        std::fprintf(stderr, "mcstat: %s\n", oneLine(context + message).c_str());
        return 1;
    };
    for (int i = 0; i < argc; ++i) {
        const std::string& arg = argv[size_t(i)];
        OIIO::Timer timer;
        bool ok = true;
        if (arg.size() > 1 && arg[0] == '-') {
            std::string name;
            Modifiers mods;
            if (!splitModifiers(arg, name, mods, err)) return fail(err);
            const Command* cmd = nullptr;
            for (const Command& c : table())
                if (c.name == name) cmd = &c;
            if (!cmd)
                return fail(format("unknown command '{}'{} (see mcstat --help)", name,
                                   didYouMean(name, commandNames())));
            const Modifiers given = mods;  // before the defaults are filled in
            if (!checkModifiers(*cmd, mods, err)) return fail(err);
            // removedradius and removedz only mean something with removed=1.
            if (mods.count("removed")) {
                const bool removed = modifierValue(cmd->modifiers, mods, "removed").integer != 0;
                if (std::string why = removedModifiersRefusal(name, removed, given); !why.empty())
                    return fail(why);
            }
            if (i + cmd->nargs > argc - 1)
                return fail(format("{} needs {} argument{} ({})", name, cmd->nargs,
                                   cmd->nargs > 1 ? "s" : "", cmd->argHelp));
            std::vector<std::string> args(argv.begin() + i + 1, argv.begin() + i + 1 + cmd->nargs);
            i += cmd->nargs;
            ok = cmd->run(st, name, args, mods, err);
            if (ok && st.verbose && name != "-v")
                std::fprintf(stderr, "mcstat: %s done in %.3f s\n", oneLine(arg).c_str(), timer());
        } else {
            ok = pushFile(st, arg, err);
            if (ok && st.verbose)
                std::fprintf(stderr, "mcstat: read %s in %.3f s\n", oneLine(arg).c_str(), timer());
        }
        if (!ok) return fail(err);
    }
    return st.exitStatus;
}

int run(int argc, const char* const* argv) {
    if (argc < 2) {
        // 1 as for every other error: 2 is --compare's DIFFERENT, and means only that.
        std::fprintf(stderr, "mcstat: no arguments; try 'mcstat --help'\n");
        return 1;
    }
    if (const int help = helpRequest(argc, argv); help >= 0) return help;
    std::vector<std::string> args(argv + 1, argv + argc);
    std::string context;
    if (args.size() >= 2 && args[0] == kFrameContextArg) {  // one frame of --parallel-frames
        context = format("frame {}: ", args[1]);
        args.erase(args.begin(), args.begin() + 2);
    }
    // -q holds for the whole line wherever it stands (frames run as processes inherit it: it
    // stays among their arguments, where its command does nothing).
    quietMode = std::find(args.begin(), args.end(), "-q") != args.end();
    // A frame pattern in a file name (or --frames): the command line once per frame.
    if (context.empty() && hasFramePattern(args)) return runFrames(args);
    return runOnce(args, context);
}

}  // namespace mcstat::cli
