// OIIO adapters over the pure estimators and metrics (see include/mcstat/image/imageops.h).
#include "mcstat/image/imageops.h"

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imagebufalgo_util.h>
#include <OpenImageIO/strutil.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>

#include "mcstat/color.h"
#include "mcstat/core/colour_space.h"
#include "mcstat/filters/aov_weights.h"
#include "mcstat/filters/interval.h"
#include "mcstat/filters/removed_light.h"
#include "mcstat/image/expected_interval.h"
#include "mcstat/image/keep_light_image.h"
#include "mcstat/image/removed_light_pass.h"
#include "mcstat/image/render_layout.h"
#include "mcstat/sample_records.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;
using OIIO::TypeDesc;

namespace {

/// Fills `dst` (an RGB float image already reset to `roi`, then `A` AOV channels) in parallel with
/// a window kernel's pass: image pixel (x, y) is the pass's pixel (x - ox, y - oy). Every chunk of
/// work has its own scratch, so threads share nothing. With A > 0 the pass leaves its weighted
/// elements in the scratch (WindowScratch::wantWeights) and `aovOf(scratch, element, buffer)`
/// points at an element's A values, to which those weights are applied (docs/aovs.md).
template <class AovOf>
void fillFiltered(ImageBuf& dst, ROI roi, int nthreads, size_t A, const AovClass* classes,
                  const WindowPass& pass, int ox, int oy, AovOf aovOf) {
    float* const base = static_cast<float*>(dst.localpixels());
    const size_t nch = 3 + A;
    OIIO::ImageBufAlgo::parallel_image(roi, nthreads, [&](ROI r) {
        const std::unique_ptr<WindowScratch> scratch = pass.newScratch();
        scratch->wantWeights = A > 0;
        PixelEstimate e;
        AovScratch as;
        std::vector<double> w;
        std::vector<float> values;
        for (int y = r.ybegin; y < r.yend; ++y)
            for (int x = r.xbegin; x < r.xend; ++x) {
                pass.filterPixel(x - ox, y - oy, e, *scratch);
                float* px =
                    base +
                    (size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin)) * nch;
                px[0] = e.rgb[0];
                px[1] = e.rgb[1];
                px[2] = e.rgb[2];
                if (A == 0) continue;
                w.clear();
                values.clear();
                for (const auto& el : scratch->weights) {
                    w.push_back(el.weight);
                    const float* v = aovOf(*scratch, el.element, el.buffer);
                    values.insert(values.end(), v, v + A);
                }
                applyAovWeights(w.data(), w.size(), values.data(), A, classes, px + 3, as);
            }
    });
}

}  // namespace

namespace {

/// The AOV channels an image carries (setAovAttributes), or false when it carries none.
bool imageAovs(const ImageSpec& spec, int& first, std::vector<AovClass>& classes) {
    first = spec.get_int_attribute(kAttrFirstAov, -1);
    const std::string text = spec.get_string_attribute(kAttrAovClasses);
    classes.clear();
    for (const std::string& t : OIIO::Strutil::splits(text, ",")) {
        AovClass c;
        if (!parseAovClass(t, c)) return false;
        classes.push_back(c);
    }
    return first >= 3 && !classes.empty() &&
           size_t(first) + classes.size() == size_t(spec.nchannels);
}

/// An AOV-carrying result: `names` (R, G, B, AOVs) and spec attributes for region `roi`.
ImageSpec aovResultSpec(ROI roi, const StatsHeader& h, const std::string& colorSpace) {
    std::vector<std::string> names = {"R", "G", "B"};
    for (const std::string& n : aovOutputChannels(h)) names.push_back(n);
    ImageSpec spec = floatSpec(roi, names, displayWindowROI(h), colorSpace);
    spec.alpha_channel = aovAlphaChannel(h, 3);
    spec.z_channel = aovDepthChannel(h, 3);
    setAovAttributes(spec, h, 3);
    return spec;
}

}  // namespace

void describeResult(ImageSpec& spec, const Operation& op, const ParamValues& values,
                    const StatsHeader& h, std::string* warning) {
    describeSource(spec, h, warning);
    std::string params;
    for (const auto& [k, v] : values) {
        const ParamSpec* ps = op.param(k);
        if (ps && ps->fixed) continue;
        params += (params.empty() ? "" : ",") + k + "=" + v.text;
    }
    const std::string p = kProvenancePrefix;
    spec.attribute(p + "operation", op.name);
    spec.attribute(p + "parameters", params);
}

std::vector<std::string> estimatorChannels(EstimatorMode mode, bool diagnostics) {
    std::vector<std::string> names = {"R", "G", "B"};
    if (!diagnostics) return names;
    if (mode == EstimatorMode::Luminance) {
        names.insert(names.end(), {"gini", "kept", "excluded"});
    } else {
        names.insert(names.end(),
                     {"gini.R", "gini.G", "gini.B", "kept.R", "kept.G", "kept.B", "excluded"});
    }
    return names;
}

