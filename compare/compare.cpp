// Noise-aware comparison of two renders from their sub-buffers (include/mcstat/compare/compare.h,
// docs/compare.md): the two entry points, which check their sides and options (compare_checks.h)
// and run the engine (comparison.h). The verdict's text is compare_verdict.cpp's, the parameters
// compare_params.cpp's.
#include "mcstat/compare/compare.h"

#include <fmt/format.h>

#include "compare_checks.h"
#include "comparison.h"

namespace mcstat {

using detail::checkOptions;
using detail::checkReferenceVariance;
using detail::compactQuantities;
using detail::Comparison;
using detail::setWindow;
using detail::Side;
using detail::sideBuffers;

bool compareStats(StatsBlockSource& a, StatsBlockSource& b, const CompareOptions& opt,
                  CompareResult& out, std::string& err) {
    out = CompareResult();
    if (!checkOptions(opt, err)) return false;
    const StatsHeader& ha = a.header();
    const StatsHeader& hb = b.header();
    if (ha.width != hb.width || ha.height != hb.height || ha.originX != hb.originX ||
        ha.originY != hb.originY) {
        err = fmt::format(
            "{} ({}x{} at {},{}) and {} ({}x{} at {},{}) have different data "
            "windows: not renders of one image",
            a.name(), ha.width, ha.height, ha.originX, ha.originY, b.name(), hb.width, hb.height,
            hb.originX, hb.originY);
        return false;
    }
    if (opt.rule == CompareOptions::Rule::Mitsuba) {
        err = fmt::format(
            "rule=mitsuba tests a render against a reference image and its variance (refvar=); "
            "{} and {} are statistics files",
            a.name(), b.name());
        return false;
    }
    if (!sideBuffers(a, out.Ma, err) || !sideBuffers(b, out.Mb, err) ||
        !compactQuantities(a, opt, err) || !compactQuantities(b, opt, err))
        return false;
    setWindow(out, ha, ha.adaptiveM || hb.adaptiveM, opt);
    Side sa, sb;
    sa.src = &a;
    sb.src = &b;
    sa.aovCount = int(ha.aovs.size());
    sb.aovCount = int(hb.aovs.size());
    Comparison c(sa, sb, opt, out);
    return c.run(err);
}

bool compareStatsToImage(const OIIO::ImageBuf& ref, const std::string& refName, StatsBlockSource& b,
                         const CompareOptions& options, CompareResult& out, std::string& err,
                         const OIIO::ImageBuf* refVar) {
    out = CompareResult();
    CompareOptions opt = options;
    if (!checkOptions(opt, err) || !checkReferenceVariance(refVar, ref, refName, opt, err))
        return false;
    if (opt.rule == CompareOptions::Rule::Mitsuba) {
        opt.rgb = true;  // Mitsuba tests each channel; no tiles
        opt.tile = 0;
    }
    const StatsHeader& hb = b.header();
    const OIIO::ROI win = ref.roi();
    if (ref.nchannels() < 3) {
        err = fmt::format("{} has {} channel(s); R, G, B are needed", refName, ref.nchannels());
        return false;
    }
    if (win.width() != hb.width || win.height() != hb.height) {
        err = fmt::format("{} is {}x{}, {} is {}x{}: not the same image", refName, win.width(),
                          win.height(), b.name(), hb.width, hb.height);
        return false;
    }
    if (!sideBuffers(b, out.Mb, err) || !compactQuantities(b, opt, err)) return false;
    if (opt.trimmed) {
        // A trimmed mean estimates the mean only for symmetric distributions; a pixel's samples
        // are skewed (rare bright paths), so it would differ from the reference's mean anyway.
        err = fmt::format(
            "test=yuen compares trimmed means, and {} holds a mean: use test=welch "
            "against a reference image",
            refName);
        return false;
    }
    out.oneSample = true;
    setWindow(out, hb, hb.adaptiveM, opt);
    Side sa, sb;
    sa.ref = &ref;
    sa.refRGB.resize(size_t(win.width()) * size_t(win.height()) * 3);
    OIIO::ROI rgb = win;
    rgb.chbegin = 0;
    rgb.chend = 3;
    if (!ref.get_pixels(rgb, OIIO::TypeFloat, sa.refRGB.data())) {
        err = fmt::format("{}: {}", refName, ref.geterror());
        return false;
    }
    if (refVar) {
        sa.refVar.resize(sa.refRGB.size());
        OIIO::ROI vr = refVar->roi();
        vr.chbegin = 0;
        vr.chend = 3;
        if (!refVar->get_pixels(vr, OIIO::TypeFloat, sa.refVar.data())) {
            err = fmt::format("{}'s variance: {}", refName, refVar->geterror());
            return false;
        }
    }
    sb.src = &b;
    sb.aovCount = int(hb.aovs.size());
    Comparison c(sa, sb, opt, out);
    return c.run(err);
}

}  // namespace mcstat
