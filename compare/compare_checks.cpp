// What a comparison refuses before it reads a pixel (compare_checks.h): options out of range, a
// reference variance that does not fit, sides without a variance, AOVs of a compact file.
#include "compare_checks.h"

#include <fmt/format.h>

#include <cmath>

namespace mcstat::detail {

bool checkOptions(const CompareOptions& opt, std::string& err) {
    if (!(opt.level > 0.0 && opt.level < 1.0)) {
        err = fmt::format("level {} is not in (0, 1)", opt.level);
        return false;
    }
    if (!(opt.trim >= 0.0 && opt.trim < 0.5)) {
        err = fmt::format("trim {} is not in [0, 0.5)", opt.trim);
        return false;
    }
    if (!(opt.tol >= 0.0) || !(opt.reltol >= 0.0) || !std::isfinite(opt.tol) ||
        !std::isfinite(opt.reltol)) {
        err = "tolerances must be finite and >= 0";
        return false;
    }
    if (opt.test == TwoSampleTest::Equivalence && opt.tol == 0.0 && opt.reltol == 0.0) {
        err =
            "an equivalence test needs a tolerance (tol or reltol > 0): no data shows that two "
            "renders agree exactly";
        return false;
    }
    if (opt.tile < 0 || opt.tile > 4096) {
        err = fmt::format("tile {} is not in 0..4096", opt.tile);
        return false;
    }
    if (!(opt.referenceSpp >= 0.0) || !std::isfinite(opt.referenceSpp)) {
        err = "the reference's samples per pixel must be finite and >= 0";
        return false;
    }
    return true;
}

/// The reference's variance image (Mitsuba 3's `_var.exr`) and the rule against what they need.
bool checkReferenceVariance(const OIIO::ImageBuf* var, const OIIO::ImageBuf& ref,
                            const std::string& refName, const CompareOptions& opt,
                            std::string& err) {
    const bool mitsuba = opt.rule == CompareOptions::Rule::Mitsuba;
    if (!var) {
        if (mitsuba)
            err = fmt::format(
                "rule=mitsuba tests against the reference's per-sample variance: give "
                "refvar=VAR.exr with {}",
                refName);
        return !mitsuba;
    }
    if (var->nchannels() < 3 || var->roi().width() != ref.roi().width() ||
        var->roi().height() != ref.roi().height()) {
        err = fmt::format("{}'s variance image is {}x{} with {} channels; {} is {}x{} (R, G, B)",
                          refName, var->roi().width(), var->roi().height(), var->nchannels(),
                          refName, ref.roi().width(), ref.roi().height());
        return false;
    }
    if (!(opt.referenceSpp > 1.0) && !mitsuba) {
        err = fmt::format(
            "refvar gives {}'s per-sample variance: refspp=K (its samples per pixel, > 1) "
            "turns it into the variance of its mean",
            refName);
        return false;
    }
    if (mitsuba && (opt.trimmed || opt.test == TwoSampleTest::Equivalence || opt.tol > 0.0 ||
                    opt.reltol > 0.0)) {
        err = "rule=mitsuba is Mitsuba 3's z-test: no test=yuen, equivalence, tol or reltol";
        return false;
    }
    return true;
}

/// The result's data window (the statistics file's) and its tile side. A tile averages a buffer
/// index over its pixels; with adaptive M (compact files too) the indices do not line up, and the
/// tile is summed from its pixels' estimates and variances instead (PixelSums).
void setWindow(CompareResult& out, const StatsHeader& h, bool adaptive, const CompareOptions& opt) {
    out.width = h.width;
    out.height = h.height;
    out.originX = h.originX;
    out.originY = h.originY;
    out.adaptive = adaptive;
    out.tile = opt.tile;
}

/// The M a side's buffers give, or an error when they give no variance.
bool sideBuffers(const StatsBlockSource& s, int& M, std::string& err) {
    const StatsHeader& h = s.header();
    M = h.M;
    if (h.M < 2) {
        err = fmt::format(
            "{} has M = {} sub-buffer{}: no variance to test against (render with "
            "--M 2 or more, or ingest two or more seeds)",
            s.name(), h.M, h.M == 1 ? "" : "s");
        return false;
    }
    return true;
}

/// AOVs of a compact file: a pixel that keeps its mean alone keeps no spread of its AOVs.
bool compactQuantities(const StatsBlockSource& s, const CompareOptions& opt, std::string& err) {
    if (!s.header().compact || opt.aovs.empty()) return true;
    err = fmt::format(
        "{} is a compact file: its pixels without heavy tails keep the spread of R, G and B, not "
        "of the AOVs, so aovs= cannot be tested there; compare the full files",
        s.name());
    return false;
}

}  // namespace mcstat::detail
