// The removed-light layers (removed_light_layers.h): the buffers' luminance mean and standard
// error through the estimate loop (in memory or streamed by blocks of rows, in parallel), then the
// per-pixel and neighbourhood tests of filters/removed_light.h.
#include "mcstat/image/removed_light_layers.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "mcstat/core/parallel.h"
#include "mcstat/filters/operation.h"
#include "mcstat/filters/registry.h"
#include "mcstat/filters/removed_light.h"
#include "mcstat/image/imageops.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;

namespace {

/// A per-pixel kernel whose R, G, B are the luminance mean of the valid buffers, its standard
/// error and the number of valid buffers: it runs through estimate(), which reads any source by
/// blocks and in parallel. Its buffer weights are the plain mean's, so that a file with AOVs
/// passes estimate()'s checks; the AOV channels it yields are not used.
PixelKernel spreadKernel(const std::array<double, 3>& luma) {
    PixelKernel k;
    k.mode = EstimatorMode::Luminance;
    k.estimate = [luma](const PixelBuffers& px, PixelEstimate& e, EstimatorScratch& s) {
        const LumaSpread sp = lumaSpread(px, luma);
        e.rgb = {float(sp.mean), float(sp.se), float(sp.valid)};
        if (!s.wantWeights) return;
        s.bufferWeight.assign(size_t(px.M), 0.0);
        double n = 0.0;
        for (int j = 0; j < px.M; ++j)
            if (isValidBuffer(px, j)) n += (s.bufferWeight[size_t(j)] = double(px.count[j]));
        if (n > 0.0)
            for (double& w : s.bufferWeight) w /= n;
    };
    // Without weights (no AOVs), a run's spreads four pixels at a time (lumaSpreads).
    k.estimates = [luma](const PixelBuffers* px, int n, PixelEstimate* e) {
        LumaSpread sp[64];
        for (int i0 = 0; i0 < n; i0 += 64) {
            const int m = std::min(64, n - i0);
            lumaSpreads(px + i0, m, luma, sp);
            for (int i = 0; i < m; ++i) {
                e[i0 + i] = PixelEstimate{};
                e[i0 + i].rgb = {float(sp[i].mean), float(sp[i].se), float(sp[i].valid)};
            }
        }
    };
    return k;
}

template <class Source>
bool appendTo(ImageBuf& robust, Source& src, const std::array<double, 3>& luma,
              const RemovedLightOptions& opt, int nthreads) {
    if (opt.radius < 0 || !(opt.zLimit > 0.0) || !std::isfinite(opt.zLimit)) {
        robust.errorfmt("removed light: radius {} and z limit {}: need radius >= 0, z > 0",
                        opt.radius, opt.zLimit);
        return false;
    }
    const ROI roi = robust.roi();
    ImageBuf spread;
    if (!lumaSpreadImage(spread, src, luma, roi, nthreads)) {
        robust.errorfmt("removed light: {}", spread.geterror());
        return false;
    }
    const size_t n = roi.npixels();
    const int nin = robust.spec().nchannels;
    std::vector<float> in(n * size_t(nin)), sp(n * 3);
    robust.get_pixels(roi, OIIO::TypeDesc::FLOAT, in.data());
    spread.get_pixels(ROI(roi.xbegin, roi.xend, roi.ybegin, roi.yend, 0, 1, 0, 3),
                      OIIO::TypeDesc::FLOAT, sp.data());
    ImageSpec spec = robust.spec();
    for (const std::string& c : removedLightChannels()) spec.channelnames.push_back(c);
    spec.nchannels = nin + 5;
    spec.channelformats.clear();
    spec.format = OIIO::TypeDesc::FLOAT;
    ImageBuf out(spec, OIIO::InitializePixels::No);
    float* o = static_cast<float*>(out.localpixels());
    const size_t nout = size_t(spec.nchannels);
    // The same first step as the estimate's pass (removedLightPixel), in parallel per pixel.
    parallelFor(0, int64_t(n), 0, nthreads, [&](int64_t b, int64_t e) {
        for (size_t p = size_t(b); p < size_t(e); ++p) {
            float* px = o + p * nout;
            std::copy(in.data() + p * size_t(nin), in.data() + (p + 1) * size_t(nin), px);
            removedLightPixel(px, sp[3 * p], sp[3 * p + 1], luma, px + nin);
        }
    });
    if (!finishRemovedLight(out, nin, luma, opt, nthreads)) {
        robust.errorfmt("{}", out.geterror());
        return false;
    }
    robust = std::move(out);
    return true;
}

}  // namespace

bool lumaSpreadImage(ImageBuf& dst, const StatsImage& src, const std::array<double, 3>& luma,
                     ROI roi, int nthreads) {
    return estimate(dst, src, *findOperation("mean"), spreadKernel(luma), false, roi, nthreads);
}

bool lumaSpreadImage(ImageBuf& dst, StatsBlockSource& src, const std::array<double, 3>& luma,
                     ROI roi, int nthreads) {
    return estimate(dst, src, *findOperation("mean"), spreadKernel(luma), false, roi, nthreads);
}

bool appendRemovedLight(ImageBuf& robust, const StatsImage& src, const std::array<double, 3>& luma,
                        const RemovedLightOptions& opt, int nthreads) {
    return appendTo(robust, src, luma, opt, nthreads);
}

bool appendRemovedLight(ImageBuf& robust, StatsBlockSource& src, const std::array<double, 3>& luma,
                        const RemovedLightOptions& opt, int nthreads) {
    return appendTo(robust, src, luma, opt, nthreads);
}

}  // namespace mcstat
