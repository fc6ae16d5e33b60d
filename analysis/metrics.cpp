// Image-comparison metrics (see include/mcstat/analysis/metrics.h and docs/metrics.md).
#include "mcstat/analysis/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "mcstat/core/color_space.h"

namespace mcstat {

namespace {

constexpr int kRadius = 5;  // 11x11 window
constexpr double kSigma = 1.5;

double clamp01(double v) { return std::clamp(v, 0.0, 1.0); }

}  // namespace

double ssimChannel(const float* a, const float* b, size_t stride, int width, int height,
                   const bool* mask) {
    // Separable Gaussian sums of a, b, a^2, b^2, ab, and of the weights (for border
    // renormalisation).
    double g[2 * kRadius + 1];
    for (int i = -kRadius; i <= kRadius; ++i)
        g[i + kRadius] = std::exp(-0.5 * i * i / (kSigma * kSigma));
    const size_t n = size_t(width) * size_t(height);
    const int kFields = 6;  // w, a, b, aa, bb, ab
    std::vector<double> rows(n * kFields, 0.0), full(n * kFields, 0.0);
    auto val = [&](const float* img, size_t p) { return clamp01(double(img[p * stride])); };
    auto ok = [&](size_t p) { return mask == nullptr || mask[p]; };
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            double* acc = &rows[(size_t(y) * width + x) * kFields];
            for (int d = -kRadius; d <= kRadius; ++d) {
                const int xx = x + d;
                if (xx < 0 || xx >= width) continue;
                const size_t p = size_t(y) * width + xx;
                if (!ok(p)) continue;
                const double w = g[d + kRadius], va = val(a, p), vb = val(b, p);
                acc[0] += w;
                acc[1] += w * va;
                acc[2] += w * vb;
                acc[3] += w * va * va;
                acc[4] += w * vb * vb;
                acc[5] += w * va * vb;
            }
        }
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            double* acc = &full[(size_t(y) * width + x) * kFields];
            for (int d = -kRadius; d <= kRadius; ++d) {
                const int yy = y + d;
                if (yy < 0 || yy >= height) continue;
                const double* r = &rows[(size_t(yy) * width + x) * kFields];
                for (int f = 0; f < kFields; ++f) acc[f] += g[d + kRadius] * r[f];
            }
        }
    const double C1 = 0.01 * 0.01, C2 = 0.03 * 0.03;  // (K L)^2 with dynamic range L = 1
    double sum = 0.0;
    long count = 0;
    for (size_t p = 0; p < n; ++p) {
        if (!ok(p)) continue;
        const double* f = &full[p * kFields];
        if (!(f[0] > 0.0)) continue;
        const double ma = f[1] / f[0], mb = f[2] / f[0];
        const double va = std::max(0.0, f[3] / f[0] - ma * ma);
        const double vb = std::max(0.0, f[4] / f[0] - mb * mb);
        const double cov = f[5] / f[0] - ma * mb;
        sum += ((2 * ma * mb + C1) * (2 * cov + C2)) / ((ma * ma + mb * mb + C1) * (va + vb + C2));
        ++count;
    }
    return count ? sum / double(count) : 1.0;
}

void detailSums(const float* a, const float* b, size_t stride, int width, int height,
                const bool* mask, double& cross, double& refPower) {
    auto ok = [&](size_t p) { return mask == nullptr || mask[p]; };
    auto val = [&](const float* img, size_t p) { return clamp01(double(img[p * stride])); };
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const size_t p = size_t(y) * width + x;
            if (!ok(p)) continue;
            double sa = 0.0, sb = 0.0;
            int n = 0;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int xx = x + dx, yy = y + dy;
                    if (xx < 0 || yy < 0 || xx >= width || yy >= height) continue;
                    const size_t q = size_t(yy) * width + xx;
                    if (!ok(q)) continue;
                    sa += val(a, q);
                    sb += val(b, q);
                    ++n;
                }
            const double ha = val(a, p) - sa / n, hb = val(b, p) - sb / n;
            cross += ha * hb;
            refPower += hb * hb;
        }
}

PixelError pixelError(const float* x, const float* r, const DiffOptions& opt) {
    PixelError e;
    for (int c = 0; c < 3; ++c)
        if (!std::isfinite(x[c]) || !std::isfinite(r[c])) return e;
    e.finite = true;
    for (int c = 0; c < 3; ++c) {
        const double xc = x[c], rc = r[c];
        e.relSum += (xc - rc) * (xc - rc) / (rc * rc + opt.relmseEpsilon);
    }
    e.y = luminance(opt.luma, x);
    e.yRef = luminance(opt.luma, r);
    e.firefly = e.y > opt.fireflyRatio * e.yRef && e.y - e.yRef > opt.fireflyFloor;
    return e;
}

