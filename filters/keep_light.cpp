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
                // Light its 3 x 3 neighbours' buffers support together (a caustic too small
                // for the intervals to tell from a few fireflies) stays within a pixel.
                const auto [x0, x1] = clipped(x, 1, width);
                const auto [y0, y1] = clipped(y, 1, height);
                const double v = sumV.box(x0, y0, x1, y1);
                if (v > 0.0 && sumD.box(x0, y0, x1, y1) / std::sqrt(v) >= params.supportZ)
                    chosen = std::min<uint8_t>(chosen, uint8_t(1));
                scale[p] = chosen;
            }
    });
}

namespace {

/// One gather of a radius and channel: into[q * nc + c] += sum over p within r of q of
/// tent(q - p) source[p], by direct sums (rows, then columns). The sources are sparse: a sorted
/// list and two pointers per row; no running sum, whose subtractions would leave a firefly's
/// rounding behind in the dark beyond it.
void gatherTent(const std::vector<double>& source, int width, int height, int r, size_t nc,
                size_t c, std::vector<double>& rows, std::vector<uint8_t>& rowUsed,
                std::vector<double>& into, int nthreads) {
    const size_t w = size_t(width);
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
    parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y) {
            const auto [y0, y1] = clipped(y, r, height);
            for (int j = y0; j < y1; ++j) {
                if (!rowUsed[size_t(j)]) continue;
                const double t = tent(j - y, r);
                const double* src = rows.data() + size_t(j) * w;
                double* dst = into.data() + size_t(y) * w * nc + c;
                for (size_t x = 0; x < w; ++x) dst[x * nc] += t * src[x];
            }
        }
    });
}

/// The guide's tent sums of radius r at the pixels `need` marks: sum over q within r of p, inside
/// the image, of tent(q - p) guide[q] (direct sums: rows for every row near a marked pixel, then
/// the column at each marked pixel). 0 elsewhere.
std::vector<double> guideSums(const float* guide, const std::vector<uint8_t>& need, int width,
                              int height, int r, int nthreads) {
    const size_t w = size_t(width), n = w * size_t(height);
    std::vector<uint8_t> rowNeeded(static_cast<size_t>(height), 0);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
            if (need[size_t(y) * w + size_t(x)]) {
                const auto [y0, y1] = clipped(y, r, height);
                for (int j = y0; j < y1; ++j) rowNeeded[size_t(j)] = 1;
                break;
            }
    std::vector<double> rows(n, 0.0), sums(n, 0.0);
    parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y) {
            if (!rowNeeded[size_t(y)]) continue;
            const float* g = guide + size_t(y) * w;
            for (int x = 0; x < width; ++x) {
                const auto [x0, x1] = clipped(x, r, width);
                double sum = 0.0;
                for (int i = x0; i < x1; ++i) sum += tent(i - x, r) * double(g[i]);
                rows[size_t(y) * w + size_t(x)] = sum;
            }
        }
    });
    parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y) {
            const auto [y0, y1] = clipped(y, r, height);
            for (int x = 0; x < width; ++x) {
                if (!need[size_t(y) * w + size_t(x)]) continue;
                double sum = 0.0;
                for (int j = y0; j < y1; ++j)
                    sum += tent(j - y, r) * rows[size_t(j) * w + size_t(x)];
                sums[size_t(y) * w + size_t(x)] = sum;
            }
        }
    });
    return sums;
}

}  // namespace

void returnResidual(const float* robust, const double* residual, const uint8_t* scale,
                    const std::vector<int>& radii, int width, int height, int nch, float* out,
                    int nthreads, const float* guide) {
    const size_t w = size_t(width), n = w * size_t(height), nc = size_t(nch);
    // What each pixel receives, per channel: `plain` by the tent alone, `guided` to be multiplied
    // by the pixel's guide value.
    std::vector<double> plain(n * nc, 0.0), guided(guide ? n * nc : 0, 0.0);
    std::vector<double> source(n), rows(n);
    std::vector<uint8_t> rowUsed(static_cast<size_t>(height)), need(n);
    for (size_t k = 0; k < radii.size(); ++k) {
        const int r = radii[k];
        bool anyAtK = false;
        for (size_t p = 0; p < n; ++p) {
            need[p] = 0;
            if (scale[p] != k) continue;
            for (size_t c = 0; c < nc; ++c) {
                const double v = residual[p * nc + c];
                if (v != 0.0 && std::isfinite(v)) need[p] = 1;
            }
            anyAtK = anyAtK || need[p];
        }
        if (!anyAtK) continue;
        // With a guide, p's light goes to q in proportion to tent(q - p) guide[q]: its weights
        // over the window sum to 1 when divided by the guide's tent sum at p. A window whose guide
        // is 0 everywhere (no surface to put the light on) takes the tent alone.
        const std::vector<double> norm =
            guide ? guideSums(guide, need, width, height, r, nthreads) : std::vector<double>();
        for (size_t c = 0; c < nc; ++c)
            for (const bool byGuide : {true, false}) {
                if (byGuide && !guide) continue;
                bool any = false;
                for (int y = 0; y < height; ++y) {
                    const double wy = tentSum(y, r, height);
                    for (int x = 0; x < width; ++x) {
                        const size_t p = size_t(y) * w + size_t(x);
                        const double v = residual[p * nc + c];
                        double s = 0.0;
                        const bool mine = guide && norm[p] > 0.0;
                        if (need[p] && v != 0.0 && std::isfinite(v) && mine == byGuide) {
                            s = v / (byGuide ? norm[p] : tentSum(x, r, width) * wy);
                            any = true;
                        }
                        source[p] = s;
                    }
                }
                if (any)
                    gatherTent(source, width, height, r, nc, c, rows, rowUsed,
                               byGuide ? guided : plain, nthreads);
            }
    }
    parallelFor(0, int64_t(n), 0, nthreads, [&](int64_t b, int64_t e) {
        for (size_t q = size_t(b); q < size_t(e); ++q)
            for (size_t c = 0; c < nc; ++c) {
                const size_t i = q * nc + c;
                const double add = plain[i] + (guide ? double(guide[q]) * guided[i] : 0.0);
                out[i] = add != 0.0 ? float(double(robust[i]) + add) : robust[i];
            }
    });
}

}  // namespace mcstat