namespace {

/// citarget=expected's neighbourhood radius unless cipool says otherwise: 9 x 9 pixels held the
/// reference in 93-94 % of pixel channels of the fixture's firefly scenes (docs/confidence.md).
constexpr int kDefaultCiPool = 4;

/// What a compact file's intervals cover beside the estimator's target (mcstat:ciTarget).
constexpr const char* kCompactIntervalTarget =
    "; on a compact file's pixels that kept only their mean (no heavy tail: every estimator gives "
    "the mean there), the expected value, by Student's t from the stored spread";

}  // namespace

namespace {

/// dst.reset(spec) that keeps dst's pixel memory when it already has the same float layout (a
/// caller estimating again into the same image: each new allocation of a 1080p result with its
/// interval layers is some 18,000 fresh pages to fault in). Every pixel is written afterwards.
void resetKeepingStorage(ImageBuf& dst, const ImageSpec& spec) {
    if (dst.initialized() && dst.localpixels() && dst.storage() == ImageBuf::LOCALBUFFER) {
        const ImageSpec& old = dst.spec();
        if (old.x == spec.x && old.y == spec.y && old.z == spec.z && old.width == spec.width &&
            old.height == spec.height && old.depth == spec.depth &&
            old.nchannels == spec.nchannels && old.format == spec.format &&
            old.channelformats.empty() && spec.channelformats.empty()) {
            dst.specmod() = spec;
            return;
        }
    }
    dst.reset(spec, OIIO::InitializePixels::No);
}

}  // namespace

