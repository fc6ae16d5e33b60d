// `--compare`: are the top two renders on the stack the same image, up to their Monte Carlo noise?
// Two statistics files: two-sample tests on their sub-buffers; a statistics file and an image: a
// one-sample test against the image as the reference (docs/compare.md). The verdict and its
// evidence go to stdout, the maps replace the two items, and the process exits 2 when they differ
// (idiff's FAILURE) once every command has run.
#include "mcstat/compare/compare.h"

#include <OpenImageIO/strutil.h>

#include <chrono>
#include <cstdio>

#include "cli.h"
#include "mcstat/color.h"
#include "mcstat/compare/compare_report.h"
#include "mcstat/core/progress.h"
#include "mcstat/image/render_layout.h"

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
    const auto it = mods.find("refvar");
    given = it != mods.end() && !it->second.empty();
    if (!given) return true;
    if (!readRGB(it->second, "", var, err)) {
        err = format("{}: refvar: {}", cmd, err);
        return false;
    }
    return true;
}

}  // namespace

bool cmdCompare(State& st, const std::string& cmd, const std::vector<std::string>&,
                const Modifiers& mods, std::string& err) {
    if (st.stack.size() < 2) {
        err = format(
            "{} compares the top two items of the stack (statistics files, or one and a "
            "reference image); there {} {}",
            cmd, st.stack.size() == 1 ? "is" : "are", st.stack.size());
        return false;
    }
    Item& a = st.stack[st.stack.size() - 2];
    Item& b = st.stack.back();
    if (!a.isStats() && !b.isStats()) {
        err = format(
            "{}: {} and {} are images: a noise-aware comparison needs the sub-buffers of "
            "at least one statistics file (for two images use --diff)",
            cmd, a.name, b.name);
        return false;
    }
    // One luminance, one meaning of R, G, B: the two sides must be in the same working space.
    std::string spaceA, spaceB;
    if (!itemSpace(a, spaceA, err) || !itemSpace(b, spaceB, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    if (!sameSpace(cmd, a.name, spaceA, b.name, spaceB, err, isImageFile(a), isImageFile(b)))
        return false;
    CompareOptions opt;
    if (!itemLuma(a, opt.luma, err)) {
        err = format("{}: {}", cmd, err);
        return false;
    }
    opt.nthreads = st.nthreads;
    if (!parseCompareOptions(mods, opt, err, cmd)) return false;
    CompareReportRequest report = compareReportRequest(mods);
    report.a = reportSide(a);
    report.b = reportSide(b);
    opt.keepMeans = report.needsMeans();
    const auto refspp = mods.find("refspp");
    const auto refvar = mods.find("refvar");
    if (a.isStats() && b.isStats() &&
        ((refspp != mods.end() && refspp->second != "0") ||
         (refvar != mods.end() && !refvar->second.empty()))) {
        err = format("{}: {} is for an image reference; {} and {} are statistics files", cmd,
                     refspp != mods.end() && refspp->second != "0" ? "refspp" : "refvar", a.name,
                     b.name);
        return false;
    }
    const auto start = std::chrono::steady_clock::now();
    Progress progress("compare", 1000, showProgress());
    opt.progress = progress.fractionCallback();
    CompareResult r;
    bool ok = false;
    std::string what;
    if (a.isStats() && b.isStats()) {
        ItemSource sa, sb;
        if (!openSource(st, a, sa, err) || !openSource(st, b, sb, err)) return false;
        ok = compareStats(*sa.root, *sb.root, opt, r, err);
        what = format("{} vs {}", a.name, b.name);
    } else {
        // One statistics file and a reference image, in either order: the image is the reference.
        Item& stats = a.isStats() ? a : b;
        Item& image = a.isStats() ? b : a;
        OIIO::ImageBuf rgb;
        const auto layer = mods.find("layer");
        if (!selectRGB(*image.image, layer == mods.end() ? std::string() : layer->second,
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
    if (!ok) {
        err = format("{}: {}", cmd, err);
        return false;
    }
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

    auto maps = std::make_shared<OIIO::ImageBuf>(std::move(r.maps));
    OIIO::ImageSpec& spec = maps->specmod();
    spec.attribute(std::string(kProvenancePrefix) + "compare.verdict", verdict);
    spec.attribute(std::string(kProvenancePrefix) + "compare.fail", r.fail ? 1 : 0);
    spec.attribute(std::string(kProvenancePrefix) + "compare.a", a.name);
    spec.attribute(std::string(kProvenancePrefix) + "compare.b", b.name);
    // The working space whose luminance and R, G, B were tested (the maps are data, not colour:
    // no chromaticities).
    spec.attribute("mcstat:colorSpace", spaceA);
    for (const ParamSpec& p : compareModifiers())
        if (mods.count(p.name))
            spec.attribute(std::string(kProvenancePrefix) + "compare." + p.name, mods.at(p.name));
    Item out;
    out.name = format("compare({}, {})", a.name, b.name);
    out.image = std::move(maps);
    st.stack.pop_back();
    st.stack.back() = std::move(out);
    return true;
}

}  // namespace mcstat::cli
