// The removed light given back over a statistics file (include/mcstat/image/keep_light_image.h):
// the plain mean and the buffers' luminance spread in one estimate() pass (in memory or streamed
// by blocks of rows, in parallel), then filters/keep_light.h's choice of scale and return.
#include "mcstat/image/keep_light_image.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "mcstat/core/float_rounding.h"
#include "mcstat/core/parallel.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/removed_light_pass.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ROI;

namespace {

const StatsHeader& headerOf(const StatsImage& s) { return s.header; }
const StatsHeader& headerOf(const StatsBlockSource& s) { return s.header(); }

/// The guide of the return (keep_light.h): the first hit's albedo as luminance, >= 0, so that
/// irradiance goes back and the surface's texture multiplies it, and nothing goes where no surface
/// was hit (albedo 0). Empty when the file keeps no albedo (renders ingested without one): the
/// tent alone then.
bool albedoGuide(const StatsImage& s, const std::array<double, 3>& luma, std::vector<float>& g,
                 std::string&) {
    g.clear();
    if (!(s.header.features & kFeatureAlbedo) || s.albedo.size() != 3 * s.pixelCount()) return true;
    g.resize(s.pixelCount());
    for (size_t p = 0; p < g.size(); ++p) {
        const double y = luma[0] * double(s.albedo[3 * p]) + luma[1] * double(s.albedo[3 * p + 1]) +
                         luma[2] * double(s.albedo[3 * p + 2]);
        g[p] = std::isfinite(y) && y > 0.0 ? float(y) : 0.f;
    }
    return true;
}

bool albedoGuide(StatsBlockSource& src, const std::array<double, 3>& luma, std::vector<float>& g,
                 std::string& err) {
    g.clear();
    const StatsHeader& h = src.header();
    if (!(h.features & kFeatureAlbedo)) return true;
    const int rows = src.blockRows(kStatsPartFeatures);
    StatsImage block;
    std::vector<float> part;
    for (int y = 0; y < h.height; y += rows) {
        const int n = std::min(rows, h.height - y);
        if (!src.read(y, n, kStatsPartFeatures, block, err)) return false;
        if (!albedoGuide(block, luma, part, err)) return false;
        if (part.empty()) {  // this block kept no albedo: no guide at all
            g.clear();
            return true;
        }
        g.insert(g.end(), part.begin(), part.end());
    }
    return true;
}

/// The plain mean (the "mean" estimator's result, AOVs included) and, in the same pass over the
/// buffers, their luminance spread: the removed-light layers' per-pixel step
/// (removed_light_pass.h), whose channels kPixelStepLumaMean and kPixelStepSe from
/// `spreadChannel` on hold the buffers' luminance mean and its standard error, the same floats
/// as lumaSpreadImage's (removed_light_layers.h). One read of every buffer instead of two.
template <class Source>
bool meanWithSpread(ImageBuf& dst, Source& src, const std::array<double, 3>& luma, ROI roi,
                    int nthreads, int& spreadChannel) {
    const Operation& mean = *findOperation("mean");
    PixelKernel kernel = mean.bindPixel(ParamValues(), luma);
    kernel.removedLight = true;
    kernel.removedLuma = luma;
    if (!estimate(dst, src, mean, kernel, false, roi, nthreads)) return false;
    spreadChannel = dst.spec().channelindex(removedLightChannels()[0]);
    if (spreadChannel < 3) {
        dst.errorfmt("the plain mean's pass gave no luminance spread");
        return false;
    }
    return true;
}

/// The plain mean and its luminance spread that the operation's own pass appended to `robust`
/// (PixelKernel::plainMeanLayers and the removed-light layers' per-pixel step: apply_operation.cpp)
/// moved into `mean` as meanWithSpread gives them (R, G, B, the AOVs, then the step's channels
/// from `spreadChannel` on), and taken off `robust`, which keeps exactly the operation's
/// channels. False, with nothing changed, when `robust` holds no such layers. Plain copies, rows
/// in parallel.
bool takePassLayers(ImageBuf& robust, ImageBuf& mean, int& spreadChannel, int nthreads) {
    const OIIO::ImageSpec& rs = robust.spec();
    if (rs.nchannels < 3 || rs.format != OIIO::TypeDesc::FLOAT || !robust.localpixels())
        return false;
    const std::vector<std::string> step = removedLightChannels();
    const int firstStep = rs.channelindex(step[0]);
    const int firstMean = rs.channelindex(kPlainMeanPrefix + rs.channelnames[0]);
    if (firstStep < 3 || firstMean != firstStep + int(step.size())) return false;
    // mean: the plain mean's channels under their own names, then the step's.
    std::vector<int> order;
    OIIO::ImageSpec ms(rs.width, rs.height, 0, OIIO::TypeDesc::FLOAT);
    ms.x = rs.x;
    ms.y = rs.y;
    for (int c = firstMean; c < rs.nchannels; ++c) {
        order.push_back(c);
        ms.channelnames.push_back(rs.channelnames[size_t(c)].substr(std::strlen(kPlainMeanPrefix)));
    }
    spreadChannel = int(order.size());
    for (size_t i = 0; i < step.size(); ++i) {
        order.push_back(firstStep + int(i));
        ms.channelnames.push_back(step[i]);
    }
    ms.nchannels = int(order.size());
    // robust: its own channels, spec and metadata as they were (alpha and depth come before).
    OIIO::ImageSpec ks = rs;
    ks.nchannels = firstStep;
    ks.channelnames.resize(size_t(firstStep));
    ks.channelformats.clear();
    ImageBuf kept(ks, OIIO::InitializePixels::No);
    mean.reset(ms, OIIO::InitializePixels::No);
    const size_t nin = size_t(rs.nchannels), nk = size_t(firstStep), nm = order.size();
    const float* src = static_cast<const float*>(robust.localpixels());
    float* kp = static_cast<float*>(kept.localpixels());
    float* mp = static_cast<float*>(mean.localpixels());
    parallelFor(0, rs.height, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (size_t p = size_t(yb) * size_t(rs.width); p < size_t(ye) * size_t(rs.width); ++p) {
            const float* q = src + p * nin;
            std::copy(q, q + nk, kp + p * nk);
            for (size_t i = 0; i < nm; ++i) mp[p * nm + i] = q[order[i]];
        }
    });
    robust = std::move(kept);
    return true;
}

