// A per-pixel estimator over a statistics image in memory (estimate, imageops.h): the estimate of
// every pixel, with its diagnostics, confidence intervals, AOVs and removed-light layers.
#include <OpenImageIO/imagebufalgo_util.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include "mcstat/filters/aov_weights.h"
#include "mcstat/filters/interval.h"
#include "mcstat/filters/removed_light.h"
#include "mcstat/image/expected_interval.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/removed_light_pass.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;

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

/// What a compact file's intervals cover beside the estimator's target (mcstat:ciTarget).
constexpr const char* kCompactIntervalTarget =
    "; on a compact file's pixels that kept only their mean (no heavy tail: every estimator gives "
    "the mean there), the expected value, by Student's t from the stored spread";

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

/// What an estimator's result over `src` is refused for: buffer arrays that do not agree, AOV
/// values that do not match the header, or AOVs with channel mode (no one weight per buffer).
bool checkEstimateInput(ImageBuf& dst, const StatsImage& src, const Operation& est,
                        const PixelKernel& kernel) {
    // Fixed or adaptive M: consistent sub-buffer arrays make pixelBuffers(p) safe.
    if (std::string why; !src.checkBufferLayout(why)) {
        dst.errorfmt("estimate {}: statistics image has inconsistent buffer arrays ({})", est.name,
                     why);
        return false;
    }
    // AOVs (docs/aovs.md): the estimator's buffer weights, from the beauty, applied to every AOV.
    const size_t A = src.header.aovs.size();
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
    return true;
}

/// One estimate() pass: what every pixel reads, set up once and shared by the threads, and where
/// each layer of a result pixel starts (R, G, B, diagnostics, intervals, AOVs, removed light).
struct EstimatePass {
    const StatsImage& src;
    const PixelKernel& kernel;
    bool diagnostics = false;
    size_t A = 0;  ///< the file's AOVs
    std::vector<std::string> names;
    size_t firstCi = 0, firstAov = 0, firstRemoved = 0, firstPlainMean = 0;
    /// PixelKernel::plainMeanLayers: the "mean" estimator's kernel.
    PixelKernel meanKernel;
    bool ci = false;
    std::vector<size_t> ciAov;  ///< the AOVs with intervals (ciAovs: all but the labels)
    std::vector<AovClass> classes;
    /// citarget=expected: every pixel's spread and its neighbourhood's pooled variance.
    std::vector<PixelSpread> spreads;
    std::vector<double> pooled;

    EstimatePass(const StatsImage& s, const PixelKernel& k, bool diag)
        : src(s), kernel(k), diagnostics(diag), A(s.header.aovs.size()) {
        const StatsHeader& h = src.header;
        names = estimatorChannels(kernel.mode, diagnostics);
        // Confidence intervals (docs/confidence.md): per channel, over the valid buffers' values.
        firstCi = names.size();
        const std::vector<std::string> ciNames = intervalChannels(kernel, h);
        names.insert(names.end(), ciNames.begin(), ciNames.end());
        ci = !ciNames.empty();
        if (ci && kernel.ciAovs)
            for (size_t a = 0; a < A; ++a)
                if (h.aovs[a].cls != AovClass::Id) ciAov.push_back(a);
        firstAov = names.size();
        for (const std::string& n : aovOutputChannels(h)) names.push_back(n);
        // The removed-light layers' first step (removed_light_pass.h), last, as
        // appendRemovedLight adds them.
        firstRemoved = names.size();
        if (kernel.removedLight)
            for (const std::string& n : removedLightChannels()) names.push_back(n);
        // The plain mean's layers (keeplight), after all the others.
        firstPlainMean = names.size();
        if (kernel.plainMeanLayers) {
            meanKernel = findOperation("mean")->bindPixel(ParamValues(), kernel.removedLuma);
            for (size_t c = 0; c < 3; ++c) names.push_back(kPlainMeanPrefix + names[c]);
            for (size_t a = firstAov; a < firstAov + A; ++a)
                names.push_back(kPlainMeanPrefix + names[a]);
        }
        classes = aovClasses(h.aovs);
    }

