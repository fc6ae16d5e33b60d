// The removed light given back over a statistics file (include/mcstat/image/keep_light_image.h):
// the plain mean and the buffers' luminance spread from the operation's own pass (or from a pass
// of their own, a band of rows at a time), then filters/keep_light_stream.h's choice of scale and
// return by bands of rows, written into the result as each band is done: beside the result, the
// memory held is a few bands of rows, whatever the image's height.
#include "mcstat/image/keep_light_image.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "mcstat/core/color_space.h"
#include "mcstat/core/float_rounding.h"
#include "mcstat/core/parallel.h"
#include "mcstat/filters/keep_light_stream.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/removed_light_pass.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ROI;

namespace {

const StatsHeader& headerOf(const StatsImage& s) { return s.header; }
const StatsHeader& headerOf(const StatsBlockSource& s) { return s.header(); }

/// The guide of the return (keep_light.h) at the pixels of `s` from index p0, n of them, into g:
/// the first hit's albedo as luminance, >= 0, so that irradiance goes back and the surface's
/// texture multiplies it, and nothing goes where no surface was hit (albedo 0).
void albedoLuma(const StatsImage& s, size_t p0, size_t n, const std::array<double, 3>& luma,
                float* g) {
    if (s.albedo.size() < 3 * (p0 + n)) {  // a block that kept no albedo: no surface to guide
        std::fill(g, g + n, 0.f);
        return;
    }
    for (size_t i = 0; i < n; ++i) {
        const float* a = s.albedo.data() + 3 * (p0 + i);
        const double y = luminance(luma, a);
        g[i] = std::isfinite(y) && y > 0.0 ? float(y) : 0.f;
    }
}

/// Whether the file keeps an albedo to guide the return with (renders ingested without one: the
/// tent alone).
bool hasAlbedo(const StatsImage& s) {
    return (s.header.features & kFeatureAlbedo) && s.albedo.size() == 3 * s.pixelCount();
}
bool hasAlbedo(StatsBlockSource& src) { return src.header().features & kFeatureAlbedo; }

/// The guide of rows [y0, y1) (0-based in the data window) into g.
bool albedoRows(const StatsImage& s, int y0, int y1, const std::array<double, 3>& luma, float* g,
                std::string&) {
    const size_t w = size_t(s.header.width);
    albedoLuma(s, size_t(y0) * w, size_t(y1 - y0) * w, luma, g);
    return true;
}
bool albedoRows(StatsBlockSource& src, int y0, int y1, const std::array<double, 3>& luma, float* g,
                std::string& err) {
    StatsImage block;
    if (!src.read(y0, y1 - y0, kStatsPartFeatures, block, err)) return false;
    albedoLuma(block, 0, size_t(y1 - y0) * size_t(src.header().width), luma, g);
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

/// Where the operation's own pass put the plain mean and its luminance spread in its result
/// (PixelKernel::plainMeanLayers and the removed-light layers' per-pixel step): the step's
/// channels from firstStep on, then the plain mean's (R, G, B, the AOVs, each named
/// kPlainMeanPrefix + the result's name) from firstMean on. `names` are the plain mean's channel
/// names without the prefix. firstStep < 0 when the result holds no such layers.
struct PassLayers {
    int firstStep = -1, firstMean = -1;
    OIIO::ImageSpec names;
};

PassLayers passLayersOf(const OIIO::ImageSpec& rs) {
    PassLayers l;
    const std::vector<std::string> step = removedLightChannels();
    const int firstStep = rs.channelindex(step[0]);
    const int firstMean = rs.channelindex(kPlainMeanPrefix + rs.channelnames[0]);
    if (firstStep < 3 || firstMean != firstStep + int(step.size())) return l;
    l.firstStep = firstStep;
    l.firstMean = firstMean;
    for (int c = firstMean; c < rs.nchannels; ++c)
        l.names.channelnames.push_back(
            rs.channelnames[size_t(c)].substr(std::strlen(kPlainMeanPrefix)));
    l.names.nchannels = int(l.names.channelnames.size());
    return l;
}

/// The plain mean and its luminance spread of the rows being filled: pixel p's (index from the
/// rows' first) plain mean channel c at base[p * stride + c], its step's from `spread` on.
struct MeanRows {
    const float* base = nullptr;
    size_t stride = 0;
    int spread = 0;
};

/// The stream's inputs of rows [y0, y1) (keep_light_stream.h): each residual channel's plain mean
/// (at meanAt in `mean`) minus the result (at `from` in rp, nin channels per pixel, w pixels per
/// row), the luminance residual, the plain mean's standard error; and per row the plain mean's
/// luminance and the residual's, into rowMeanY[y] and rowReturnedY[y].
void residualRows(const float* rp, size_t nin, size_t w, const MeanRows& mean,
                  const std::vector<int>& from, const std::vector<int>& meanAt,
                  const std::array<double, 3>& luma, int y0, int y1, const KeepLightBandIn& in,
                  double* rowMeanY, double* rowReturnedY, int nthreads) {
    const size_t nc = from.size();
    parallelFor(y0, y1, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (size_t y = size_t(yb); y < size_t(ye); ++y) {
            double rowY = 0.0, returnedY = 0.0;
            for (size_t x = 0; x < w; ++x) {
                const size_t p = y * w + x, i0 = (y - size_t(y0)) * w + x;
                const float* m = mean.base + i0 * mean.stride;
                double dy = 0.0;
                bool active = false;
                for (size_t i = 0; i < nc; ++i) {
                    const float r = rp[p * nin + size_t(from[i])];
                    const float mv = m[meanAt[i]];
                    // A difference within float rounding of the two values is no light: the
                    // mean and an estimator that trims nothing may sum the same buffers in
                    // other orders.
                    const double v = withinFloatRounding(mv, r) ? 0.0 : double(mv) - double(r);
                    in.residual[i0 * nc + i] = v;
                    if (v != 0.0 && std::isfinite(v)) active = true;
                    if (from[i] < 3 && std::isfinite(v)) dy += luma[size_t(from[i])] * v;
                }
                // The luminance residual and its scale, the plain mean's standard error from
                // the buffers. A pixel that lost nothing counts as an exact 0 (se 0): the
                // estimator kept its mean, and a compact file, which keeps no buffers there,
                // gives the same choice.
                in.d[i0] = float(dy);
                const float* rgb = rp + p * nin;  // R, G, B first (returnByBands checks it)
                in.robustY[i0] = float(luminance(luma, rgb));
                in.active[i0] = active;
                const float* step = m + mean.spread;
                in.se[i0] = active ? step[kPixelStepSe] : 0.f;
                if (std::isfinite(step[kPixelStepLumaMean]))
                    rowY += double(step[kPixelStepLumaMean]);
                returnedY += dy;
            }
            rowMeanY[y] = rowY;
            rowReturnedY[y] = returnedY;
        }
    });
}

/// One band of rows [y0, y1) (0-based in the data window) of what the stream reads: the plain
/// mean and its luminance spread (`mean`, into `img`), and the names of the plain mean's channels,
/// the first at firstMean in a pixel (residualChannels matches them with the result's).
struct Band {
    int y0 = 0, y1 = 0;
    ImageBuf img;
    MeanRows mean;
    OIIO::ImageSpec meanNames;
    int firstMean = 0;
};

/// The stream's band height: keepLightBandRows, in whole chunks of a file, so that no chunk is
/// decoded for two bands.
int bandRowsOf(const StatsImage&, const KeepLightParams& p) { return keepLightBandRows(p); }
int bandRowsOf(StatsBlockSource& src, const KeepLightParams& p) {
    const int chunk = std::max(1, src.chunkRows());
    return (keepLightBandRows(p) + chunk - 1) / chunk * chunk;
}

/// The light given back to `robust`, the result over `roi` (the data window), by bands of rows
/// (keep_light_stream.h): makeBand(y0, y1, band, err) gives each band's plain mean and spread and,
/// where the result is computed band by band too, puts its rows into `robust` first.
template <class Source, class MakeBand>
bool returnByBands(ImageBuf& robust, Source& src, const std::array<double, 3>& luma,
                   const KeepLightParams& params, ROI roi, int nthreads, MakeBand makeBand) {
    if (!(params.gamma > 0.0) || !std::isfinite(params.gamma) || params.maxRadius < 0 ||
        params.maxRadius > 1024) {
        robust.errorfmt("keeplight: gamma {} and radius {}: need gamma > 0, radius in [0, 1024]",
                        params.gamma, params.maxRadius);
        return false;
    }
    const int width = roi.width(), height = roi.height(), bandRows = bandRowsOf(src, params);
    Band band;
    std::string err;
    if (!makeBand(0, std::min(bandRows, height), band, err)) {
        robust.errorfmt("keeplight: {}", err);
        return false;
    }
    const OIIO::ImageSpec& rs = robust.spec();
    if (rs.nchannels < 3 || rs.format != OIIO::TypeDesc::FLOAT || !robust.localpixels() ||
        rs.width != width || rs.height != height) {
        robust.errorfmt("keeplight: the result is not a float image with R, G, B first");
        return false;
    }
    // The residual channels (the beauty and every AOV but the labels, as appendResidual picks
    // them) and where each one's plain mean lies in a band's pixel.
    std::vector<int> meanAt;
    const std::vector<int> from = residualChannels(rs, band.meanNames, headerOf(src), meanAt);
    for (int& m : meanAt) m += band.firstMean;
    const size_t w = size_t(width), nin = size_t(rs.nchannels), nc = from.size();
    float* rp = static_cast<float*>(robust.localpixels());
    // Per row, summed in row order at the end: the same bits at any thread count.
    std::vector<double> rowMeanY(size_t(height), 0.0), rowReturnedY(size_t(height), 0.0);
    auto fill = [&](int y0, int y1, const KeepLightBandIn& in) {
        if ((band.y0 != y0 || band.y1 != y1) && !makeBand(y0, y1, band, err)) return false;
        residualRows(rp, nin, w, band.mean, from, meanAt, luma, y0, y1, in, rowMeanY.data(),
                     rowReturnedY.data(), nthreads);
        return !in.guide || albedoRows(src, y0, y1, luma, in.guide, err);
    };
    auto take = [&](int y0, int y1, const double* add) {
        parallelFor(y0, y1, 0, nthreads, [&](int64_t yb, int64_t ye) {
            for (size_t p = size_t(yb) * w; p < size_t(ye) * w; ++p)
                for (size_t i = 0; i < nc; ++i) {
                    float& r = rp[p * nin + size_t(from[i])];
                    r = withReturnedLight(r, add[(p - size_t(y0) * w) * nc + i]);
                }
        });
        return true;
    };
    if (!keepLightStream(width, height, int(nc), hasAlbedo(src), params, fill, take, nthreads,
                         bandRows)) {
        robust.errorfmt("keeplight: {}", err);
        return false;
    }
    double meanY = 0.0, returnedY = 0.0;
    for (size_t y = 0; y < size_t(height); ++y) {
        meanY += rowMeanY[y];
        returnedY += rowReturnedY[y];
    }
    robust.specmod().attribute("mcstat:keeplight:returned",
                               float(meanY != 0.0 ? returnedY / meanY : 0.0));
    robust.specmod().attribute("mcstat:keeplight:gamma", float(params.gamma));
    robust.specmod().attribute("mcstat:keeplight:maxRadius", params.maxRadius);
    return true;
}

/// keepLight: the result is given; each band's plain mean and spread from a pass of its own.
template <class Source>
bool keepLightTo(ImageBuf& robust, Source& src, const std::array<double, 3>& luma,
                 const KeepLightParams& params, int nthreads) {
    if (passLayersOf(robust.spec()).firstStep >= 0) {
        robust.errorfmt(
            "keeplight: the result holds its pass's plain mean layers; "
            "keepLightEstimate computes the estimate with them");
        return false;
    }
    const ROI roi = robust.roi();
    auto makeBand = [&](int y0, int y1, Band& b, std::string& err) {
        const ROI rows(roi.xbegin, roi.xend, roi.ybegin + y0, roi.ybegin + y1);
        int spread = 0;
        if (!meanWithSpread(b.img, src, luma, rows, nthreads, spread)) {
            err = b.img.geterror();
            return false;
        }
        b.y0 = y0;
        b.y1 = y1;
        b.mean = {static_cast<const float*>(b.img.localpixels()), size_t(b.img.nchannels()),
                  spread};
        b.meanNames = b.img.spec();
        b.firstMean = 0;
        return true;
    };
    return returnByBands(robust, src, luma, params, roi, nthreads, makeBand);
}

/// keepLightEstimate: the result too is computed band by band, its own pass giving the band's
/// plain mean and spread as layers that stay in the band.
template <class Source>
bool keepLightEstimateTo(ImageBuf& dst, Source& src, const Operation& op, const PixelKernel& kernel,
                         bool diagnostics, const std::array<double, 3>& luma,
                         const KeepLightParams& params, int nthreads) {
    const ROI roi = dataWindowROI(headerOf(src));
    bool allocated = false;
    auto makeBand = [&](int y0, int y1, Band& b, std::string& err) {
        const ROI rows(roi.xbegin, roi.xend, roi.ybegin + y0, roi.ybegin + y1);
        if (!estimate(b.img, src, op, kernel, diagnostics, rows, nthreads)) {
            err = b.img.geterror();
            return false;
        }
        const OIIO::ImageSpec& bs = b.img.spec();
        const PassLayers layers = passLayersOf(bs);
        if (layers.firstStep < 0 || bs.format != OIIO::TypeDesc::FLOAT) {
            err = op.name + ": the estimate's pass gave no plain mean";
            return false;
        }
        const size_t nin = size_t(bs.nchannels), nk = size_t(layers.firstStep),
                     w = size_t(roi.width());
        if (!allocated) {  // the result: the band's spec over every row, without the layers
            OIIO::ImageSpec spec = bs;
            spec.y = roi.ybegin;
            spec.height = roi.height();
            spec.nchannels = layers.firstStep;
            spec.channelnames.resize(nk);
            spec.channelformats.clear();
            dst.reset(spec, OIIO::InitializePixels::No);
            allocated = true;
        }
        const float* from = static_cast<const float*>(b.img.localpixels());
        float* to = static_cast<float*>(dst.localpixels()) + size_t(y0) * w * nk;
        parallelFor(0, y1 - y0, 0, nthreads, [&](int64_t yb, int64_t ye) {
            for (size_t p = size_t(yb) * w; p < size_t(ye) * w; ++p)
                std::copy(from + p * nin, from + p * nin + nk, to + p * nk);
        });
        b.y0 = y0;
        b.y1 = y1;
        b.mean = {from, nin, layers.firstStep};
        b.meanNames = layers.names;
        b.firstMean = layers.firstMean;
        return true;
    };
    return returnByBands(dst, src, luma, params, roi, nthreads, makeBand);
}

}  // namespace

