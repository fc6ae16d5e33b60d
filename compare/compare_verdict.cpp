// The comparison's verdict and evidence in words (compareVerdict, comparePowerText,
// compareEvidence; compare.h, docs/compare.md).
#include <fmt/format.h>

#include <cmath>

#include "mcstat/compare/compare.h"
#include "mcstat/core/untrusted_text.h"

namespace mcstat {

namespace {

std::string percentText(double v) { return fmt::format("{:g}%", v * 100.0); }

std::string controlText(const CompareOptions& opt) {
    if (opt.test == TwoSampleTest::Equivalence)
        return fmt::format("each at level {}", percentText(opt.level));
    switch (opt.control) {
        case Multiplicity::FDR:
            return fmt::format("false discovery rate {}", percentText(opt.level));
        case Multiplicity::FWER:
            return fmt::format("family-wise error rate {} (Holm)", percentText(opt.level));
        case Multiplicity::None:
            return fmt::format("each at level {}, uncorrected", percentText(opt.level));
    }
    return "";
}

std::string testText(const CompareResult& r, const CompareOptions& opt) {
    const std::string t = opt.trimmed
                              ? fmt::format("Yuen's trimmed t ({} per end)", percentText(opt.trim))
                              : std::string("Welch's t");
    const char* M = r.adaptive ? "M_max" : "M";
    const std::string m = r.oneSample
                              ? fmt::format("{} = {} sub-buffers against the reference", M, r.Mb)
                              : fmt::format("{} = {} + {} sub-buffers", M, r.Ma, r.Mb);
    return fmt::format("{} on {}", t, m);
}

std::string toleranceText(const CompareOptions& opt) {
    if (opt.tol == 0.0 && opt.reltol == 0.0) return "";
    std::string s = " within ";
    if (opt.reltol > 0.0) s += percentText(opt.reltol);
    if (opt.reltol > 0.0 && opt.tol > 0.0) s += " or ";
    if (opt.tol > 0.0) s += fmt::format("{:g}", opt.tol);
    return s;
}

/// The quantities tested (luminance, R, G, B, AOV names from the files: printable()).
std::string quantitiesText(const CompareResult& r) {
    std::vector<std::string> shown;
    for (size_t i = 0; i < r.quantities.size() && i < 3; ++i)
        shown.push_back(printable(r.quantities[i]));
    if (r.quantities.size() <= 3) return fmt::format("{}", fmt::join(shown, ", "));
    return fmt::format("{} and {} more", fmt::join(shown, ", "), r.quantities.size() - 3);
}

std::string findingText(const CompareFinding& f, const CompareResult& r,
                        const CompareOptions& opt) {
    const double rel = f.a != 0.0 ? f.result.difference / std::fabs(f.a) : 0.0;
    std::string where = f.tile ? fmt::format("tile {}x{} at ({}, {})", r.tile, r.tile, f.x, f.y)
                               : fmt::format("pixel ({}, {})", f.x, f.y);
    // No standard error: against an image, only the statistics file's buffers measure noise, and
    // :refspp= scales that measure, so a noiseless file leaves the reference noiseless too.
    const char* exact = !r.oneSample ? "exact (no noise on either side)"
                        : opt.referenceSpp > 0.0
                            ? "exact (no noise in the statistics file here, so none in the "
                              "reference either: refspp scales the file's own)"
                            : "exact (no noise in the statistics file here, and the reference is "
                              "taken as exact; :refspp= gives it noise)";
    std::string size = std::isfinite(f.result.z)
                           ? fmt::format("{:+.2f} standard errors", f.result.z)
                           : std::string(exact);
    return fmt::format("{} {}: {:.6g} -> {:.6g} ({:+.4g}{}, {}), p = {:.3g}", where,
                       printable(f.quantity), f.a, f.b, f.result.difference,
                       f.a != 0.0 ? fmt::format(", {:+.2f}%", rel * 100.0) : std::string(), size,
                       f.result.p);
}

}  // namespace

/// Mitsuba 3's verdict: a few failing channel tests pass (its pass fraction).
std::string mitsubaVerdict(const CompareResult& r, const CompareOptions& opt) {
    const std::string how = fmt::format(
        "Mitsuba 3's rule: z-tests against the reference's variance floored at {:g}, "
        "Sidak-corrected level {:.3g} ({} over {} pixels), {} of the channel tests must pass",
        opt.varianceFloor, r.threshold, percentText(opt.level), r.pixels,
        percentText(opt.passFraction));
    const size_t failed = r.channelTests - r.channelTestsPassed;
    if (r.identical) return fmt::format("IDENTICAL: every pixel equals the reference ({})", how);
    if (r.fail)
        return fmt::format(
            "DIFFERENT: {} of {} pixels differ in {}: {} of {} channel tests failed ({})",
            r.pixelsRejected, r.pixels, quantitiesText(r), failed, r.channelTests, how);
    return fmt::format(
        "SAME: {} of {} pixels differ in {}, {} of {} channel tests failed: within "
        "what the rule allows ({})",
        r.pixelsRejected, r.pixels, quantitiesText(r), failed, r.channelTests, how);
}

namespace {

/// A relative change as a percentage with 2 significant digits (3.1 %, 42 %, 0.051 %).
std::string changeText(double v) { return fmt::format("{:.2g} %", v * 100.0); }

/// What a difference test could have seen, in words (CompareResult::power).
std::string powerText(const CompareResult& r) {
    const ComparePower& w = r.power;
    std::vector<std::string> parts;
    if (std::isfinite(w.tileRelative))
        parts.push_back(fmt::format("{} in one tile", changeText(w.tileRelative)));
    if (std::isfinite(w.pixelRelative))
        parts.push_back(fmt::format("{} in one pixel", changeText(w.pixelRelative)));
    if (parts.empty()) return "its power is unknown: no hypothesis it tested has noise and a value";
    return fmt::format("it finds a change of {} with probability {:g} (medians)",
                       fmt::join(parts, " or "), kComparePower);
}

}  // namespace

std::string comparePowerText(const CompareResult& r, const CompareOptions& opt) {
    if (opt.rule == CompareOptions::Rule::Mitsuba || opt.test == TwoSampleTest::Equivalence ||
        r.identical)
        return "";
    return powerText(r);
}

std::string compareVerdict(const CompareResult& r, const CompareOptions& opt) {
    if (opt.rule == CompareOptions::Rule::Mitsuba) return mitsubaVerdict(r, opt);
    const std::string how = fmt::format("{}, {}", testText(r, opt), controlText(opt));
    if (r.identical)
        return fmt::format(
            "IDENTICAL: every pixel's {} is the same on both sides (two copies of "
            "one render test nothing{}; {})",
            quantitiesText(r),
            opt.identicalFails ? ", and identical=fail makes that a failure" : "", how);
    if (r.underpowered)
        return fmt::format(
            "UNDERPOWERED: no pixel{} differs in {} beyond the noise, but {}, above "
            "minpower={:g} ({})",
            r.tile > 0 ? " or tile" : "", quantitiesText(r), powerText(r), opt.minPower, how);
    const std::string tiles =
        r.tile > 0 ? fmt::format(" and {} of {} tiles", r.tilesRejected, r.tilesTested) : "";
    if (opt.test == TwoSampleTest::Equivalence) {
        if (!r.fail)
            return fmt::format("EQUIVALENT{}: every {} agrees in {} ({})", toleranceText(opt),
                               r.tile > 0 ? "tile" : "pixel", quantitiesText(r), how);
        return fmt::format("NOT SHOWN EQUIVALENT{}: {} of {} {} not shown to agree in {} ({})",
                           toleranceText(opt), r.tile > 0 ? r.tilesRejected : r.pixelsRejected,
                           r.tile > 0 ? r.tilesTested : r.pixelsTested,
                           r.tile > 0 ? "tiles" : "pixels", quantitiesText(r), how);
    }
    if (r.fail)
        return fmt::format("DIFFERENT: {} of {} pixels{} differ{} in {} ({})", r.pixelsRejected,
                           r.pixelsTested, tiles,
                           opt.tol > 0 || opt.reltol > 0
                               ? " by more than" + toleranceText(opt).substr(7)
                               : std::string(),
                           quantitiesText(r), how);
    return fmt::format(
        "SAME: no pixel{} differs{} in {} beyond the noise; {} ({})", r.tile > 0 ? " or tile" : "",
        opt.tol > 0 || opt.reltol > 0 ? " by more than" + toleranceText(opt).substr(7)
                                      : std::string(),
        quantitiesText(r), powerText(r), how);
}

std::vector<std::string> compareEvidence(const CompareResult& r, const CompareOptions& opt) {
    std::vector<std::string> lines;
    const bool equivalence = opt.test == TwoSampleTest::Equivalence;
    lines.push_back(fmt::format(
        "pixels: {} tested of {}, {} {}{}", r.pixelsTested, r.pixels, r.pixelsRejected,
        equivalence ? "not shown equivalent" : "differ",
        r.tile > 0
            ? fmt::format("; tiles {}x{}: {} tested of {}, {} {}", r.tile, r.tile, r.tilesTested,
                          r.tiles, r.tilesRejected, equivalence ? "not shown equivalent" : "differ")
            : std::string("; no tile tests")));
    auto thr = [](double t) { return t < 0 ? std::string("none") : fmt::format("{:.3g}", t); };
    if (opt.rule == CompareOptions::Rule::Mitsuba)
        lines.push_back(fmt::format(
            "tested: {} channel tests at level {:.3g}; {} passed ({:.4g}%, {} needed)",
            r.channelTests, r.threshold, r.channelTestsPassed,
            r.channelTests ? 100.0 * double(r.channelTestsPassed) / double(r.channelTests) : 0.0,
            percentText(opt.passFraction)));
    else
        lines.push_back(fmt::format(
            "tested: {} hypotheses; largest p-value rejected: pixels {}{}", r.hypotheses,
            thr(r.threshold), r.tile > 0 ? ", tiles " + thr(r.tileThreshold) : std::string()));
    if (opt.rule == CompareOptions::Rule::Mcstat && !equivalence) {
        const ComparePower& w = r.power;
        auto one = [](double rel, double abs, const char* what) {
            return std::isfinite(abs)
                       ? fmt::format("{} ({:.4g} in the image's units) in one {}",
                                     std::isfinite(rel) ? changeText(rel) : std::string("?"), abs,
                                     what)
                       : std::string();
        };
        std::vector<std::string> parts;
        for (const std::string& t : {one(w.tileRelative, w.tileAbsolute, "tile"),
                                     one(w.pixelRelative, w.pixelAbsolute, "pixel")})
            if (!t.empty()) parts.push_back(t);
        lines.push_back(
            parts.empty()
                ? std::string("power: unknown (no tested hypothesis has noise)")
                : fmt::format("power: a change of {} is found with probability {:g} at this "
                              "level (medians over the tested hypotheses with noise){}",
                              fmt::join(parts, ", "), kComparePower,
                              opt.minPower > 0.0
                                  ? fmt::format("; minpower={:g} asks for {} per {}", opt.minPower,
                                                changeText(opt.minPower),
                                                std::isfinite(w.tileRelative) ? "tile" : "pixel")
                                  : std::string()));
    }
    const char* label = equivalence ? "least equivalent" : (r.fail ? "strongest" : "largest |z|");
    if (r.strongest.valid)
        lines.push_back(fmt::format("{}: {}", label, findingText(r.strongest, r, opt)));
    if (r.strongestTile.valid)
        lines.push_back(fmt::format("{} tile: {}", label, findingText(r.strongestTile, r, opt)));
    if (r.nonFiniteOneSide > 0)
        lines.push_back(
            fmt::format("{} pixels hold NaN or Inf on one side only (counted as "
                        "differing)",
                        r.nonFiniteOneSide));
    if (r.nonFiniteBoth > 0)
        lines.push_back(
            fmt::format("{} pixels hold NaN or Inf on both sides (not tested)", r.nonFiniteBoth));
    if (r.constantEqual > 0)
        lines.push_back(
            fmt::format("{} pixel tests had no noise and no difference (e.g. black "
                        "background)",
                        r.constantEqual));
    if (r.oneSample && !equivalence && r.rejectedNoisy >= 10 &&
        r.rejectedDarker * 10 >= r.rejectedNoisy * 9)
        lines.push_back(fmt::format(
            "warning: {} of the {} noisy pixels that differ are darker than the reference: the "
            "signature of rare paths (fireflies, caustics) this render has not seen yet, not of a "
            "change; compare against a statistics file of the reference instead (docs/compare.md)",
            r.rejectedDarker, r.rejectedNoisy));
    // Measured (docs/compare.md): 29 of 200 same-scene splits 10 + 11 of Cycles renders alarmed at
    // level 1 %, none of 200 at 21 + 21, none of 40 fixture pairs at 16 + 16.
    if (opt.trimmed && std::min(r.Ma, r.Mb) < 16)
        lines.push_back(fmt::format(
            "warning: Yuen's test on fewer than 16 buffers a side (here {}) can find no spread "
            "where the few kept buffer values cluster: on Cycles renders it alarmed in 14.5 % of "
            "10 + 11 splits of one scene at level 1 % (docs/compare.md); prefer test=welch or "
            "more seeds",
            std::min(r.Ma, r.Mb)));
    if (r.fewBuffers > 0)
        lines.push_back(
            fmt::format("{} pixels not tested: fewer than two non-empty buffers on a "
                        "side ({})",
                        r.fewBuffers,
                        r.adaptive ? "adaptive M gives smooth pixels one buffer"
                                   : "fewer samples than buffers"));
    if (r.tile > 0 && r.adaptive)
        lines.push_back(fmt::format(
            "tiles tested from their pixels' means and variances, pixels' noise taken as "
            "independent{} (a side has adaptive M or is a compact file: buffer indices differ "
            "from pixel to pixel)",
            opt.trimmed ? ", with Welch's t on both sides" : ""));
    return lines;
}

}  // namespace mcstat