template <class Source>
bool keepLightTo(ImageBuf& robust, Source& src, const std::array<double, 3>& luma,
                 const KeepLightParams& params, int nthreads) {
    if (!(params.gamma > 0.0) || !std::isfinite(params.gamma) || params.maxRadius < 0 ||
        params.maxRadius > 1024) {
        robust.errorfmt("keeplight: gamma {} and radius {}: need gamma > 0, radius in [0, 1024]",
                        params.gamma, params.maxRadius);
        return false;
    }
    // The plain mean and its spread from the operation's own pass where it gave them, else from
    // a pass of their own.
    ImageBuf mean;
    int spreadChannel = 0;
    const bool taken = takePassLayers(robust, mean, spreadChannel, nthreads);
    const OIIO::ImageSpec& rs = robust.spec();
    if (rs.nchannels < 3 || rs.format != OIIO::TypeDesc::FLOAT || !robust.localpixels()) {
        robust.errorfmt("keeplight: the result is not a float image with R, G, B first");
        return false;
    }
    const ROI roi = robust.roi();
    if (!taken && !meanWithSpread(mean, src, luma, roi, nthreads, spreadChannel)) {
        robust.errorfmt("keeplight: {}", mean.geterror());
        return false;
    }
    std::vector<int> meanIndex;
    // The beauty and every AOV but the labels, as appendResidual picks them.
    const std::vector<int> from = residualChannels(rs, mean.spec(), headerOf(src), meanIndex);
    const int width = roi.width(), height = roi.height();
    // The removed-light channels of the mean's pass (after its R, G, B and AOVs) are not
    // residual channels: residualChannels matches the result's channels by name.
    const size_t n = roi.npixels(), nc = from.size(), nin = size_t(rs.nchannels),
                 nm = size_t(mean.nchannels());
    float* rp = static_cast<float*>(robust.localpixels());
    const float* mp = static_cast<const float*>(mean.localpixels());
    const float* sp = mp + spreadChannel;  // pixel p's removed-light step at sp + nm * p
    std::vector<float> values(n * nc), d(n), se(n);
    std::vector<double> residual(n * nc);
    std::vector<uint8_t> active(n, 0), scale(n);
    // Per pixel, in parallel; the luminance sum of the plain mean by rows, then summed in row
    // order (the same bits at any thread count).
    std::vector<double> rowMeanY(size_t(height), 0.0);
    parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (size_t y = size_t(yb); y < size_t(ye); ++y) {
            double rowY = 0.0;
            for (size_t p = y * size_t(width); p < (y + 1) * size_t(width); ++p) {
                double dy = 0.0;
                for (size_t i = 0; i < nc; ++i) {
                    const float r = rp[p * nin + size_t(from[i])];
                    const float m = mp[p * nm + size_t(meanIndex[i])];
                    // A difference within float rounding of the two values is no light: the mean
                    // and an estimator that trims nothing may sum the same buffers in other
                    // orders.
                    const double v = withinFloatRounding(m, r) ? 0.0 : double(m) - double(r);
                    values[p * nc + i] = r;
                    residual[p * nc + i] = v;
                    if (v != 0.0 && std::isfinite(v)) active[p] = 1;
                    if (from[i] < 3 && std::isfinite(v)) dy += luma[size_t(from[i])] * v;
                }
                // The luminance residual and its scale, the plain mean's standard error from the
                // buffers. A pixel that lost nothing counts as an exact 0 (se 0): the estimator
                // kept its mean, and a compact file, which keeps no buffers there, gives the same
                // choice.
                d[p] = float(dy);
                const float* step = sp + nm * p;
                se[p] = active[p] ? step[kPixelStepSe] : 0.f;
                if (std::isfinite(step[kPixelStepLumaMean]))
                    rowY += double(step[kPixelStepLumaMean]);
            }
            rowMeanY[y] = rowY;
        }
    });
    double meanY = 0.0;
    for (double v : rowMeanY) meanY += v;
    keepLightScales(d.data(), se.data(), active.data(), width, height, params, scale.data(),
                    nthreads);
    const std::vector<int> radii = keepLightRadii(params.maxRadius);
    std::vector<float> guide, out(n * nc);
    std::string err;
    if (!albedoGuide(src, luma, guide, err)) {
        robust.errorfmt("keeplight: {}", err);
        return false;
    }
    // No guide where it holds no surface at all (albedo 0 everywhere): the tent alone then.
    if (guide.size() != n ||
        std::all_of(guide.begin(), guide.end(), [](float g) { return g == 0.f; }))
        guide.clear();
    // A supported cluster's light goes where its own light was found (keep_light.h).
    const std::vector<float> cluster = keepLightClusterGuide(d.data(), width, height, nthreads);
    returnResidual(values.data(), residual.data(), scale.data(), radii, width, height, int(nc),
                   out.data(), nthreads, guide.empty() ? nullptr : guide.data(), cluster.data());
    double returnedY = 0.0;
    for (size_t p = 0; p < n; ++p) {
        double y = 0.0;
        for (size_t i = 0; i < nc; ++i) {
            if (from[i] < 3) {
                const double v = residual[p * nc + i];
                if (std::isfinite(v)) y += luma[size_t(from[i])] * v;
            }
            rp[p * nin + size_t(from[i])] = out[p * nc + i];
        }
        returnedY += y;
    }
    robust.specmod().attribute("mcstat:keeplight:returned",
                               float(meanY != 0.0 ? returnedY / meanY : 0.0));
    robust.specmod().attribute("mcstat:keeplight:gamma", float(params.gamma));
    robust.specmod().attribute("mcstat:keeplight:maxRadius", params.maxRadius);
    return true;
}

}  // namespace

