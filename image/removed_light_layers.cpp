// The removed-light layers (removed_light_layers.h): the buffers' luminance mean and standard
// error through the estimate loop (in memory or streamed by blocks of rows, in parallel), then the
// per-pixel and neighbourhood tests of filters/removed_light.h.
#include "mcstat/image/removed_light_layers.h"

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
    std::vector<float> d(n), se(n), z(n), zlocal(n);
    // Per pixel in parallel (each pixel its own); the image's sums below in pixel order, so that
    // they do not depend on the thread count.
    parallelFor(0, int64_t(n), 0, nthreads, [&](int64_t b, int64_t e) {
        for (size_t p = size_t(b); p < size_t(e); ++p) {
            const float* rgb = in.data() + p * size_t(nin);
            const double y =
                luma[0] * double(rgb[0]) + luma[1] * double(rgb[1]) + luma[2] * double(rgb[2]);
            const double dp = double(sp[3 * p]) - y;
            d[p] = std::isfinite(dp) ? float(dp) : 0.f;
            se[p] = sp[3 * p + 1];
            z[p] = float(removedZ(d[p], se[p]));
        }
    });
    double removed = 0.0, total = 0.0, variance = 0.0;
    for (size_t p = 0; p < n; ++p) {
        const float* rgb = in.data() + p * size_t(nin);
        const double y =
            luma[0] * double(rgb[0]) + luma[1] * double(rgb[1]) + luma[2] * double(rgb[2]);
        const double dp = double(sp[3 * p]) - y;
        if (std::isfinite(dp) && std::isfinite(se[p])) {
            removed += dp;
            variance += double(se[p]) * double(se[p]);
        }
        if (std::isfinite(sp[3 * p])) total += double(sp[3 * p]);
    }
    localRemovedZ(d.data(), se.data(), roi.width(), roi.height(), opt.radius, zlocal.data(),
                  nthreads);
    double significant = 0.0;
    for (size_t p = 0; p < n; ++p)
        if (zlocal[p] > opt.zLimit) significant += double(d[p]);

    const std::vector<std::string> names = {"Y", "se", "z", "zlocal", "significant"};
    ImageSpec spec = robust.spec();
    for (const std::string& c : names) spec.channelnames.push_back(kRemovedPrefix + c);
    spec.nchannels = nin + int(names.size());
    spec.channelformats.clear();
    spec.format = OIIO::TypeDesc::FLOAT;
    spec.attribute("mcstat:removed:energyFraction", float(total != 0.0 ? removed / total : 0.0));
    spec.attribute("mcstat:removed:significantFraction",
                   float(removed != 0.0 ? significant / removed : 0.0));
    // The whole image as one window: light spread thin over many pixels (fireflies everywhere)
    // is no region's, yet real in sum.
    spec.attribute("mcstat:removed:zImage", float(removedZ(removed, std::sqrt(variance))));
    spec.attribute("mcstat:removed:radius", opt.radius);
    spec.attribute("mcstat:removed:zLimit", float(opt.zLimit));
    ImageBuf out(spec, OIIO::InitializePixels::No);
    float* o = static_cast<float*>(out.localpixels());
    const size_t nout = size_t(spec.nchannels);
    parallelFor(0, int64_t(n), 0, nthreads, [&](int64_t b, int64_t e) {
        for (size_t p = size_t(b); p < size_t(e); ++p) {
            float* px = o + p * nout;
            std::copy(in.data() + p * size_t(nin), in.data() + (p + 1) * size_t(nin), px);
            px[nin] = d[p];
            px[nin + 1] = se[p];
            px[nin + 2] = z[p];
            px[nin + 3] = zlocal[p];
            px[nin + 4] = zlocal[p] > opt.zLimit ? 1.f : 0.f;
        }
    });
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