void errorMap(const float* lin, const float* ref, size_t npixels, const DiffOptions& opt,
              float* relerr, float* firefly) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (size_t p = 0; p < npixels; ++p) {
        const PixelError e = pixelError(lin + 3 * p, ref + 3 * p, opt);
        if (relerr) relerr[p] = e.finite ? float(e.relSum / 3.0) : nan;
        if (firefly) firefly[p] = e.finite ? (e.firefly ? 1.f : 0.f) : nan;
    }
}

DiffMetrics compareImages(const float* lin, const float* ref, const float* disp,
                          const float* refDisp, int width, int height, const DiffOptions& opt) {
    DiffMetrics m;
    const size_t n = size_t(width) * size_t(height);
    std::unique_ptr<bool[]> mask(new bool[n]);
    double rel = 0.0, se = 0.0, sumY = 0.0, sumYRef = 0.0;
    // Jung eq. 5.25 per pixel on luminance, kept for the two passes of eq. 5.26-5.27.
    std::vector<double> normErr;
    normErr.reserve(n);
    for (size_t p = 0; p < n; ++p) {
        // The scene-linear terms come from pixelError (shared with errorMap); the display values
        // must be finite too, for PSNR and SSIM.
        const PixelError e = pixelError(lin + 3 * p, ref + 3 * p, opt);
        bool ok = e.finite;
        for (int c = 0; c < 3; ++c)
            ok = ok && std::isfinite(disp[3 * p + c]) && std::isfinite(refDisp[3 * p + c]);
        mask[p] = ok;
        if (!ok) {
            ++m.nonFinite;
            continue;
        }
        ++m.pixels;
        rel += e.relSum;
        for (int c = 0; c < 3; ++c) {
            const double d = clamp01(disp[3 * p + c]) - clamp01(refDisp[3 * p + c]);
            se += d * d;
        }
        const double y = e.y, yr = e.yRef;
        sumY += y;
        sumYRef += yr;
        if (e.firefly) ++m.fireflies;
        if (std::abs(yr) < opt.normEpsilon) ++m.normFloored;
        normErr.push_back((y - yr) / std::max(std::abs(yr), opt.normEpsilon));  // eq. 5.25
    }
    if (m.pixels == 0) {
        m.relMSE = std::numeric_limits<double>::quiet_NaN();
        m.psnr = std::numeric_limits<double>::quiet_NaN();
        m.ssim = std::numeric_limits<double>::quiet_NaN();
        m.normBias = std::numeric_limits<double>::quiet_NaN();
        m.normNoise = std::numeric_limits<double>::quiet_NaN();
        m.detail = std::numeric_limits<double>::quiet_NaN();
        m.energy = std::numeric_limits<double>::quiet_NaN();
        return m;
    }
    m.relMSE = rel / double(3 * m.pixels);
    m.energy = sumYRef > 0.0 ? sumY / sumYRef - 1.0 : std::numeric_limits<double>::quiet_NaN();
    // Eq. 5.26 (bias: mean of E') and eq. 5.27 (noise: mean squared deviation of E' from the bias,
    // 1/N), two passes so the variance has no cancellation.
    double sumE = 0.0;
    for (double e : normErr) sumE += e;
    m.normBias = sumE / double(m.pixels);
    double sumD = 0.0;
    for (double e : normErr) sumD += (e - m.normBias) * (e - m.normBias);
    m.normNoise = sumD / double(m.pixels);
    const double mse = se / double(3 * m.pixels);
    m.psnr = mse > 0.0 ? 10.0 * std::log10(1.0 / mse) : std::numeric_limits<double>::infinity();
    double s = 0.0;
    for (int c = 0; c < 3; ++c)
        s += ssimChannel(disp + c, refDisp + c, 3, width, height, mask.get());
    m.ssim = s / 3.0;
    double cross = 0.0, refPower = 0.0;
    for (int c = 0; c < 3; ++c)
        detailSums(disp + c, refDisp + c, 3, width, height, mask.get(), cross, refPower);
    // A reference without any detail (flat, or clamped flat) leaves the slope undefined.
    m.detail = refPower > 0.0 ? cross / refPower : std::numeric_limits<double>::quiet_NaN();
    return m;
}

}  // namespace mcstat