    /// The result's spec over `roi`: the layers above, the AOVs' roles, what the intervals cover.
    ImageSpec spec(ROI roi, const Operation& est) const {
        const StatsHeader& h = src.header;
        ImageSpec spec = floatSpec(roi, names, h);
        spec.alpha_channel = aovAlphaChannel(h, firstAov);
        spec.z_channel = aovDepthChannel(h, firstAov);
        setAovAttributes(spec, h, firstAov);
        spec.attribute("mcstat:estimator", est.name);
        if (ci) {
            spec.attribute("mcstat:ciLevel", float(kernel.ciLevel));
            // What it covers: a compositor reads a bare level as "the true value is in here",
            // which only the mean's interval claims (docs/confidence.md).
            spec.attribute("mcstat:ciTarget", h.compact && !kernel.ciExpected
                                                  ? kernel.intervalTarget + kCompactIntervalTarget
                                                  : kernel.intervalTarget);
        }
        return spec;
    }
};

/// Pixels whose removed-light spreads estimateRun sums together.
constexpr int kGroup = 8;

/// One thread's scratch for the pixels of an estimate() pass.
struct PixelScratch {
    EstimatorScratch scratch;
    AovScratch aovScratch;
    PixelEstimate e;
    std::vector<int> valid;
    std::vector<double> values, counts;
    /// The removed light's luminance spreads of eight pixels (estimateRun): the pixels' buffers
    /// and, where the estimates left them (EstimatorScratch::LumaKeys), their buffers'
    /// luminances and counts, eight lanes per buffer (on the heap: four kilobytes more of this
    /// scratch on the stack made every estimate 5 to 8 % slower).
    PixelBuffers groupBuffers[kGroup];
    LumaSpread groupSpreads[kGroup];
    std::vector<double> groupKeys, groupCounts;  // kGroup x 64
    /// The run's intervals where the kernel takes runs (PixelKernel::runIntervals): for each
    /// pixel of the run its index among those given (-1: not given, channelIntervals' case).
    std::vector<PixelBuffers> runIntervalBuffers;
    std::vector<ValueInterval> runIntervals;  // 3 per pixel given
    std::vector<int> runIntervalOf;
    /// The run's estimates where the kernel gives them with the intervals
    /// (PixelKernel::estimatesWithIntervals), as runIntervals.
    std::vector<PixelEstimate> runEstimates;
    /// PixelKernel::plainMeanLayers: the plain mean's own estimate and scratch.
    EstimatorScratch meanScratch;
    PixelEstimate meanEstimate;
};

/// Pixel `p`'s A AOV values (buffers `pb`) into `out` with the buffer weights an estimate left
/// in `weight` (applyAovWeights); false, with zeros, when it left none.
bool weightedAovs(const EstimatePass& pass, size_t p, const PixelBuffers& pb,
                  const std::vector<double>& weight, float* out, AovScratch& s) {
    if (weight.size() != size_t(pb.M)) {
        std::fill(out, out + pass.A, 0.f);
        return false;
    }
    applyAovWeights(weight.data(), size_t(pb.M),
                    pass.src.aov.data() + pass.src.bufferBegin(p) * pass.A, pass.A,
                    pass.classes.data(), out, s);
    return true;
}

/// PixelKernel::plainMeanLayers: the plain mean of pixel `p` (buffers `pb`) into `out`: R, G, B,
/// then the AOVs with the "mean" estimator's weights. The same calls as a pass of the "mean"
/// estimator, so the same bits.
void plainMeanPixel(const EstimatePass& pass, size_t p, const PixelBuffers& pb, float* out,
                    PixelScratch& w) {
    w.meanScratch.wantWeights = pass.A > 0;
    pass.meanKernel.estimate(pb, w.meanEstimate, w.meanScratch);
    for (int c = 0; c < 3; ++c) out[c] = w.meanEstimate.rgb[size_t(c)];
    if (pass.A > 0) weightedAovs(pass, p, pb, w.meanScratch.bufferWeight, out + 3, w.aovScratch);
}

