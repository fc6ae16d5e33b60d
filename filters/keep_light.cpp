// The residual given back at a scale the data choose (include/mcstat/filters/keep_light.h).
#include "mcstat/filters/keep_light.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "mcstat/core/parallel.h"

namespace mcstat {

namespace {

/// A summed-area table in double of a width x height array, for window sums of the scale choice
/// (a decision statistic: its rounding, relative to the image's sums, never reaches an output
/// value, which returnResidual sums directly).
class AreaSums {
  public:
    template <class Value>
    AreaSums(int width, int height, Value value)
        : w_(size_t(width) + 1), s_(w_ * (size_t(height) + 1), 0.0) {
        for (int y = 0; y < height; ++y) {
            double row = 0.0;
            for (int x = 0; x < width; ++x) {
                row += value(size_t(y) * size_t(width) + size_t(x));
                s_[(size_t(y) + 1) * w_ + size_t(x) + 1] = s_[size_t(y) * w_ + size_t(x) + 1] + row;
            }
        }
    }
    /// The sum over [x0, x1) x [y0, y1).
    double box(int x0, int y0, int x1, int y1) const {
        return s_[size_t(y1) * w_ + size_t(x1)] - s_[size_t(y0) * w_ + size_t(x1)] -
               s_[size_t(y1) * w_ + size_t(x0)] + s_[size_t(y0) * w_ + size_t(x0)];
    }

  private:
    size_t w_;
    std::vector<double> s_;
};

double finiteOrZero(float v) { return std::isfinite(v) ? double(v) : 0.0; }

/// The part of [c - r, c + r] inside [0, n).
std::pair<int, int> clipped(int c, int r, int n) {
    return {std::max(0, c - r), std::min(n, c + r + 1)};
}

/// The tent's weight at offset i of radius r: r + 1 - |i| (1 at radius 0).
double tent(int i, int r) { return double(r + 1 - std::abs(i)); }

/// The sum of the tent's weights of radius r around c that fall inside [0, n).
double tentSum(int c, int r, int n) {
    double s = 0.0;
    for (int i = std::max(0, c - r); i < std::min(n, c + r + 1); ++i) s += tent(i - c, r);
    return s;
}

}  // namespace

std::vector<int> keepLightRadii(int maxRadius) {
    std::vector<int> radii = {0};
    for (int r = 1; r < maxRadius; r *= 2) radii.push_back(r);
    if (maxRadius > 0) radii.push_back(maxRadius);
    return radii;
}

void keepLightScales(const float* d, const float* se, const uint8_t* active, int width, int height,
                     const KeepLightParams& params, uint8_t* scale, int nthreads) {
    const std::vector<int> radii = keepLightRadii(params.maxRadius);
    const size_t n = size_t(width) * size_t(height);
    std::fill(scale, scale + n, uint8_t(0));
    const AreaSums sumD(width, height, [&](size_t p) { return finiteOrZero(d[p]); });
    const AreaSums sumV(width, height, [&](size_t p) {
        const double s = finiteOrZero(se[p]);
        return s * s;
    });
    const double gamma = params.gamma;
    parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y)
            for (int x = 0; x < width; ++x) {
                const size_t p = size_t(y) * size_t(width) + size_t(x);
                if (!active[p]) continue;
                // Intersect the windows' intervals from the smallest up; keep the last radius
                // whose intersection is not empty.
                double lo = -std::numeric_limits<double>::infinity();
                double hi = std::numeric_limits<double>::infinity();
                uint8_t chosen = 0;
                for (size_t k = 0; k < radii.size(); ++k) {
                    const auto [x0, x1] = clipped(x, radii[k], width);
                    const auto [y0, y1] = clipped(y, radii[k], height);
                    const double area = double(x1 - x0) * double(y1 - y0);
                    const double m = sumD.box(x0, y0, x1, y1) / area;
                    const double s = std::sqrt(std::max(0.0, sumV.box(x0, y0, x1, y1))) / area;
                    lo = std::max(lo, m - gamma * s);
                    hi = std::min(hi, m + gamma * s);
                    if (!(lo <= hi)) break;
                    chosen = uint8_t(k);
                }
                scale[p] = chosen;
            }
    });
}

double returnResidual(const float* robust, const double* residual, const uint8_t* scale,
                      const std::vector<int>& radii, int width, int height, int nch, float* out,
                      int nthreads) {
    const size_t w = size_t(width), n = w * size_t(height), nc = size_t(nch);
    std::vector<double> given(n * nc, 0.0);  // what each pixel receives, per channel
    std::vector<double> source(n), rows(n);
    std::vector<uint8_t> rowUsed(static_cast<size_t>(height));
    double returned = 0.0;
    for (size_t k = 0; k < radii.size(); ++k) {
        const int r = radii[k];
        for (size_t c = 0; c < nc; ++c) {
            // The sources of this radius and channel: residual / the clipped tent's weight.
            bool any = false;
            for (int y = 0; y < height; ++y) {
                const double wy = tentSum(y, r, height);
                for (int x = 0; x < width; ++x) {
                    const size_t p = size_t(y) * w + size_t(x);
                    const double v = residual[p * nc + c];
                    double s = 0.0;
                    if (scale[p] == k && v != 0.0 && std::isfinite(v)) {
                        s = v / (tentSum(x, r, width) * wy);
                        returned += v;
                        any = true;
                    }
                    source[p] = s;
                }
            }
            if (!any) continue;
            // Rows: each pixel the direct sum of the sources within r along its row (sources
            // are sparse: a sorted list and two pointers; no running sum, whose subtractions
            // would leave a firefly's rounding behind in the dark beyond it).
            parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
                std::vector<int> xs;
                for (int y = int(yb); y < int(ye); ++y) {
                    const double* src = source.data() + size_t(y) * w;
                    double* dst = rows.data() + size_t(y) * w;
                    xs.clear();
                    for (int x = 0; x < width; ++x)
                        if (src[x] != 0.0) xs.push_back(x);
                    rowUsed[size_t(y)] = !xs.empty();
                    std::fill(dst, dst + w, 0.0);
                    size_t lo = 0, hi = 0;
                    for (int x = 0; x < width && !xs.empty(); ++x) {
                        while (hi < xs.size() && xs[hi] <= x + r) ++hi;
                        while (lo < hi && xs[lo] < x - r) ++lo;
                        double sum = 0.0;
                        for (size_t i = lo; i < hi; ++i) sum += tent(xs[i] - x, r) * src[xs[i]];
                        dst[x] = sum;
                    }
                }
            });
            // Columns: each output row the direct sum of the rows within r that hold anything.
            parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
                for (int y = int(yb); y < int(ye); ++y) {
                    const auto [y0, y1] = clipped(y, r, height);
                    for (int j = y0; j < y1; ++j) {
                        if (!rowUsed[size_t(j)]) continue;
                        const double t = tent(j - y, r);
                        const double* src = rows.data() + size_t(j) * w;
                        double* dst = given.data() + size_t(y) * w * nc + c;
                        for (size_t x = 0; x < w; ++x) dst[x * nc] += t * src[x];
                    }
                }
            });
        }
    }
    parallelFor(0, int64_t(n), 0, nthreads, [&](int64_t b, int64_t e) {
        for (size_t i = size_t(b) * nc; i < size_t(e) * nc; ++i)
            out[i] = given[i] != 0.0 ? float(double(robust[i]) + given[i]) : robust[i];
    });
    return returned;
}

}  // namespace mcstat