bool estimate(ImageBuf& dst, const StatsImage& src, const Operation& est, const PixelKernel& kernel,
              bool diagnostics, ROI roi, int nthreads) {
    const StatsHeader& h = src.header;
    const ROI full = dataWindowROI(h);
    roi = prepareRoi(roi, full);
    // Fixed or adaptive M: consistent sub-buffer arrays make pixelBuffers(p) safe.
    if (std::string why; !src.checkBufferLayout(why)) {
        dst.errorfmt("estimate {}: statistics image has inconsistent buffer arrays ({})", est.name,
                     why);
        return false;
    }
    // AOVs (docs/aovs.md): the estimator's buffer weights, from the beauty, applied to every AOV.
    const size_t A = h.aovs.size();
    if (A > 0) {
        // One value per buffer and AOV (fixed M, or every pixel's own buffers: version 6).
        if (src.aov.size() != src.bufferCount.size() * A) {
            dst.errorfmt("estimate {}: statistics image has {} AOV values for {} AOV channels",
                         est.name, src.aov.size(), A);
            return false;
        }
        if (kernel.mode != EstimatorMode::Luminance) {
            dst.errorfmt(
                "{}: mode=channel ranks R, G and B separately, so no one weight per sub-buffer "
                "exists to apply to the file's {} AOV channels (they would stop adding up to the "
                "beauty); use mode=lum (the default)",
                est.name, A);
            return false;
        }
    }
    std::vector<std::string> names = estimatorChannels(kernel.mode, diagnostics);
    // Confidence intervals (docs/confidence.md): per channel, over the valid buffers' values.
    const size_t firstCi = names.size();
    const std::vector<std::string> ciNames = intervalChannels(kernel, h);
    names.insert(names.end(), ciNames.begin(), ciNames.end());
    const bool ci = !ciNames.empty();
    std::vector<size_t> ciAov;  // the AOVs with intervals (ciAovs: all but the labels)
    if (ci && kernel.ciAovs)
        for (size_t a = 0; a < A; ++a)
            if (h.aovs[a].cls != AovClass::Id) ciAov.push_back(a);
    const size_t firstAov = names.size();
    for (const std::string& n : aovOutputChannels(h)) names.push_back(n);
    // The removed-light layers' first step (removed_light_pass.h), last, as appendRemovedLight
    // adds them.
    const size_t firstRemoved = names.size();
    if (kernel.removedLight)
        for (const std::string& n : removedLightChannels()) names.push_back(n);
    const std::vector<AovClass> classes = aovClasses(h.aovs);
    ImageSpec spec = floatSpec(roi, names, h);
    spec.alpha_channel = aovAlphaChannel(h, firstAov);
    spec.z_channel = aovDepthChannel(h, firstAov);
    setAovAttributes(spec, h, firstAov);
    spec.attribute("mcstat:estimator", est.name);
    if (ci) {
        spec.attribute("mcstat:ciLevel", float(kernel.ciLevel));
        // What it covers: a compositor reads a bare level as "the true value is in here", which
        // only the mean's interval claims (docs/confidence.md).
        spec.attribute("mcstat:ciTarget", h.compact && !kernel.ciExpected
                                              ? kernel.intervalTarget + kCompactIntervalTarget
                                              : kernel.intervalTarget);
    }
    resetKeepingStorage(dst, spec);

    // citarget=expected: every pixel's spread and its neighbourhood's, over the whole of `src`
    // (a streamed block carries cipool rows above and below: the same windows as the whole image).
    std::vector<PixelSpread> spreads;
    std::vector<double> pooled;
    if (ci && kernel.ciExpected) {
        spreads = pixelSpreads(src, nthreads);
        pooled = pooledSampleVariance(spreads, h.width, h.height, kernel.ciPool, nthreads);
    }
    // Written straight into the local float buffer: ImageBuf::setpixel converts per call.
    float* const base = static_cast<float*>(dst.localpixels());
    const size_t nch = names.size();
    std::atomic<bool> noWeights{false};
    OIIO::ImageBufAlgo::parallel_image(roi, nthreads, [&](ROI r) {
        EstimatorScratch scratch;
        scratch.wantWeights = A > 0;
        AovScratch aovScratch;
        PixelEstimate e;
        std::vector<int> valid;
        std::vector<double> values, counts;
        for (int y = r.ybegin; y < r.yend; ++y)
            for (int x = r.xbegin; x < r.xend; ++x) {
                const size_t p = size_t(y - h.originY) * size_t(h.width) + size_t(x - h.originX);
                const PixelBuffers pb = src.pixelBuffers(p);
                // A compact file's pixel that kept only its mean (G-MoN trimmed nothing: the
                // estimators give the mean there) has the mean's t interval from its spread.
                const float* sp = ci ? src.meanOnlySpread(p) : nullptr;
                ValueInterval iv[3];
                // The estimate and its interval from one pass over the buffers (the mean's).
                const bool shared =
                    ci && A == 0 && !kernel.ciExpected && !sp && kernel.estimateWithInterval;
                if (shared)
                    kernel.estimateWithInterval(pb, kernel.ciLevel, e, scratch, iv);
                else
                    kernel.estimate(pb, e, scratch);
                float* px =
                    base +
                    (size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin)) * nch;
                if (A > 0) {
                    if (scratch.bufferWeight.size() != size_t(pb.M)) {
                        noWeights = true;
                        std::fill(px + firstAov, px + nch, 0.f);
                    } else {
                        applyAovWeights(scratch.bufferWeight.data(), size_t(pb.M),
                                        src.aov.data() + src.bufferBegin(p) * A, A, classes.data(),
                                        px + firstAov, aovScratch);
                    }
                }
                px[0] = e.rgb[0];
                px[1] = e.rgb[1];
                px[2] = e.rgb[2];
                if (ci) {
                    int m = 0, excluded = 0;
                    if (!shared) m = collectValidBuffers(pb, valid, excluded);
                    if (!shared && !kernel.ciExpected && !sp && kernel.pixelInterval) {
                        kernel.pixelInterval(pb, valid.data(), m, kernel.ciLevel, iv);
                    } else if (!shared) {
                        values.resize(size_t(m));
                        counts.resize(size_t(m));
                        for (int i = 0; i < m; ++i) counts[size_t(i)] = pb.count[valid[size_t(i)]];
                        for (int c = 0; c < 3; ++c) {
                            if (kernel.ciExpected) {
                                const PixelSpread& s = spreads[p];
                                iv[c] =
                                    expectedInterval(s.mean[c], s.s2[c], pooled[p * 3 + size_t(c)],
                                                     s.samples, s.buffers, kernel.ciLevel);
                            } else if (sp) {
                                iv[c] = spreadInterval(pb.mean[c], sp[spreadIndex(c, c)],
                                                       pb.count[0], int(sp[0]), kernel.ciLevel);
                            } else {
                                for (int i = 0; i < m; ++i)
                                    values[size_t(i)] = pb.mean[3 * valid[size_t(i)] + c];
                                iv[c] = kernel.interval(values.data(), counts.data(), m,
                                                        kernel.ciLevel);
                            }
                        }
                    }
                    float* lo = px + firstCi;
                    float* hi = lo + 3;
                    for (int c = 0; c < 3; ++c) {
                        lo[c] = float(iv[c].low);
                        hi[c] = float(iv[c].high);
                    }
                    // An AOV's interval: the same rule over its values in the beauty's valid
                    // buffers (non-finite AOV values left out).
                    const float* aov = A > 0 ? src.aov.data() + src.bufferBegin(p) * A : nullptr;
                    if (!ciAov.empty()) {
                        values.resize(valid.size());
                        counts.resize(valid.size());
                    }
                    for (size_t i = 0; i < ciAov.size(); ++i) {
                        int k = 0;
                        for (int b : valid) {
                            const float v = aov[size_t(b) * A + ciAov[i]];
                            if (!std::isfinite(v)) continue;
                            values[size_t(k)] = v;
                            counts[size_t(k)] = pb.count[b];
                            ++k;
                        }
                        const ValueInterval aiv =
                            kernel.interval(values.data(), counts.data(), k, kernel.ciLevel);
                        lo[6 + 2 * i] = float(aiv.low);
                        lo[7 + 2 * i] = float(aiv.high);
                    }
                }
                if (kernel.removedLight) {
                    const LumaSpread ls = lumaSpread(pb, kernel.removedLuma);
                    removedLightPixel(px, float(ls.mean), float(ls.se), kernel.removedLuma,
                                      px + firstRemoved);
                }
                if (diagnostics) {
                    if (kernel.mode == EstimatorMode::Luminance) {
                        px[3] = e.gini[0];
                        px[4] = float(e.kept[0]);
                        px[5] = float(e.excluded);
                    } else {
                        for (int c = 0; c < 3; ++c) {
                            px[3 + c] = e.gini[c];
                            px[6 + c] = float(e.kept[c]);
                        }
                        px[9] = float(e.excluded);
                    }
                }
            }
    });
    if (noWeights) {
        dst.errorfmt("estimate {}: the estimator gives no buffer weights, so it cannot carry AOVs",
                     est.name);
        return false;
    }
    return true;
}

