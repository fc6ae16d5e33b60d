// `--compare`: are the top two renders on the stack the same image, up to their Monte Carlo noise?
// Two statistics files: two-sample tests on their sub-buffers; a statistics file and an image: a
// one-sample test against the image as the reference (docs/compare.md). The verdict and its
// evidence go to stdout, the maps replace the two items, and the process exits 2 when they differ
// (idiff's FAILURE) once every command has run.
#include <OpenImageIO/strutil.h>

#include <chrono>
#include <cstdio>

#include "cli.h"
#include "mcstat/color/color.h"
#include "mcstat/compare/compare.h"
#include "mcstat/compare/report/compare_report.h"
#include "mcstat/core/progress.h"
#include "mcstat/image/spec/render_layout.h"

namespace mcstat::cli {

using OIIO::Strutil::fmt::format;

const std::vector<ParamSpec>& compareModifiers() { return compareParams(); }

namespace {

/// An item as the reports name it: its name and the files it was read from.
CompareReportSide reportSide(const Item& item) {
    CompareReportSide s;
    s.name = item.name;
    s.files = item.files;
    if (s.files.empty() && !item.path.empty()) s.files.push_back(item.path);
    return s;
}

/// The reference's variance image (refvar=), read as its R, G, B; none when not asked for.
bool readReferenceVariance(const Modifiers& mods, const std::string& cmd, OIIO::ImageBuf& var,
                           bool& given, std::string& err) {
    const std::string path = modifierValue(compareModifiers(), mods, "refvar").text;
    given = !path.empty();
    if (!given) return true;
    if (!readRGB(path, "", var, err)) {
        err = format("{}: refvar: {}", cmd, err);
        return false;
    }
    return true;
}

/// The two sides of `cmd` (the top two items) checked: at least one statistics file, the same
/// working space (its name in `space`, its luminance in opt.luma).
bool checkSides(const State& st, const std::string& cmd, std::string& space, CompareOptions& opt,
                std::string& err) {
    if (st.stack.size() < 2) {
        err = format(
            "{} compares the top two items of the stack (statistics files, or one and a "
            "reference image); there {} {}",
            cmd, st.stack.size() == 1 ? "is" : "are", st.stack.size());
        return false;
    }
    const Item& a = st.stack[st.stack.size() - 2];
    const Item& b = st.stack.back();
    if (!a.isStats() && !b.isStats()) {
        err = format(
            "{}: {} and {} are images: a noise-aware comparison needs the sub-buffers of "
            "at least one statistics file (for two images use --diff)",
            cmd, a.name, b.name);
        return false;
    }
    // One luminance, one meaning of R, G, B: the two sides must be in the same working space.
    std::string spaceB;
    if (!itemSpace(a, space, err) || !itemSpace(b, spaceB, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    if (!sameSpace(cmd, a.name, space, b.name, spaceB, err, isImageFile(a), isImageFile(b)))
        return false;
    if (!itemLuma(a, opt.luma, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    return true;
}

/// The comparison itself: two statistics files, or one and a reference image in either order
/// (the image is the reference), `progress` finished once it ran. `what` names the pair for the
/// verdict line.
bool runComparison(State& st, const std::string& cmd, const Modifiers& mods,
                   const CompareOptions& opt, Progress& progress, CompareResult& r,
                   std::string& what, std::string& err) {
    Item& a = st.stack[st.stack.size() - 2];
    Item& b = st.stack.back();
    bool ok = false;
    if (a.isStats() && b.isStats()) {
        ItemSource sa, sb;
        if (!openSource(st, a, sa, err) || !openSource(st, b, sb, err)) return false;
        ok = compareStats(*sa.root, *sb.root, opt, r, err);
        what = format("{} vs {}", a.name, b.name);
    } else {
        Item& stats = a.isStats() ? a : b;
        Item& image = a.isStats() ? b : a;
        OIIO::ImageBuf rgb;
        if (!selectRGB(*image.image, modifierValue(compareModifiers(), mods, "layer").text,
                       image.name, rgb, err)) {
            err = format("{}: {}", cmd, err);
            return false;
        }
        OIIO::ImageBuf var;
        bool hasVar = false;
        if (!readReferenceVariance(mods, cmd, var, hasVar, err)) return false;
        ItemSource src;
        if (!openSource(st, stats, src, err)) return false;
        ok = compareStatsToImage(rgb, image.name, *src.root, opt, r, err, hasVar ? &var : nullptr);
        what = format("{} vs reference {}", stats.name, image.name);
    }
    progress.finish();
    if (!ok) err = format("{}: {}", cmd, err);
    return ok;
}

/// Replaces the two compared items by the maps, with the verdict, the pair, the working space
/// and every modifier given as provenance.
void replaceWithMaps(State& st, CompareResult& r, const std::string& verdict,
                     const std::string& space, const Modifiers& mods) {
    const Item& a = st.stack[st.stack.size() - 2];
    const Item& b = st.stack.back();
    auto maps = std::make_shared<OIIO::ImageBuf>(std::move(r.maps));
    OIIO::ImageSpec& spec = maps->specmod();
    spec.attribute(std::string(kProvenancePrefix) + "compare.verdict", verdict);
    spec.attribute(std::string(kProvenancePrefix) + "compare.fail", r.fail ? 1 : 0);
    spec.attribute(std::string(kProvenancePrefix) + "compare.a", a.name);
    spec.attribute(std::string(kProvenancePrefix) + "compare.b", b.name);
    // The working space whose luminance and R, G, B were tested (the maps are data, not colour:
    // no chromaticities).
    spec.attribute("mcstat:colorSpace", space);
    for (const ParamSpec& p : compareModifiers())
        if (mods.count(p.name))
            spec.attribute(std::string(kProvenancePrefix) + "compare." + p.name, mods.at(p.name));
    Item out;
    out.name = format("compare({}, {})", a.name, b.name);
    out.image = std::move(maps);
    st.stack.pop_back();
    st.stack.back() = std::move(out);
}

}  // namespace

bool cmdCompare(State& st, const std::string& cmd, const std::vector<std::string>&,
                const Modifiers& mods, std::string& err) {
    CompareOptions opt;
    std::string space;
    if (!checkSides(st, cmd, space, opt, err)) return false;
    const Item& a = st.stack[st.stack.size() - 2];
    const Item& b = st.stack.back();
    opt.nthreads = st.nthreads;
    if (!parseCompareOptions(mods, opt, err, cmd)) return false;
    CompareReportRequest report = compareReportRequest(mods);
    report.a = reportSide(a);
    report.b = reportSide(b);
    opt.keepMeans = report.needsMeans();
    const bool refspp = modifierValue(compareModifiers(), mods, "refspp").real != 0.0;
    const bool refvar = !modifierValue(compareModifiers(), mods, "refvar").text.empty();
    if (a.isStats() && b.isStats() && (refspp || refvar)) {
        err = format("{}: {} is for an image reference; {} and {} are statistics files", cmd,
                     refspp ? "refspp" : "refvar", a.name, b.name);
        return false;
    }
    const auto start = std::chrono::steady_clock::now();
    Progress progress("compare", 1000, showProgress());
    opt.progress = progress.fractionCallback();
    CompareResult r;
    std::string what;
    if (!runComparison(st, cmd, mods, opt, progress, r, what, err)) return false;
    const std::string verdict = compareVerdict(r, opt);
    // Each line stays one line whatever the inputs are named (core/untrusted_text.h).
    std::printf("%s: %s\n", oneLine(what).c_str(), oneLine(verdict).c_str());
    for (const std::string& line : compareEvidence(r, opt))
        std::printf("  %s\n", oneLine(line).c_str());
    std::fflush(stdout);
    if (r.fail) st.exitStatus = 2;
    report.seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (report.any() && !writeCompareReports(r, opt, report, err, st.nthreads)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    replaceWithMaps(st, r, verdict, space, mods);
    return true;
}

}  // namespace mcstat::cli