/// The interval of R, G and B of pixel `p` when the estimate did not give it in its own pass: the
/// kernel's own over the valid buffers, the expected value's (citarget=expected), a compact
/// pixel's from its stored spread `sp`, or the kernel's rule over each channel's buffer values.
/// Leaves the valid buffers in w.valid for the AOVs' intervals.
void channelIntervals(const EstimatePass& pass, size_t p, const PixelBuffers& pb, const float* sp,
                      PixelScratch& w, ValueInterval iv[3]) {
    const PixelKernel& kernel = pass.kernel;
    int excluded = 0;
    const int m = collectValidBuffers(pb, w.valid, excluded);
    if (!kernel.ciExpected && !sp && kernel.pixelInterval) {
        kernel.pixelInterval(pb, w.valid.data(), m, kernel.ciLevel, iv);
        return;
    }
    w.values.resize(size_t(m));
    w.counts.resize(size_t(m));
    for (int i = 0; i < m; ++i) w.counts[size_t(i)] = pb.count[w.valid[size_t(i)]];
    for (int c = 0; c < 3; ++c) {
        if (kernel.ciExpected) {
            const PixelSpread& s = pass.spreads[p];
            iv[c] = expectedInterval(s.mean[c], s.s2[c], pass.pooled[p * 3 + size_t(c)], s.samples,
                                     s.buffers, kernel.ciLevel);
        } else if (sp) {
            iv[c] = spreadInterval(pb.mean[c], sp[spreadIndex(c, c)], pb.count[0], int(sp[0]),
                                   kernel.ciLevel);
        } else {
            for (int i = 0; i < m; ++i) w.values[size_t(i)] = pb.mean[3 * w.valid[size_t(i)] + c];
            iv[c] = kernel.interval(w.values.data(), w.counts.data(), m, kernel.ciLevel);
        }
    }
}

/// An AOV's interval: the kernel's rule over its values in the beauty's valid buffers (w.valid;
/// non-finite AOV values left out), written as the pair ci_low.<aov>, ci_high.<aov> after the
/// channels' (`lo`: the first interval layer).
void aovIntervals(const EstimatePass& pass, size_t p, const PixelBuffers& pb, PixelScratch& w,
                  float* lo) {
    const size_t A = pass.A;
    const float* aov = A > 0 ? pass.src.aov.data() + pass.src.bufferBegin(p) * A : nullptr;
    if (!pass.ciAov.empty()) {
        w.values.resize(w.valid.size());
        w.counts.resize(w.valid.size());
    }
    for (size_t i = 0; i < pass.ciAov.size(); ++i) {
        int k = 0;
        for (int b : w.valid) {
            const float v = aov[size_t(b) * A + pass.ciAov[i]];
            if (!std::isfinite(v)) continue;
            w.values[size_t(k)] = v;
            w.counts[size_t(k)] = pb.count[b];
            ++k;
        }
        const ValueInterval aiv =
            pass.kernel.interval(w.values.data(), w.counts.data(), k, pass.kernel.ciLevel);
        lo[6 + 2 * i] = float(aiv.low);
        lo[7 + 2 * i] = float(aiv.high);
    }
}