ImageBuf estimate(const StatsImage& src, const Operation& est, const PixelKernel& kernel,
                  bool diagnostics, ROI roi, int nthreads) {
    ImageBuf dst;
    estimate(dst, src, est, kernel, diagnostics, roi, nthreads);
    return dst;
}

namespace {

/// Float RGB destination for `roi` with the full (display) window `full`.
ImageSpec rgbSpec(ROI roi, ROI full, const std::string& colorSpace) {
    return floatSpec(roi, {"R", "G", "B"}, full, colorSpace);
}

}  // namespace

bool windowFilter(ImageBuf& dst, const ImageBuf& src, const WindowKernel& kernel, ROI roi,
                  int nthreads) {
    if (kernel.over != Neighbourhood::Image) {
        dst.errorfmt("{}: filters the sub-buffers of a statistics file, not an image", kernel.name);
        return false;
    }
    if (src.nchannels() < 3) {
        dst.errorfmt("{} needs R, G, B channels; the image has {}", kernel.name, src.nchannels());
        return false;
    }
    const ROI full = src.roi();  // the data window: what the filter window is clipped to
    roi = prepareRoi(roi, full);
    std::vector<float> in(size_t(full.width()) * size_t(full.height()) * 3);
    if (!src.get_pixels(ROI(full.xbegin, full.xend, full.ybegin, full.yend, 0, 1, 0, 3),
                        TypeDesc::FLOAT, in.data())) {
        dst.errorfmt("{}: {}", kernel.name, src.geterror());
        return false;
    }
    const RGBImageView view{in.data(), full.width(), full.height()};
    std::string err;
    const std::unique_ptr<WindowPass> pass = kernel.begin(
        WindowInput{&view, nullptr}, roi.xbegin - full.xbegin, roi.ybegin - full.ybegin,
        roi.xend - full.xbegin, roi.yend - full.ybegin, nthreads, err);
    if (!pass) {
        dst.errorfmt("{}: {}", kernel.name, err);
        return false;
    }
    std::string colorSpace = src.spec().get_string_attribute("oiio:ColorSpace", "lin_rec709");
    int firstAov = 0;
    std::vector<AovClass> classes;
    if (!imageAovs(src.spec(), firstAov, classes)) {
        dst.reset(rgbSpec(roi, src.roi_full(), colorSpace), OIIO::InitializePixels::No);
        static const float kNoAov = 0.f;  // never read: no AOV channel
        fillFiltered(dst, roi, nthreads, 0, nullptr, *pass, full.xbegin, full.ybegin,
                     [](const WindowScratch&, int, int) { return &kNoAov; });
        return true;
    }
    // AOVs (docs/aovs.md): the window pixels' weights, from the beauty, applied to each.
    if (kernel.mode != EstimatorMode::Luminance) {
        dst.errorfmt(
            "{}: mode=channel keeps different pixels for R, G and B, so no one weight per pixel "
            "exists for the image's {} AOV channels; use mode=lum",
            kernel.name, classes.size());
        return false;
    }
    const size_t A = classes.size(), nch = size_t(src.nchannels());
    std::vector<float> all(size_t(full.width()) * size_t(full.height()) * nch);
    if (!src.get_pixels(full, TypeDesc::FLOAT, all.data())) {
        dst.errorfmt("{}: {}", kernel.name, src.geterror());
        return false;
    }
    ImageSpec spec = rgbSpec(roi, src.roi_full(), colorSpace);
    spec.nchannels = int(3 + A);
    spec.channelnames.resize(3);
    spec.channelformats.clear();
    for (size_t a = 0; a < A; ++a)
        spec.channelnames.push_back(src.spec().channelnames[size_t(firstAov) + a]);
    spec.alpha_channel = -1;
    for (size_t a = 0; a < A; ++a)
        if (classes[a] == AovClass::Alpha) spec.alpha_channel = int(3 + a);
    spec.z_channel = -1;
    spec.attribute(kAttrFirstAov, 3);
    spec.attribute(kAttrAovClasses, src.spec().get_string_attribute(kAttrAovClasses));
    dst.reset(spec, OIIO::InitializePixels::No);
    fillFiltered(dst, roi, nthreads, A, classes.data(), *pass, full.xbegin, full.ybegin,
                 [&](const WindowScratch& scratch, int element, int) {
                     const auto [xx, yy] = scratch.source[size_t(element)];
                     return all.data() + (size_t(yy) * size_t(full.width()) + size_t(xx)) * nch +
                            size_t(firstAov);
                 });
    return true;
}

ImageBuf windowFilter(const ImageBuf& src, const WindowKernel& kernel, ROI roi, int nthreads) {
    ImageBuf dst;
    windowFilter(dst, src, kernel, roi, nthreads);
    return dst;
}

