// Zirr, Hanika and Dachsbacher 2018, "Re-weighting Firefly Samples for Improved Finite-Sample
// Monte Carlo Estimates": the cascades and the reweighting
// (include/mcstat/filters/samples/cascade_reweighting.h; docs/reweighting.md).
#include "mcstat/filters/samples/cascade_reweighting.h"

#include <algorithm>
#include <cmath>

#include "mcstat/core/parallel.h"

namespace mcstat {

namespace {

constexpr int kMaxCascades = 16;

double lum(const std::array<double, 3>& w, const double* c) {
    return w[0] * c[0] + w[1] * c[1] + w[2] * c[2];
}

}  // namespace

bool validateReweightParams(const ReweightParams& p, std::string& err) {
    if (p.count < 2 || p.count > kMaxCascades) {
        err = "reweight: count must be an integer in [2, " + std::to_string(kMaxCascades) +
              "], not " + std::to_string(p.count);
        return false;
    }
    if (!(p.base > 1.0) || !std::isfinite(p.base)) {
        err = "reweight: base must be a number > 1";
        return false;
    }
    if (!(p.start > 0.0) || !std::isfinite(p.start) ||
        !std::isfinite(p.start * std::pow(p.base, p.count - 1))) {
        err = "reweight: start must be a number > 0 whose top scale start*base^(count-1) is finite";
        return false;
    }
    if (!(p.kappa > 0.0) || !std::isfinite(p.kappa)) {
        err = "reweight: kappa must be a number > 0";
        return false;
    }
    if (p.spread < 0 || p.spread > 64) {
        err = "reweight: spread must be an integer in [0, 64], not " + std::to_string(p.spread);
        return false;
    }
    for (double w : p.luma)
        if (!std::isfinite(w)) {
            err = "reweight: luma must be three finite weights";
            return false;
        }
    return true;
}

CascadeSplit splitSample(double y, const ReweightParams& p) {
    CascadeSplit s;
    double lower = p.start, upper = p.start * p.base;
    // The two cascades around y (split.cpp's search); the top pair takes everything above.
    while (!(y < upper) && s.lower < p.count - 2) {
        lower = upper;
        upper *= p.base;
        ++s.lower;
    }
    if (y <= lower)
        s.wLower = 1.0;
    else if (y < upper)
        s.wLower = std::max(0.0, (lower / y - lower / upper) / (1.0 - lower / upper));
    else
        s.wLower = 0.0;
    if (y < upper)
        s.wUpper = std::max(0.0, 1.0 - s.wLower);
    else
        s.wUpper = upper / y;  // beyond the top scale: clamped to it
    return s;
}

void splatSample(CascadePixel& px, const float rgb[3], const ReweightParams& p) {
    if (!std::isfinite(rgb[0]) || !std::isfinite(rgb[1]) || !std::isfinite(rgb[2])) {
        ++px.skipped;
        return;
    }
    const double c[3] = {double(rgb[0]), double(rgb[1]), double(rgb[2])};
    const double y = lum(p.luma, c);
    if (!std::isfinite(y)) {  // finite components, overflowing luminance (|rgb| ~ 1e38 * weights)
        ++px.skipped;
        return;
    }
    if (px.sum.size() != size_t(p.count) * 3) px.sum.assign(size_t(p.count) * 3, 0.0);
    const CascadeSplit s = splitSample(y, p);
    double* lo = px.sum.data() + size_t(s.lower) * 3;
    for (int k = 0; k < 3; ++k) {
        lo[k] += s.wLower * c[k];
        lo[3 + k] += s.wUpper * c[k];
    }
    ++px.n;
}

void scatterRemoved(int width, int height, int radius, size_t nch,
                    const std::vector<double>& removed, std::vector<double>& add, int nthreads) {
    add.assign(size_t(width) * size_t(height) * nch, 0.0);
    if (width <= 0 || height <= 0) return;
    // The windows' sides per column and row: pixel (x, y) shares its removed part among
    // span[x] * spanY[y] pixels, as 1 / that product.
    std::vector<int> spanX(static_cast<size_t>(width)), spanY(static_cast<size_t>(height));
    for (int x = 0; x < width; ++x)
        spanX[size_t(x)] = std::min(width - 1, x + radius) - std::max(0, x - radius) + 1;
    for (int y = 0; y < height; ++y)
        spanY[size_t(y)] = std::min(height - 1, y + radius) - std::max(0, y - radius) + 1;
    // Gathered, not scattered: pixel q sums the shares of the pixels whose windows hold it (those
    // within `radius` of it) in scanline order, the order in which a scatter over the pixels in
    // scanline order adds them, so every sum is the same bit for bit for any thread count.
    parallelFor(0, height, 1, nthreads, [&](int64_t yb, int64_t ye) {
        for (int qy = int(yb); qy < int(ye); ++qy)
            for (int qx = 0; qx < width; ++qx) {
                double* a = add.data() + (size_t(qy) * size_t(width) + size_t(qx)) * nch;
                const int y0 = std::max(0, qy - radius), y1 = std::min(height - 1, qy + radius);
                const int x0 = std::max(0, qx - radius), x1 = std::min(width - 1, qx + radius);
                for (int y = y0; y <= y1; ++y)
                    for (int x = x0; x <= x1; ++x) {
                        const size_t pix = size_t(y) * size_t(width) + size_t(x);
                        const double share = 1.0 / double(spanX[size_t(x)] * spanY[size_t(y)]);
                        for (size_t k = 0; k < nch; ++k) a[k] += share * removed[pix * nch + k];
                    }
            }
    });
}

void sampleShares(double y, const ReweightParams& p, const double* w, double& kept, double& taken) {
    const CascadeSplit s = splitSample(y, p);
    kept = w[s.lower] * s.wLower + w[s.lower + 1] * s.wUpper;
    taken = s.wLower + s.wUpper;
}

void reweightImage(const CascadeImage& img, const ReweightParams& p, std::vector<float>& rgb,
                   std::vector<double>* weights, int nthreads) {
    const int W = img.width, H = img.height, C = img.count;
    const size_t pixels = size_t(W) * size_t(H);
    std::vector<double> est(pixels * 3, 0.0);
    if (weights) weights->assign(pixels * size_t(C), 0.0);
    std::vector<double> scale(size_t(std::max(C, 0)));
    for (int i = 0; i < C; ++i) scale[size_t(i)] = p.start * std::pow(p.base, i);
    const double oneOverK = 1.0 / p.kappa;
    const double optimizeForError = std::clamp(oneOverK, 0.0, 1.0);
    const double colorFactor = (1.0 + 0.6 * (p.base - 1.0)) * (1.0 - optimizeForError) +
                               optimizeForError;  // mix(mix(1, b, .6), 1, 1/kappa)
    // c_i(q): the luminance of the counts of cascades i-1, i, i+1 at pixel q.
    auto counts = [&](size_t q, int i) {
        const double* s = img.sum.data() + q * size_t(C) * 3;
        double v[3] = {0.0, 0.0, 0.0};
        for (int j = std::max(0, i - 1); j <= std::min(C - 1, i + 1); ++j)
            for (int k = 0; k < 3; ++k) v[k] += s[size_t(j) * 3 + size_t(k)] / scale[size_t(j)];
        return lum(p.luma, v);
    };
    std::vector<double> removed(p.spread > 0 ? pixels * 3 : 0, 0.0);
    // Every pixel from the cascades alone: rows in any order, on any thread.
    parallelFor(0, H, 1, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y)
            for (int x = 0; x < W; ++x) {
                const size_t pix = size_t(y) * size_t(W) + size_t(x);
                const uint64_t n = img.n[pix];
                if (n == 0) continue;  // no samples: 0
                const double N = double(n);
                const double* s = img.sum.data() + pix * size_t(C) * 3;
                double* e = est.data() + pix * 3;
                for (int i = 0; i < C; ++i) {
                    double block = 0.0;
                    for (int dy = -1; dy <= 1; ++dy)
                        for (int dx = -1; dx <= 1; ++dx) {
                            const int qx = std::clamp(x + dx, 0, W - 1);
                            const int qy = std::clamp(y + dy, 0, H - 1);
                            block += counts(size_t(qy) * size_t(W) + size_t(qx), i);
                        }
                    const double global = block / 9.0 * oneOverK;
                    const double local = counts(pix, i) * oneOverK;
                    double r = global - oneOverK;
                    if (r >= 0.0) r = local - oneOverK;
                    const double currScale = N * oneOverK / scale[size_t(i)];
                    double color = std::max(lum(p.luma, e), 0.05) * currScale;
                    color *= colorFactor;
                    double w = std::clamp((r + color) * 0.5, 0.0, 1.0);
                    if (!(oneOverK < 1e6)) w = 1.0;  // the reference's switch: kappa <= 1e-6 is off
                    for (int k = 0; k < 3; ++k) e[k] += w * s[size_t(i) * 3 + size_t(k)] / N;
                    if (weights) (*weights)[pix * size_t(C) + size_t(i)] = w;
                }
                if (p.spread > 0)
                    for (int k = 0; k < 3; ++k) {
                        double all = 0.0;
                        for (int i = 0; i < C; ++i) all += s[size_t(i) * 3 + size_t(k)] / N;
                        removed[pix * 3 + size_t(k)] = all - e[k];
                    }
            }
    });
    if (p.spread > 0) {
        std::vector<double> add;
        scatterRemoved(W, H, p.spread, 3, removed, add, nthreads);
        for (size_t q = 0; q < pixels; ++q)
            if (img.n[q] > 0)  // no samples: stays 0
                for (size_t k = 0; k < 3; ++k) est[q * 3 + k] += add[q * 3 + k];
    }
    rgb.resize(pixels * 3);
    for (size_t i = 0; i < pixels * 3; ++i) rgb[i] = float(est[i]);
}

}  // namespace mcstat