/// The diagnostics layers: the Gini coefficient, the buffers kept and those excluded (per channel
/// in channel mode).
void writeDiagnostics(float* px, const PixelEstimate& e, EstimatorMode mode) {
    if (mode == EstimatorMode::Luminance) {
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

/// The layers of `px` that come from the estimate `e` and the R, G, B intervals `iv` (null in a
/// pass without intervals): R, G, B, the intervals' ends, the diagnostics. Inlined: called for
/// each pixel, it was 5 % of the mean's :ci samples (three medians of five, 81-86 ms against
/// 86 ms).
[[gnu::always_inline]] inline void writeEstimateLayers(const EstimatePass& pass, float* px,
                                                       const PixelEstimate& e,
                                                       const ValueInterval* iv) {
    px[0] = e.rgb[0];
    px[1] = e.rgb[1];
    px[2] = e.rgb[2];
    if (iv) {
        float* lo = px + pass.firstCi;
        float* hi = lo + 3;
        for (int c = 0; c < 3; ++c) {
            lo[c] = float(iv[c].low);
            hi[c] = float(iv[c].high);
        }
    }
    if (pass.diagnostics) writeDiagnostics(px, e, pass.kernel.mode);
}

/// Pixel `p` of the statistics image into `px`, every layer of the pass but the removed light's
/// (estimateRun adds it); `given` its interval when estimateRun took it with the run's, and
/// `givenEstimate` its estimate when the run's came with the intervals. False when the estimator
/// gave no buffer weights for the AOVs (their layers are then zero).
bool estimatePixel(const EstimatePass& pass, size_t p, float* px, PixelScratch& w,
                   const ValueInterval* given, const PixelEstimate* givenEstimate) {
    const StatsImage& src = pass.src;
    const PixelKernel& kernel = pass.kernel;
    const size_t A = pass.A;
    const PixelBuffers pb = src.pixelBuffers(p);
    if (givenEstimate)
        w.e = *givenEstimate;
    else
        kernel.estimate(pb, w.e, w.scratch);
    const bool weighted = A == 0 || weightedAovs(pass, p, pb, w.scratch.bufferWeight,
                                                 px + pass.firstAov, w.aovScratch);
    ValueInterval computed[3];
    const ValueInterval* iv = given;
    if (pass.ci && !given) {
        // A compact file's pixel that kept only its mean (G-MoN trimmed nothing: the estimators
        // give the mean there) has the mean's t interval from its spread.
        channelIntervals(pass, p, pb, src.meanOnlySpread(p), w, computed);
        iv = computed;
    }
    writeEstimateLayers(pass, px, w.e, pass.ci ? iv : nullptr);
    if (pass.ci) aovIntervals(pass, p, pb, w, px + pass.firstCi);
    if (kernel.plainMeanLayers) plainMeanPixel(pass, p, pb, px + pass.firstPlainMean, w);
    return weighted;
}

/// Asks for the buffers of the pixel `ahead` after p, where the image has one (prefetchBuffers,
/// pixel_buffers.h). Always inlined, as prefetchBuffers is: GCC would drop calls to a function
/// whose only effect is a prefetch.
[[gnu::always_inline]] inline void prefetchAhead(const StatsImage& src, size_t p,
                                                 size_t ahead = kPrefetchPixels) {
    if (p + ahead < src.pixelCount()) prefetchBuffers(src.pixelBuffers(p + ahead));
}

/// What takeRun took for a run: EstimatesAndIntervals from one call of the kernel's (pixels
/// taken in order), EstimatesThenIntervals every pixel's estimate (by its place in the run) and
/// the intervals of those taken.
enum class RunGiven {
    Nothing,
    Intervals,
    EstimatesAndIntervals,
    EstimatesThenIntervals,
    Estimates
};

/// What the kernel computes for the n pixels from `p0` on as a run, before the pixels one by one:
/// in a pass with intervals of the kernel's own (no AOV intervals, not citarget=expected), never
/// of a compact file's pixel without buffers, the intervals with their estimates
/// (estimatesWithIntervals: any pixel) or alone (runIntervals: the pixels whose buffers are all
/// valid), after every pixel's estimate in a pass without removed light and plain-mean layers;
/// in a pass with no interval, no AOVs and no removed light, the estimates alone
/// (PixelKernel::estimates).
RunGiven takeRun(const EstimatePass& pass, size_t p0, int n, PixelScratch& w) {
    const PixelKernel& kernel = pass.kernel;
    if (!pass.ci && pass.A == 0 && !kernel.removedLight && kernel.estimates) {
        // No interval: the kernel's estimates of the whole run at once.
        w.runIntervalBuffers.resize(size_t(n));
        w.runIntervalOf.resize(size_t(n));
        for (int i = 0; i < n; ++i) {
            w.runIntervalBuffers[size_t(i)] = pass.src.pixelBuffers(p0 + size_t(i));
            w.runIntervalOf[size_t(i)] = i;
        }
        w.runEstimates.resize(size_t(n));
        kernel.estimates(w.runIntervalBuffers.data(), n, w.runEstimates.data());
        return RunGiven::Estimates;
    }
    const bool withEstimates = bool(kernel.estimatesWithIntervals);
    if (!pass.ci || pass.A > 0 || kernel.ciExpected || (!kernel.runIntervals && !withEstimates))
        return RunGiven::Nothing;
    w.runIntervalBuffers.resize(size_t(n));
    w.runIntervalOf.assign(size_t(n), -1);
    w.runIntervals.resize(3 * size_t(n));
    int taken = 0;
    // Pixel i of the run goes to the kernel as the next one taken when it is to be given an
    // interval (runIntervals: only where its buffers are all valid).
    auto take = [&](int i) {
        const size_t p = p0 + size_t(i);
        const PixelBuffers pb = pass.src.pixelBuffers(p);
        if ((!withEstimates && !allBuffersValid(pb)) || pass.src.meanOnlySpread(p)) return;
        // Field by field from the registers: push_back(pb) stored pb on the stack in halves and
        // read it back whole, a failed store forwarding on every pixel (6 % of the mean's :ci).
        PixelBuffers& to = w.runIntervalBuffers[size_t(taken)];
        to.mean = pb.mean;
        to.count = pb.count;
        to.M = pb.M;
        w.runIntervalOf[size_t(i)] = taken++;
    };
    if (withEstimates) {  // estimatesWithIntervals asks for the buffers ahead itself
        for (int i = 0; i < n; ++i) take(i);
        w.runEstimates.resize(size_t(taken));
        kernel.estimatesWithIntervals(w.runIntervalBuffers.data(), taken, kernel.ciLevel,
                                      w.runEstimates.data(), w.runIntervals.data());
        return RunGiven::EstimatesAndIntervals;
    }
    // kChunk pixels at a time: their estimates where the pass allows, their validity tests, then
    // their intervals. The first of these reads the buffers from memory. The estimates ask for
    // the pixel kPrefetchPixels on, as in a pass without intervals, and the tests and intervals
    // then read the buffers from cache (first in a run of tests, the reads overlapped little
    // computation: G-MoN's and TMPE's :ci spent some 10 % of their time waiting on them). Without
    // estimates the tests ask for the next kChunk pixels.
    const bool estimatesFirst = !kernel.removedLight && !kernel.plainMeanLayers;
    if (estimatesFirst) w.runEstimates.resize(size_t(n));
    constexpr int kChunk = 8;
    for (int c0 = 0; c0 < n; c0 += kChunk) {
        const int c1 = std::min(n, c0 + kChunk), first = taken;
        if (estimatesFirst)
            for (int i = c0; i < c1; ++i) {
                const size_t p = p0 + size_t(i);
                prefetchAhead(pass.src, p);
                kernel.estimate(pass.src.pixelBuffers(p), w.runEstimates[size_t(i)], w.scratch);
            }
        for (int i = c0; i < c1; ++i) {
            if (!estimatesFirst) prefetchAhead(pass.src, p0 + size_t(i), kChunk);
            take(i);
        }
        if (taken > first)
            kernel.runIntervals(w.runIntervalBuffers.data() + first, taken - first, kernel.ciLevel,
                                w.runIntervals.data() + 3 * size_t(first));
    }
    return estimatesFirst ? RunGiven::EstimatesThenIntervals : RunGiven::Intervals;
}

/// Pixels x0 to x1 of row y: first what takeRun takes of them (their intervals, and with them or
/// before them their estimates), then each pixel; with the removed light, eight pixels at a time,
/// then their luminance spreads, from the buffers' luminances the estimates left where they did
/// (lumaSpread8FromKeys), else from the buffers (lumaSpreads), then their removed-light values. The
/// run is short enough that its buffers are still in cache for the estimates. False as
/// estimatePixel.
bool estimateRun(const EstimatePass& pass, int y, int x0, int x1, const ROI& roi, float* base,
                 PixelScratch& w) {
    const StatsHeader& h = pass.src.header;
    const PixelKernel& kernel = pass.kernel;
    const size_t nch = pass.names.size();
    const size_t row = size_t(y - h.originY) * size_t(h.width);
    const RunGiven given = takeRun(pass, row + size_t(x0 - h.originX), x1 - x0, w);
    auto pixelOut = [&](int x) {
        return base + (size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin)) * nch;
    };
    bool weighted = true;
    // A pixel whose estimate the run gave has no other per-pixel work in a pass without AOVs and
    // plain-mean layers: its layers are written straight from the run's results (the mean's :ci
    // spent 8 % of its time in estimatePixel's general path).
    const bool givenWhole = pass.A == 0 && !kernel.plainMeanLayers;
    auto one = [&](int x) {
        const size_t p = row + size_t(x - h.originX);
        const int iv = given != RunGiven::Nothing ? w.runIntervalOf[size_t(x - x0)] : -1;
        const ValueInterval* interval = iv >= 0 && given != RunGiven::Estimates
                                            ? w.runIntervals.data() + 3 * size_t(iv)
                                            : nullptr;
        const PixelEstimate* estimate =
            given == RunGiven::EstimatesThenIntervals ? w.runEstimates.data() + (x - x0)
            : iv >= 0 && (given == RunGiven::EstimatesAndIntervals || given == RunGiven::Estimates)
                ? w.runEstimates.data() + iv
                : nullptr;
        if (estimate && givenWhole && (interval || !pass.ci)) {
            writeEstimateLayers(pass, pixelOut(x), *estimate, interval);
            return;
        }
        if (!estimate) prefetchAhead(pass.src, p);  // while this one is estimated
        if (!estimatePixel(pass, p, pixelOut(x), w, interval, estimate)) weighted = false;
    };
    if (!kernel.removedLight) {
        for (int x = x0; x < x1; ++x) one(x);
        return weighted;
    }
    // The keys' place is set field by field: a whole LumaKeys assigned from a temporary was
    // stored in parts and read back whole, a failed store forwarding on every pixel (perf put 5 %
    // of TMPE :removed's samples on those two loads). Only `key` tells an estimate to leave
    // them.
    EstimatorScratch::LumaKeys& keys = w.scratch.lumaKeys;
    keys.stride = kGroup;
    keys.luma = kernel.removedLuma;
    w.groupKeys.resize(kGroup * 64);
    w.groupCounts.resize(kGroup * 64);
    for (int g = x0; g < x1; g += kGroup) {
        const int k = std::min(kGroup, x1 - g);
        bool fromKeys = k == kGroup;
        for (int i = 0; i < k; ++i) {
            w.groupBuffers[i] = pass.src.pixelBuffers(row + size_t(g + i - h.originX));
            const int M = w.groupBuffers[i].M;
            fromKeys = fromKeys && M >= 2 && M <= 64 && M == w.groupBuffers[0].M;
            keys.key = fromKeys ? w.groupKeys.data() + i : nullptr;
            keys.count = fromKeys ? w.groupCounts.data() + i : nullptr;
            keys.given = false;
            one(g + i);
            fromKeys = fromKeys && keys.given;
        }
        keys.key = keys.count = nullptr;
        keys.given = false;
        if (fromKeys)
            lumaSpread8FromKeys(w.groupKeys.data(), w.groupCounts.data(), w.groupBuffers[0].M,
                                w.groupSpreads);
        else
            lumaSpreads(w.groupBuffers, k, kernel.removedLuma, w.groupSpreads);
        for (int i = 0; i < k; ++i) {
            float* px = pixelOut(g + i);
            removedLightPixel(px, float(w.groupSpreads[i].mean), float(w.groupSpreads[i].se),
                              kernel.removedLuma, px + pass.firstRemoved);
        }
    }
    return weighted;
}

}  // namespace