bool windowFilter(ImageBuf& dst, const StatsImage& src, const WindowKernel& kernel, ROI roi,
                  int nthreads) {
    const StatsHeader& h = src.header;
    if (kernel.over != Neighbourhood::SubBuffers) {
        dst.errorfmt("{}: filters an image, not the sub-buffers of a statistics file", kernel.name);
        return false;
    }
    // Fixed or adaptive M: the view hands each pixel's own buffers (StatsImage::pixelBuffers).
    if (std::string why; !src.checkBufferLayout(why)) {
        dst.errorfmt("{}: statistics image has inconsistent buffer arrays ({})", kernel.name, why);
        return false;
    }
    const ROI full = dataWindowROI(h);
    roi = prepareRoi(roi, full);
    const size_t A = h.aovs.size();
    if (A > 0 && src.aov.size() != src.bufferCount.size() * A) {
        dst.errorfmt("{}: statistics image has {} AOV values for {} AOV channels", kernel.name,
                     src.aov.size(), A);
        return false;
    }
    if (A > 0 && kernel.mode != EstimatorMode::Luminance) {
        dst.errorfmt(
            "{}: mode=channel keeps different sub-buffers for R, G and B, so no one weight per "
            "sub-buffer exists for the file's {} AOV channels (they would stop adding up to the "
            "beauty); use mode=lum",
            kernel.name, A);
        return false;
    }
    // Adaptive M: a pixel's M_p buffers hold n / M_p samples each next to one-buffer pixels of n,
    // so every sample votes once (BufferVotes::PerSample); fixed M: one vote per buffer (eq. 5.19).
    const BufferView view{
        h.width, h.height, &src,
        [](const void* ctx, int x, int y) {
            const auto* img = static_cast<const StatsImage*>(ctx);
            return img->pixelBuffers(size_t(y) * size_t(img->header.width) + size_t(x));
        },
        h.adaptiveM ? BufferVotes::PerSample : BufferVotes::PerBuffer};
    std::string err;
    const std::unique_ptr<WindowPass> pass =
        kernel.begin(WindowInput{nullptr, &view}, roi.xbegin - h.originX, roi.ybegin - h.originY,
                     roi.xend - h.originX, roi.yend - h.originY, nthreads, err);
    if (!pass) {
        dst.errorfmt("{}: {}", kernel.name, err);
        return false;
    }
    dst.reset(A > 0 ? aovResultSpec(roi, h, h.colorSpace) : floatSpec(roi, {"R", "G", "B"}, h),
              OIIO::InitializePixels::No);
    // AOVs (docs/aovs.md): every (window pixel, sub-buffer) keeps the weight it had in the
    // beauty's trimmed average.
    const std::vector<AovClass> classes = aovClasses(h.aovs);
    fillFiltered(dst, roi, nthreads, A, classes.data(), *pass, h.originX, h.originY,
                 [&](const WindowScratch& scratch, int list, int buffer) {
                     const auto [xx, yy] = scratch.source[size_t(list)];
                     const size_t k = src.bufferBegin(size_t(yy) * size_t(h.width) + size_t(xx)) +
                                      size_t(buffer);
                     return src.aov.data() + k * A;
                 });
    return true;
}

ImageBuf windowFilter(const StatsImage& src, const WindowKernel& kernel, ROI roi, int nthreads) {
    ImageBuf dst;
    windowFilter(dst, src, kernel, roi, nthreads);
    return dst;
}

