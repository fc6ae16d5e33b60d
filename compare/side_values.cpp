// What one side of a comparison holds per pixel (comparison.h): its buffers' values of a quantity,
// a compact pixel's stored spread, the reference image's value and variance, the R, G, B mean.
#include "comparison.h"
#include "mcstat/core/color_space.h"

namespace mcstat::detail {

void gatherBuffers(const Side& s, const Quantity& q, bool sideB, size_t p,
                   const std::array<double, 3>& luma, std::vector<double>& values,
                   std::vector<double>& counts) {
    const PixelBuffers pb = s.block.pixelBuffers(p);
    values.resize(size_t(pb.M));
    counts.resize(size_t(pb.M));
    const size_t k0 = s.block.bufferBegin(p);
    for (int j = 0; j < pb.M; ++j) {
        const float* m = pb.mean + size_t(j) * 3;
        double v = 0.0;
        switch (q.kind) {
            case Quantity::Luminance:
                v = luminance(luma, m);
                break;
            case Quantity::Channel:
                v = double(m[q.channel]);
                break;
            case Quantity::Aov:
                v = double(s.block.aov[(k0 + size_t(j)) * size_t(s.aovCount) +
                                       size_t(sideB ? q.aovB : q.aovA)]);
                break;
        }
        values[size_t(j)] = v;
        counts[size_t(j)] = double(pb.count[j]);
    }
}

bool compactSummary(const Side& s, const Quantity& q, size_t p, const std::array<double, 3>& luma,
                    SideSummary& out) {
    const float* sp = s.block.meanOnlySpread(p);
    if (!sp) return false;
    const PixelBuffers pb = s.block.pixelBuffers(p);
    std::array<double, 3> w{0.0, 0.0, 0.0};
    if (q.kind == Quantity::Channel)
        w[size_t(q.channel)] = 1.0;
    else
        w = luma;
    double est = 0.0, s2 = 0.0;
    for (int c = 0; c < 3; ++c) {
        est += w[size_t(c)] * double(pb.mean[c]);
        for (int d = 0; d < 3; ++d)
            s2 += w[size_t(c)] * w[size_t(d)] * double(sp[spreadIndex(c, d)]);
    }
    out = SideSummary();
    out.estimate = est;
    out.buffers = int(sp[0]);
    const double n = double(pb.count[0]);
    if (out.buffers >= 2 && n > 0.0 && std::isfinite(s2)) {
        out.df = double(out.buffers - 1);
        out.variance = std::max(0.0, s2) / n;
    }
    return true;
}

double referenceValue(const Side& s, const Quantity& q, int x, int y,
                      const std::array<double, 3>& luma) {
    const float* rgb = &s.refRGB[(size_t(y) * size_t(s.ref->roi().width()) + size_t(x)) * 3];
    if (q.kind == Quantity::Channel) return double(rgb[q.channel]);
    return luminance(luma, rgb);
}

double referenceVariance(const Side& s, const Quantity& q, int x, int y,
                         const std::array<double, 3>& luma) {
    const float* v = &s.refVar[(size_t(y) * size_t(s.ref->roi().width()) + size_t(x)) * 3];
    if (q.kind == Quantity::Channel) return double(v[q.channel]);
    return luma[0] * luma[0] * v[0] + luma[1] * luma[1] * v[1] + luma[2] * luma[2] * v[2];
}

void rgbMean(const Side& s, size_t local, int x, int y, float* out) {
    if (s.ref) {
        const float* rgb = &s.refRGB[(size_t(y) * size_t(s.ref->roi().width()) + size_t(x)) * 3];
        std::copy(rgb, rgb + 3, out);
        return;
    }
    const PixelBuffers pb = s.block.pixelBuffers(local);
    double sum[3] = {0.0, 0.0, 0.0}, n = 0.0;
    for (int j = 0; j < pb.M; ++j) {
        const double c = double(pb.count[j]);
        if (!(c > 0.0)) continue;
        for (int k = 0; k < 3; ++k) sum[k] += c * double(pb.mean[size_t(j) * 3 + size_t(k)]);
        n += c;
    }
    for (int k = 0; k < 3; ++k) out[k] = n > 0.0 ? float(sum[k] / n) : kNaNf;
}

}  // namespace mcstat::detail