bool estimate(ImageBuf& dst, const StatsImage& src, const Operation& est, const PixelKernel& kernel,
              bool diagnostics, ROI roi, int nthreads) {
    const StatsHeader& h = src.header;
    const ROI full = dataWindowROI(h);
    roi = prepareRoi(roi, full);
    if (!checkEstimateInput(dst, src, est, kernel)) return false;
    EstimatePass pass(src, kernel, diagnostics);
    resetKeepingStorage(dst, pass.spec(roi, est));

    // citarget=expected: every pixel's spread and its neighbourhood's, over the whole of `src`
    // (a streamed block carries cipool rows above and below: the same windows as the whole image).
    if (pass.ci && kernel.ciExpected) {
        pass.spreads = pixelSpreads(src, nthreads);
        pass.pooled =
            pooledSampleVariance(pass.spreads, h.width, h.height, kernel.ciPool, nthreads);
    }
    // Written straight into the local float buffer: ImageBuf::setpixel converts per call.
    float* const base = static_cast<float*>(dst.localpixels());
    std::atomic<bool> noWeights{false};
    OIIO::ImageBufAlgo::parallel_image(roi, nthreads, [&](ROI r) {
        PixelScratch w;
        w.scratch.wantWeights = pass.A > 0;
        constexpr int kRun = 64;  // pixels: 64 x 21 buffers of R, G, B and count are 21 KB
        for (int y = r.ybegin; y < r.yend; ++y)
            for (int x = r.xbegin; x < r.xend; x += kRun)
                if (!estimateRun(pass, y, x, std::min(x + kRun, r.xend), roi, base, w))
                    noWeights = true;
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

}  // namespace mcstat