namespace {

const StatsHeader& headerOf(const StatsImage& s) { return s.header; }
const StatsHeader& headerOf(const StatsBlockSource& s) { return s.header(); }

template <class Source>
bool plainMeanOf(ImageBuf& dst, Source& src, const std::array<double, 3>& luma, ROI roi,
                 int nthreads) {
    const Operation& mean = *findOperation("mean");
    return estimate(dst, src, mean, mean.bindPixel(ParamValues(), luma), false, roi, nthreads);
}

/// applyOperation over an image in memory or a streamed source: the same calls, each with its
/// own overloads of estimate() and windowFilter().
template <class Source>
bool runOperationOn(ImageBuf& dst, Source& src, const Operation& op, const ParamValues& values,
                    const std::array<double, 3>& luma, bool diagnostics, ROI roi, int nthreads) {
    switch (op.input) {
        case InputKind::BufferMeans: {
            PixelKernel kernel = op.bindPixel(values, luma);
            bindConfidence(kernel, values);
            // The removed-light layers in this pass (removedLightInPass): no second read.
            RemovedLightOptions removed;
            kernel.removedLight = removedLightValues(values, removed);
            kernel.removedLuma = luma;
            if (!estimate(dst, src, op, kernel, diagnostics, roi, nthreads)) return false;
            return !kernel.removedLight ||
                   finishRemovedLight(dst, dst.nchannels() - 5, luma, removed, nthreads);
        }
        case InputKind::Neighbourhood: {
            const WindowKernel kernel = op.bindWindow(values, luma);
            if (kernel.over == Neighbourhood::SubBuffers)
                return windowFilter(dst, src, kernel, roi, nthreads);
            if (kernel.over == Neighbourhood::Image) {
                // The plain mean as the "mean" estimator computes it (`mcstat f --mean --mif`)
                // over roi grown by the window's radius (clipped to the data window), then the
                // median filter over roi: each window sees the same pixels as over the whole
                // image, since only the data window's edges clip it.
                const ROI full = dataWindowROI(headerOf(src));
                roi = prepareRoi(roi, full);
                const int rx = kernel.haloX(), ry = kernel.haloY();
                const ROI grown = OIIO::roi_intersection(
                    ROI(roi.xbegin - rx, roi.xend + rx, roi.ybegin - ry, roi.yend + ry), full);
                ImageBuf mean;
                if (!plainMean(mean, src, luma, grown, nthreads)) {
                    dst.errorfmt("{}: {}", op.name, mean.geterror());
                    return false;
                }
                return windowFilter(dst, mean, kernel, roi, nthreads);
            }
            break;
        }
        case InputKind::Samples:
            dst.errorfmt("{} works on the per-sample records of a statistics file on disk",
                         op.name);
            return false;
    }
    dst.errorfmt("{}: the registry entry names no input it can run on", op.name);
    return false;
}

/// The operation, then with keeplight=1 (keep_light_image.h) the light it removed given back.
template <class Source>
bool applyOperationTo(ImageBuf& dst, Source& src, const Operation& op, const ParamValues& values,
                      const std::array<double, 3>& luma, bool diagnostics, ROI roi, int nthreads) {
    const bool keep = keepLightAsked(values);
    if (const std::string why = keepLightRefusal(op, values); !why.empty()) {
        dst.errorfmt("{}", why);
        return false;
    }
    if (keep && roi.defined() && roi != dataWindowROI(headerOf(src))) {
        dst.errorfmt("{}: keeplight needs the whole data window (light moves between pixels)",
                     op.name);
        return false;
    }
    if (RemovedLightOptions r; removedLightValues(values, r) && !removedLightInPass(op, keep)) {
        dst.errorfmt(
            "{}: removed=1 is computed in the operation's pass only for a per-pixel estimator "
            "without keeplight; append the layers afterwards (appendRemovedLight)",
            op.name);
        return false;
    }
    if (!runOperationOn(dst, src, op, values, luma, diagnostics, roi, nthreads)) return false;
    return !keep || keepLight(dst, src, luma, keepLightParams(values), nthreads);
}

}  // namespace

namespace {

/// appendResidual over an image in memory or a streamed source.
template <class Source>
bool appendResidualTo(ImageBuf& robust, Source& src, const std::array<double, 3>& luma,
                      int nthreads) {
    const StatsHeader& h = headerOf(src);
    ImageBuf mean;
    if (!plainMean(mean, src, luma, robust.roi(), nthreads)) {
        robust.errorfmt("residual: {}", mean.geterror());
        return false;
    }
    const ImageSpec& rs = robust.spec();
    std::vector<int> meanIndex;
    const std::vector<int> from = residualChannels(rs, mean.spec(), h, meanIndex);
    std::vector<std::string> names;
    for (int c : from) names.push_back(kResidualPrefix + rs.channelnames[size_t(c)]);
    ImageSpec spec = rs;
    spec.nchannels = rs.nchannels + int(from.size());
    spec.channelnames.insert(spec.channelnames.end(), names.begin(), names.end());
    spec.channelformats.clear();
    ImageBuf out(spec);
    const ROI roi = robust.roi();
    const size_t nin = size_t(rs.nchannels), nout = size_t(spec.nchannels),
                 nm = size_t(mean.nchannels());
    const float* rp = static_cast<const float*>(robust.localpixels());
    const float* mp = static_cast<const float*>(mean.localpixels());
    float* op = static_cast<float*>(out.localpixels());
    for (size_t q = 0; q < roi.npixels(); ++q) {
        std::copy(rp + q * nin, rp + (q + 1) * nin, op + q * nout);
        for (size_t i = 0; i < from.size(); ++i)
            op[q * nout + nin + i] = float(double(mp[q * nm + size_t(meanIndex[i])]) -
                                           double(rp[q * nin + size_t(from[i])]));
    }
    robust = std::move(out);
    return true;
}

}  // namespace

bool plainMean(ImageBuf& dst, const StatsImage& src, const std::array<double, 3>& luma, ROI roi,
               int nthreads) {
    return plainMeanOf(dst, src, luma, roi, nthreads);
}

bool plainMean(ImageBuf& dst, StatsBlockSource& src, const std::array<double, 3>& luma, ROI roi,
               int nthreads) {
    return plainMeanOf(dst, src, luma, roi, nthreads);
}

std::vector<int> residualChannels(const ImageSpec& robust, const ImageSpec& mean,
                                  const StatsHeader& h, std::vector<int>& meanIndex) {
    std::vector<int> from;
    for (int c = 0; c < robust.nchannels; ++c) {
        const std::string& n = robust.channelnames[size_t(c)];
        const int a = h.aovIndex(n);
        if (c >= 3 && (a < 0 || h.aovs[size_t(a)].cls == AovClass::Id)) continue;
        const int m = mean.channelindex(n);
        if (m < 0) continue;
        from.push_back(c);
        meanIndex.push_back(m);
    }
    return from;
}