std::vector<ParamSpec> keepLightModifiers() {
    return {flagParam("keeplight", "0",
                      "1 gives the removed light back, all of it, where the evidence puts it: "
                      "each pixel's residual spread by a window the data choose "
                      "(docs/keep-light.md)"),
            realParam("keeplightgamma", 0.0, 100.0, true, "",
                      "with keeplight=1: the scale choice's threshold in standard errors "
                      "(default 3; larger spreads wider)"),
            intParam("keeplightradius", 0, 1024, "",
                     "with keeplight=1: the largest window radius in pixels (default 32)")};
}

bool takeKeepLightModifiers(const std::string& context, std::map<std::string, std::string>& mods,
                            ParamValues& out, std::string& err) {
    ParamValues given;
    if (!takeModifiers(context, keepLightModifiers(), mods, given, err)) return false;
    const bool on = given.count("keeplight") && given.at("keeplight").integer != 0;
    for (const char* k : {"keeplightgamma", "keeplightradius"})
        if (given.count(k) && !on) {
            err = context + ": " + k + " needs keeplight=1";
            return false;
        }
    if (on)
        for (const auto& [k, v] : given) out[k] = v;
    return true;
}

std::string keepLightRefusal(const Operation& op, const ParamValues& values) {
    if (!keepLightAsked(values)) return {};
    if (takesImage(op) || readsSamples(op))
        return op.name + ": keeplight is for estimators and 3D filters over a statistics file";
    if (values.count("ci"))
        return op.name +
               ": keeplight and ci: the interval is the robust estimate's, not the image's with "
               "the light given back; ask for one of them";
    return {};
}

bool keepLightAsked(const ParamValues& values) {
    const auto it = values.find("keeplight");
    return it != values.end() && it->second.integer != 0;
}

KeepLightParams keepLightParams(const ParamValues& values) {
    KeepLightParams p;
    if (const auto it = values.find("keeplightgamma"); it != values.end())
        p.gamma = it->second.real;
    if (const auto it = values.find("keeplightradius"); it != values.end())
        p.maxRadius = int(it->second.integer);
    return p;
}

bool keepLight(ImageBuf& robust, const StatsImage& src, const std::array<double, 3>& luma,
               const KeepLightParams& params, int nthreads) {
    return keepLightTo(robust, src, luma, params, nthreads);
}

bool keepLight(ImageBuf& robust, StatsBlockSource& src, const std::array<double, 3>& luma,
               const KeepLightParams& params, int nthreads) {
    return keepLightTo(robust, src, luma, params, nthreads);
}

}  // namespace mcstat