std::vector<ParamSpec> keepLightModifiers() {
    return {flagParam("keeplight", "0",
                      "1 gives the removed light back, all of it, where the evidence puts it: "
                      "each pixel's residual spread by a window the data choose "
                      "(docs/keep-light.md)"),
            realParam("keeplightgamma", 0.0, 100.0, true, "",
                      "with keeplight=1: the scale choice's threshold in standard errors "
                      "(default 4; larger spreads wider)"),
            intParam("keeplightradius", 0, 1024, "",
                     "with keeplight=1: the largest window radius in pixels (default 64)")};
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

bool keepLightEstimate(ImageBuf& dst, const StatsImage& src, const Operation& op,
                       const PixelKernel& kernel, bool diagnostics,
                       const std::array<double, 3>& luma, const KeepLightParams& params,
                       int nthreads) {
    return keepLightEstimateTo(dst, src, op, kernel, diagnostics, luma, params, nthreads);
}

bool keepLightEstimate(ImageBuf& dst, StatsBlockSource& src, const Operation& op,
                       const PixelKernel& kernel, bool diagnostics,
                       const std::array<double, 3>& luma, const KeepLightParams& params,
                       int nthreads) {
    return keepLightEstimateTo(dst, src, op, kernel, diagnostics, luma, params, nthreads);
}

}  // namespace mcstat