bool appendResidual(ImageBuf& robust, const StatsImage& src, const std::array<double, 3>& luma,
                    int nthreads) {
    return appendResidualTo(robust, src, luma, nthreads);
}

bool appendResidual(ImageBuf& robust, StatsBlockSource& src, const std::array<double, 3>& luma,
                    int nthreads) {
    return appendResidualTo(robust, src, luma, nthreads);
}

bool applyOperation(ImageBuf& dst, const StatsImage& src, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma, bool diagnostics,
                    ROI roi, int nthreads) {
    return applyOperationTo(dst, src, op, values, luma, diagnostics, roi, nthreads);
}

bool applyOperation(ImageBuf& dst, StatsBlockSource& src, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma, bool diagnostics,
                    ROI roi, int nthreads) {
    return applyOperationTo(dst, src, op, values, luma, diagnostics, roi, nthreads);
}

bool applyOperation(ImageBuf& dst, const ImageBuf& src, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma, ROI roi,
                    int nthreads) {
    if (!takesImage(op)) {
        dst.errorfmt("{} works on a statistics file, not on an image", op.name);
        return false;
    }
    return windowFilter(dst, src, op.bindWindow(values, luma), roi, nthreads);
}

bool takesImage(const Operation& op) {
    return op.input == InputKind::Neighbourhood && op.over == Neighbourhood::Image;
}

bool readsSamples(const Operation& op) { return op.input == InputKind::Samples; }

bool hasDiagnostics(const Operation& op) { return op.input == InputKind::BufferMeans; }

std::vector<ParamSpec> operationModifiers(const Operation& op) {
    std::vector<ParamSpec> m;
    for (const ParamSpec* p : op.settable()) m.push_back(*p);
    if (hasDiagnostics(op))
        m.push_back(flagParam("diag", "0", "1 appends channels gini, kept, excluded"));
    if (hasIntervals(op))
        for (const ParamSpec& p : confidenceModifiers()) m.push_back(p);
    if (!takesImage(op) && !readsSamples(op)) {
        m.push_back(
            flagParam("residual", "0",
                      "1 appends residual.<channel> = mean - result for the beauty and every AOV"));
        m.push_back(flagParam(
            "removed", "0",
            "1 appends removed.Y, .se, .z, .zlocal, .significant: the light taken, its standard "
            "error, and where the buffers support it (docs/removed-light.md)"));
        m.push_back(intParam("removedradius", 0, 16, "2",
                             "with removed=1: radius of the window of removed.zlocal"));
        m.push_back(realParam("removedz", 0.0, 1e6, true, "3",
                              "with removed=1: removed.significant where removed.zlocal > this"));
        for (const ParamSpec& p : keepLightModifiers()) m.push_back(p);
    }
    return m;
}

std::string removedModifiersRefusal(const std::string& context, bool removed,
                                    const std::map<std::string, std::string>& mods) {
    if (removed) return {};
    for (const char* k : {"removedradius", "removedz"})
        if (mods.count(k)) return context + ": " + k + " needs removed=1";
    return {};
}

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

