// The confidence-interval modifiers of an estimator with intervals (ci, ciaovs, citarget, cipool;
// docs/confidence.md): declared, taken out of a command's modifiers, bound to a kernel, and what
// they add (intervalChannels, smallestIntervalM; imageops.h).
#include "mcstat/image/imageops.h"

namespace mcstat {

namespace {

/// citarget=expected's neighbourhood radius unless cipool says otherwise: 9 x 9 pixels held the
/// reference in 93-94 % of pixel channels of the fixture's firefly scenes (docs/confidence.md).
constexpr int kDefaultCiPool = 4;

}  // namespace

bool hasIntervals(const Operation& op) {
    if (op.input != InputKind::BufferMeans) return false;
    ParamValues defaults;
    std::string err;
    if (!parseOperationParams(op, {}, defaults, err)) return false;
    return bool(op.bindPixel(defaults, {0.0, 0.0, 0.0}).interval);
}

std::vector<ParamSpec> confidenceModifiers() {
    // The one declaration of the level: open at both ends (0 and 1 are no intervals).
    ParamSpec level = realParam("ci", 0.0, 1.0, true, "",
                                "LEVEL in (0, 1): append layers ci_low, ci_high (R, G, B), a "
                                "confidence interval per pixel from its sub-buffers, of the "
                                "estimator's target (the file's mcstat:ciTarget): the mean's "
                                "covers the expected value, MoN's, G-MoN's and G-MoN_b's the "
                                "median of the buffer means, TMPE's the trimmed mean "
                                "(docs/confidence.md)");
    level.maxOpen = true;
    return {level, flagParam("ciaovs", "", "1 (with ci): intervals for every AOV too"),
            enumParam("citarget", {"estimator", "expected"}, "",
                      "with ci: the interval's target: estimator (what the estimator estimates, "
                      "the default) "
                      "or expected (the pixel's expected value, its true value: Student's t "
                      "about the mean, the variance pooled over neighbours)"),
            intParam("cipool", 0, 32, "",
                     "with citarget=expected: radius of the neighbourhood whose mean per-sample "
                     "variance the interval takes where it is larger than the pixel's own (0: "
                     "the pixel alone; default " +
                         std::to_string(kDefaultCiPool) + ": 9 x 9)")};
}

bool takeConfidenceModifiers(const std::string& context, std::map<std::string, std::string>& mods,
                             ParamValues& out, std::string& err) {
    ParamValues given;
    if (!takeModifiers(context, confidenceModifiers(), mods, given, err)) return false;
    // Only what asks for layers goes on: a result without them keeps the parameters it had.
    const bool aovs = given.count("ciaovs") && given.at("ciaovs").integer != 0;
    const bool expected = given.count("citarget") && given.at("citarget").text == "expected";
    if (!given.count("ci")) {
        for (const char* k : {"ciaovs", "citarget", "cipool"})
            if (given.count(k)) {
                err = context + ": " + k + "=" + given.at(k).text + " needs ci=LEVEL";
                return false;
            }
        return true;
    }
    if (given.count("cipool") && !expected) {
        err = context + ": cipool=" + given.at("cipool").text + " needs citarget=expected";
        return false;
    }
    if (aovs && expected) {
        err = context +
              ": ciaovs=1 with citarget=expected: the AOVs' expected-value intervals are not "
              "offered (their pooled variances are not computed); use citarget=estimator for "
              "AOV intervals";
        return false;
    }
    out["ci"] = given.at("ci");
    if (aovs) out["ciaovs"] = given.at("ciaovs");
    if (expected) {
        out["citarget"] = given.at("citarget");
        if (given.count("cipool")) {
            out["cipool"] = given.at("cipool");
        } else {  // its default (no default in the spec: given only with citarget=expected)
            for (const ParamSpec& p : confidenceModifiers())
                if (p.name == "cipool" &&
                    !parseParamValue(context, p, std::to_string(kDefaultCiPool), out["cipool"],
                                     err))
                    return false;
        }
    }
    return true;
}

void bindConfidence(PixelKernel& kernel, const ParamValues& values) {
    const auto level = values.find("ci");
    kernel.ciLevel = level == values.end() || !kernel.interval ? 0.0 : level->second.real;
    const auto aovs = values.find("ciaovs");
    kernel.ciAovs = aovs != values.end() && aovs->second.integer != 0;
    const auto target = values.find("citarget");
    kernel.ciExpected = target != values.end() && target->second.text == "expected";
    const auto pool = values.find("cipool");
    kernel.ciPool = kernel.ciExpected && pool != values.end() ? int(pool->second.integer) : 0;
    if (kernel.ciExpected)
        kernel.intervalTarget =
            "the expected value of the pixel (its true value): Student's t about the mean, the "
            "per-sample variance the larger of the pixel's and the mean of its " +
            std::to_string(2 * kernel.ciPool + 1) + " x " + std::to_string(2 * kernel.ciPool + 1) +
            " neighbourhood's";
}

std::vector<std::string> intervalChannels(const PixelKernel& kernel, const StatsHeader& h) {
    std::vector<std::string> names;
    if (!(kernel.ciLevel > 0.0) || !kernel.interval) return names;
    for (const char* prefix : {kCiLowPrefix, kCiHighPrefix})
        for (const char* c : {"R", "G", "B"}) names.push_back(prefix + std::string(c));
    if (kernel.ciAovs)
        for (const AovChannel& a : h.aovs)
            if (a.cls != AovClass::Id) {
                names.push_back(kCiLowPrefix + a.name);
                names.push_back(kCiHighPrefix + a.name);
            }
    return names;
}

int smallestIntervalM(const Operation& op, const ParamValues& values) {
    if (op.input != InputKind::BufferMeans) return 0;
    PixelKernel kernel = op.bindPixel(values, {0.0, 0.0, 0.0});
    bindConfidence(kernel, values);
    if (!(kernel.ciLevel > 0.0)) return 0;
    if (kernel.ciExpected) return 2;  // Student's t: two buffers
    // Asked of the kernel itself on distinct values: the first m whose interval is not `full`.
    std::vector<double> v, n;
    for (int m = 1; m <= kMaxBuffers; ++m) {
        v.resize(size_t(m));
        n.assign(size_t(m), 1.0);
        for (int i = 0; i < m; ++i) v[size_t(i)] = i;
        if (!kernel.interval(v.data(), n.data(), m, kernel.ciLevel).full) return m;
    }
    return kMaxBuffers + 1;
}

}  // namespace mcstat