bool intervalWidthImage(ImageBuf& dst, const ImageBuf& src) {
    const ImageSpec& in = src.spec();
    int lo[3], hi[3], est[3];
    for (int c = 0; c < 3; ++c) {
        const std::string n(1, "RGB"[c]);
        est[c] = in.channelindex(n);
        lo[c] = in.channelindex(kCiLowPrefix + n);
        hi[c] = in.channelindex(kCiHighPrefix + n);
        if (est[c] < 0 || lo[c] < 0 || hi[c] < 0) {
            dst.errorfmt("the image has no channel {}{} (an estimator's result with :ci=LEVEL)",
                         est[c] < 0  ? ""
                         : lo[c] < 0 ? kCiLowPrefix
                                     : kCiHighPrefix,
                         n);
            return false;
        }
    }
    ImageSpec spec = floatSpec(src.roi(), {kCiWidthChannel}, src.roi_full());
    spec.extra_attribs = in.extra_attribs;  // provenance: the heatmap's caption
    dst.reset(spec);
    std::vector<float> px(size_t(in.nchannels));
    for (OIIO::ImageBuf::Iterator<float> it(dst); !it.done(); ++it) {
        src.getpixel(it.x(), it.y(), px.data(), in.nchannels);
        double width = 0.0, value = 0.0;
        for (int c = 0; c < 3; ++c) {
            width += double(px[size_t(hi[c])]) - double(px[size_t(lo[c])]);
            value += std::fabs(double(px[size_t(est[c])]));
        }
        it[0] = float(width == 0.0 ? 0.0 : value > 0.0 ? width / value : HUGE_VAL);
        if (std::isnan(width)) it[0] = NAN;
    }
    return true;
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

int smallestRobustM(const Operation& op, const ParamValues& values) {
    if (op.input != InputKind::BufferMeans) return 1;
    return op.bindPixel(values, {0.0, 0.0, 0.0}).smallestRobustM;
}

bool runSamplesOperation(ImageBuf& dst, const std::string& path, const StatsHeader& header,
                         const Operation& op, const ParamValues& values,
                         const std::array<double, 3>& luma, int nthreads,
                         const std::function<void(double)>& progress) {
    if (op.input != InputKind::Samples || op.samples == nullptr) {
        dst.errorfmt("{} is not a per-sample operation", op.name);
        return false;
    }
    std::string openErr;
    const std::unique_ptr<SampleSource> source =
        openSampleSource(path, openErr, ReadLimits(), nthreads);
    if (!source) {
        dst.errorfmt("{}", openErr);
        return false;
    }
    SamplesRequest req;
    req.path = path;
    req.source = source.get();
    req.params = &values;
    req.luma = luma;
    req.nthreads = nthreads;
    req.progress = progress;
    OperationImage out;
    std::string err;
    if (!op.samples(req, out, err)) {
        dst.errorfmt("{}", err);
        return false;
    }
    const size_t nch = out.channels.size();
    if (out.width != header.width || out.height != header.height || nch < 3 ||
        out.pixels.size() != size_t(out.width) * size_t(out.height) * nch) {
        dst.errorfmt(
            "{}: {} returned a {} x {} image of {} channels and {} values; the file is {} "
            "x {}",
            path, op.name, out.width, out.height, nch, out.pixels.size(), header.width,
            header.height);
        return false;
    }
    dst.reset(floatSpec(dataWindowROI(header), out.channels, {}, header.colorSpace));
    return dst.set_pixels(dst.roi(), TypeDesc::FLOAT, out.pixels.data());
}

ImageBuf beautyImage(const StatsImage& src) {
    const StatsHeader& h = src.header;
    ImageBuf dst(floatSpec(dataWindowROI(h), {"R", "G", "B"}, {}, h.colorSpace));
    if (src.beauty.size() == src.pixelCount() * 3)
        dst.set_pixels(dst.roi(), TypeDesc::FLOAT, src.beauty.data());
    else
        dst.errorfmt("statistics image has no beauty part");
    return dst;
}

bool displayTransform(ImageBuf& dst, const ImageBuf& src, ROI roi, int nthreads) {
    if (!roi.defined()) roi = src.roi();
    if (src.nchannels() < 3) {
        dst.errorfmt("display transform needs R, G, B channels; the image has {}", src.nchannels());
        return false;
    }
    ImageBuf out(floatSpec(roi, {"R", "G", "B"}));
    if (!OIIO::ImageBufAlgo::copy(out, src, TypeDesc::FLOAT,
                                  ROI(roi.xbegin, roi.xend, roi.ybegin, roi.yend, 0, 1, 0, 3),
                                  nthreads)) {
        dst.errorfmt("{}", out.geterror());
        return false;
    }
    std::string err;
    auto* pixels = static_cast<float*>(out.localpixels());
    // The pixels' working space (docs/colour.md): an ACEScg result is not shown as Rec.709.
    const std::string space = src.spec().get_string_attribute("oiio:ColorSpace");
    if (!applyDisplayTransform(pixels, long(roi.npixels()), err, "", "", space)) {
        dst.errorfmt("{}", err);
        return false;
    }
    dst = std::move(out);
    return true;
}

ImageBuf displayTransform(const ImageBuf& src, ROI roi, int nthreads) {
    ImageBuf dst;
    displayTransform(dst, src, roi, nthreads);
    return dst;
}

bool diffImages(const ImageBuf& img, const ImageBuf& ref, const DiffOptions& opt, DiffMetrics& out,
                std::string& err) {
    const ROI a = img.roi(), b = ref.roi();
    if (a.width() != b.width() || a.height() != b.height()) {
        err = OIIO::Strutil::fmt::format("image is {}x{} but the reference is {}x{}", a.width(),
                                         a.height(), b.width(), b.height());
        return false;
    }
    if (img.nchannels() < 3 || ref.nchannels() < 3) {
        err = "both images need R, G, B channels";
        return false;
    }
    const int w = a.width(), h = a.height();
    std::vector<float> lin(size_t(w) * h * 3), rlin(lin.size());
    img.get_pixels(ROI(a.xbegin, a.xend, a.ybegin, a.yend, 0, 1, 0, 3), TypeDesc::FLOAT,
                   lin.data());
    ref.get_pixels(ROI(b.xbegin, b.xend, b.ybegin, b.yend, 0, 1, 0, 3), TypeDesc::FLOAT,
                   rlin.data());
    std::vector<float> disp = lin, rdisp = rlin;
    if (!applyDisplayTransform(disp.data(), long(w) * h, err, "", "", opt.space) ||
        !applyDisplayTransform(rdisp.data(), long(w) * h, err, "", "", opt.space))
        return false;
    out = compareImages(lin.data(), rlin.data(), disp.data(), rdisp.data(), w, h, opt);
    return true;
}

}  // namespace mcstat
