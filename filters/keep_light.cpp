// The residual given back at a scale the data choose (include/mcstat/filters/keep_light.h).
#include "mcstat/filters/keep_light.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
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

/// The tent's weights summed over [0, n) around c, in closed form: (r + 1) for the centre and
/// sum_{k=1..a} (r + 1 - k) for each side reaching a pixels into the image. Exact in double.
double tentSumClosed(int c, int r, int n) {
    const double a = double(std::min(r, c)), b = double(std::min(r, n - 1 - c)), r1 = double(r + 1);
    return r1 + a * r1 - a * (a + 1.0) / 2.0 + b * r1 - b * (b + 1.0) / 2.0;
}

/// Forward box sums of B = r + 1 elements by van Herk's blocks: dst[j] = sum of src[j .. j + r]
/// for j in [0, outLen), where element t of the source is src[(t - offset) * stride .. + L) for t
/// - offset in [0, srcLen) and 0 elsewhere. Each sum is a suffix of one block plus a prefix of the
/// next, both summed directly from elements inside the window: no subtraction, so a window of
/// zeros sums to exactly 0 and a large value never leaves its rounding in a window that does not
/// hold it (a running sum would). `pre` and `suf` are scratch.
void boxForward(const double* src, size_t stride, int offset, int srcLen, int outLen, int r,
                size_t L, double* dst, size_t dstStride, std::vector<double>& pre,
                std::vector<double>& suf) {
    const int B = r + 1;
    const int blocks = (outLen + r + B - 1) / B + 1;
    const size_t span = size_t(blocks) * size_t(B);
    pre.assign(span * L, 0.0);
    suf.assign(span * L, 0.0);
    auto element = [&](int t) -> const double* {
        const int i = t - offset;
        return i >= 0 && i < srcLen ? src + size_t(i) * stride : nullptr;
    };
    for (int b0 = 0; b0 < int(span); b0 += B) {
        // Prefix within the block, then suffix within the block.
        for (int t = b0; t < b0 + B; ++t) {
            double* p = pre.data() + size_t(t) * L;
            const double* e = element(t);
            if (t == b0) {
                for (size_t l = 0; l < L; ++l) p[l] = e ? e[l] : 0.0;
            } else {
                const double* q = p - L;
                for (size_t l = 0; l < L; ++l) p[l] = q[l] + (e ? e[l] : 0.0);
            }
        }
        for (int t = b0 + B - 1; t >= b0; --t) {
            double* s = suf.data() + size_t(t) * L;
            const double* e = element(t);
            if (t == b0 + B - 1) {
                for (size_t l = 0; l < L; ++l) s[l] = e ? e[l] : 0.0;
            } else {
                const double* q = s + L;
                for (size_t l = 0; l < L; ++l) s[l] = q[l] + (e ? e[l] : 0.0);
            }
        }
    }
    for (int j = 0; j < outLen; ++j) {
        double* d = dst + size_t(j) * dstStride;
        const double* s = suf.data() + size_t(j) * L;
        if (j % B == 0) {
            for (size_t l = 0; l < L; ++l) d[l] = s[l];
        } else {
            const double* p = pre.data() + size_t(j + r) * L;
            for (size_t l = 0; l < L; ++l) d[l] = s[l] + p[l];
        }
    }
}

/// The tent of radius r along a line of n elements (L values each, `stride` apart):
/// dst[x] = sum over i in [x - r, x + r] inside [0, n) of (r + 1 - |i - x|) src[i]. The tent is
/// the convolution of two boxes of r + 1: a box back (the source padded by r zeros in front), then
/// a box forward, each by boxForward. `mid` holds the first box's n + r sums.
void tentLine(const double* src, size_t stride, int n, int r, size_t L, double* dst,
              size_t dstStride, std::vector<double>& mid, std::vector<double>& pre,
              std::vector<double>& suf) {
    mid.resize(size_t(n + r) * L);
    // mid[k] = sum of src[k - r .. k]; dst[x] = sum of mid[x .. x + r].
    boxForward(src, stride, r, n, n + r, r, L, mid.data(), L, pre, suf);
    boxForward(mid.data(), L, 0, n + r, n, r, L, dst, dstStride, pre, suf);
}

/// The indices of the elements of a line (n elements of L values, `stride` apart) that hold a
/// nonzero value, in order.
void nonzeroElements(const double* src, size_t stride, int n, size_t L, std::vector<int>& out) {
    out.clear();
    for (int i = 0; i < n; ++i) {
        const double* e = src + size_t(i) * stride;
        for (size_t l = 0; l < L; ++l)
            if (e[l] != 0.0) {
                out.push_back(i);
                break;
            }
    }
}

/// tentLine over a line whose nonzero elements are `nz` (sorted): direct sums over them when they
/// are few (their windows' widths cost less than the blocks' about 8 values per element), else the
/// blocks. Every dst element is written.
void tentSparseLine(const double* src, size_t stride, int n, int r, size_t L,
                    const std::vector<int>& nz, double* dst, size_t dstStride,
                    std::vector<double>& mid, std::vector<double>& pre, std::vector<double>& suf) {
    if (!(double(nz.size()) * double(2 * r + 1) < 8.0 * double(n))) {
        tentLine(src, stride, n, r, L, dst, dstStride, mid, pre, suf);
        return;
    }
    size_t lo = 0, hi = 0;
    for (int x = 0; x < n; ++x) {
        while (hi < nz.size() && nz[hi] <= x + r) ++hi;
        while (lo < hi && nz[lo] < x - r) ++lo;
        double* d = dst + size_t(x) * dstStride;
        std::fill(d, d + L, 0.0);
        for (size_t i = lo; i < hi; ++i) {
            const double t = tent(nz[i] - x, r);
            const double* e = src + size_t(nz[i]) * stride;
            for (size_t l = 0; l < L; ++l) d[l] += t * e[l];
        }
    }
}

/// One gather of a radius over nc interleaved channels: into[q * nc + c] += sum over p within r
/// of q (inside the image) of tent(q - p) source[p * nc + c], where only rows y with rowHas[y]
/// hold sources (the others are not read). Rows first, then columns, each by tentSparseLine. Every
/// output sums only
/// the sources inside its window: a pixel that none reaches gets exactly 0. Columns are split
/// among threads, rows too; no result depends on the split.
void gatherTent(const std::vector<double>& source, const std::vector<uint8_t>& rowHas, int width,
                int height, int r, size_t nc, std::vector<double>& rows, std::vector<double>& into,
                int nthreads) {
    const size_t w = size_t(width), rowLen = w * nc;
    std::vector<uint8_t> rowUsed(size_t(height), 0);
    parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
        std::vector<int> xs;
        std::vector<double> mid, pre, suf;
        for (int y = int(yb); y < int(ye); ++y) {
            const double* src = source.data() + size_t(y) * rowLen;
            double* dst = rows.data() + size_t(y) * rowLen;
            xs.clear();
            if (rowHas[size_t(y)]) nonzeroElements(src, nc, width, nc, xs);
            rowUsed[size_t(y)] = !xs.empty();
            if (!xs.empty()) tentSparseLine(src, nc, width, r, nc, xs, dst, nc, mid, pre, suf);
        }
    });
    // Columns: the rows within r of a used row, in strips of columns.
    int first = height, last = -1;
    for (int y = 0; y < height; ++y)
        if (rowUsed[size_t(y)]) {
            first = std::min(first, y);
            last = y;
        }
    if (last < 0) return;
    const int y0 = std::max(0, first - r), y1 = std::min(height, last + r + 1);
    // The rows outside [first, last] hold no source: their horizontal sums are 0.
    for (int y = y0; y < y1; ++y)
        if (!rowUsed[size_t(y)])
            std::fill(rows.data() + size_t(y) * rowLen, rows.data() + size_t(y + 1) * rowLen, 0.0);
    constexpr size_t kStrip = 64;
    const int64_t strips = int64_t((rowLen + kStrip - 1) / kStrip);
    parallelFor(0, strips, 0, nthreads, [&](int64_t sb, int64_t se) {
        std::vector<double> mid, pre, suf, col;
        std::vector<int> js;
        for (int64_t s = sb; s < se; ++s) {
            const size_t l0 = size_t(s) * kStrip, L = std::min(kStrip, rowLen - l0);
            const int n = y1 - y0;
            const double* base = rows.data() + size_t(y0) * rowLen + l0;
            nonzeroElements(base, rowLen, n, L, js);
            if (js.empty()) continue;
            col.resize(size_t(n) * L);
            tentSparseLine(base, rowLen, n, r, L, js, col.data(), L, mid, pre, suf);
            for (int y = y0; y < y1; ++y) {
                double* d = into.data() + size_t(y) * rowLen + l0;
                const double* c = col.data() + size_t(y - y0) * L;
                for (size_t l = 0; l < L; ++l) d[l] += c[l];
            }
        }
    });
}

/// The guide's tent sums of radius r, sum over q within r of p, inside the image, of tent(q - p)
/// guide[q], at every pixel (rows, then columns, by tentLine).
std::vector<double> guideSums(const float* guide, int width, int height, int r, int nthreads) {
    const size_t w = size_t(width), n = w * size_t(height);
    std::vector<double> g(guide, guide + n), rows(n, 0.0), sums(n, 0.0);
    gatherTent(g, std::vector<uint8_t>(size_t(height), 1), width, height, r, 1, rows, sums,
               nthreads);
    return sums;
}

/// The sources of one gather: at each sender p (need[p]) that `mine` picks, its residual
/// divided by its window's weight sum share(p, x, y); 0 elsewhere (a row that held something and
/// holds no sender now is cleared). rowHas[y]: row y holds a nonzero value.
template <class Mine, class Share>
void senderRows(const double* residual, const std::vector<uint8_t>& need,
                const std::vector<uint8_t>& rowNeed, Mine mine, Share share, int width, int height,
                size_t nc, std::vector<double>& source, std::vector<uint8_t>& rowHas,
                int nthreads) {
    const size_t w = size_t(width);
    parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y) {
            double* row = source.data() + size_t(y) * w * nc;
            if (!rowNeed[size_t(y)]) {
                if (rowHas[size_t(y)]) std::fill(row, row + w * nc, 0.0);
                rowHas[size_t(y)] = 0;
                continue;
            }
            bool any = false;
            for (int x = 0; x < width; ++x) {
                const size_t p = size_t(y) * w + size_t(x);
                const bool from = need[p] && mine(p);
                const double sum = from ? share(p, x, y) : 1.0;
                for (size_t c = 0; c < nc; ++c) {
                    const double v = residual[p * nc + c];
                    double s = 0.0;
                    if (from && v != 0.0 && std::isfinite(v)) {
                        s = v / sum;
                        any = true;
                    }
                    row[size_t(x) * nc + c] = s;
                }
            }
            rowHas[size_t(y)] = any;
        }
    });
}

}  // namespace

void returnResidual(const float* robust, const double* residual, const uint8_t* scale,
                    const std::vector<int>& radii, int width, int height, int nch, float* out,
                    int nthreads, const float* guide, const float* clusterGuide) {
    const size_t w = size_t(width), n = w * size_t(height), nc = size_t(nch);
    // What each pixel receives, per channel: `plain` by the tent alone, `guided` and `clustered`
    // to be multiplied by the pixel's guide and cluster guide values.
    std::vector<double> plain(n * nc, 0.0), guided(guide ? n * nc : 0, 0.0),
        clustered(clusterGuide ? n * nc : 0, 0.0);
    std::vector<double> source, rows;
    // need[p]: p sends light at the radius at hand; rowNeed: its row holds such a p; rowHas: the
    // source's row holds a nonzero value (the others are 0).
    std::vector<uint8_t> need(n), rowNeed(static_cast<size_t>(height)),
        rowHas(static_cast<size_t>(height), 0);
    auto sends = [&](size_t p) {
        for (size_t c = 0; c < nc; ++c) {
            const double v = residual[p * nc + c];
            if (v != 0.0 && std::isfinite(v)) return true;
        }
        return false;
    };
    for (size_t k = 0; k < radii.size(); ++k) {
        const int r = radii[k];
        parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
            for (size_t y = size_t(yb); y < size_t(ye); ++y) {
                bool any = false;
                for (size_t p = y * w; p < (y + 1) * w; ++p) {
                    need[p] = scale[p] == k && sends(p);
                    any = any || need[p];
                }
                rowNeed[y] = any;
            }
        });
        if (std::none_of(rowNeed.begin(), rowNeed.end(), [](uint8_t v) { return v != 0; }))
            continue;
        if (source.empty()) {
            source.assign(n * nc, 0.0);
            rows.assign(n * nc, 0.0);
        }
        // With a guide, p's light goes to q in proportion to tent(q - p) guide[q]: its weights
        // over the window sum to 1 when divided by the guide's tent sum at p. A window whose guide
        // is 0 everywhere (no surface to put the light on) takes the next: the cluster guide
        // (radius 1 only), the guide, the tent alone.
        enum Kernel : int { kByCluster, kByGuide, kByTent };
        const bool byCluster = clusterGuide && r == 1;
        const std::vector<double> clusterNorm =
            byCluster ? guideSums(clusterGuide, width, height, r, nthreads) : std::vector<double>();
        const std::vector<double> norm =
            guide ? guideSums(guide, width, height, r, nthreads) : std::vector<double>();
        auto kernelOf = [&](size_t p) {
            if (byCluster && clusterNorm[p] > 0.0) return kByCluster;
            if (guide && norm[p] > 0.0) return kByGuide;
            return kByTent;
        };
        for (const Kernel kernel : {kByCluster, kByGuide, kByTent}) {
            if ((kernel == kByCluster && !byCluster) || (kernel == kByGuide && !guide)) continue;
            auto share = [&](size_t p, int x, int y) {
                return kernel == kByCluster ? clusterNorm[p]
                       : kernel == kByGuide
                           ? norm[p]
                           : tentSumClosed(x, r, width) * tentSumClosed(y, r, height);
            };
            senderRows(
                residual, need, rowNeed, [&](size_t p) { return kernelOf(p) == kernel; }, share,
                width, height, nc, source, rowHas, nthreads);
            if (std::any_of(rowHas.begin(), rowHas.end(), [](uint8_t v) { return v != 0; }))
                gatherTent(source, rowHas, width, height, r, nc, rows,
                           kernel == kByCluster ? clustered
                           : kernel == kByGuide ? guided
                                                : plain,
                           nthreads);
        }
    }
    parallelFor(0, int64_t(n), 0, nthreads, [&](int64_t b, int64_t e) {
        for (size_t q = size_t(b); q < size_t(e); ++q)
            for (size_t c = 0; c < nc; ++c) {
                const size_t i = q * nc + c;
                const double add = plain[i] + (guide ? double(guide[q]) * guided[i] : 0.0) +
                                   (clusterGuide ? double(clusterGuide[q]) * clustered[i] : 0.0);
                out[i] = add != 0.0 ? float(double(robust[i]) + add) : robust[i];
            }
    });
}

std::vector<float> keepLightClusterGuide(const float* d, int width, int height, int nthreads) {
    const size_t w = size_t(width), n = w * size_t(height);
    std::vector<float> g(n, 0.f);
    auto at = [&](int x, int y) {
        const float v = d[size_t(y) * w + size_t(x)];
        return std::isfinite(v) && v > 0.f ? double(v) : 0.0;
    };
    parallelFor(0, height, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y)
            for (int x = 0; x < width; ++x) {
                double sum = 0.0, weight = 0.0;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int qx = x + dx, qy = y + dy;
                        if (qx < 0 || qy < 0 || qx >= width || qy >= height) continue;
                        const double t = double((2 - std::abs(dx)) * (2 - std::abs(dy)));
                        sum += t * at(qx, qy);
                        weight += t;
                    }
                g[size_t(y) * w + size_t(x)] = float(sum / weight);
            }
    });
    return g;
}

}  // namespace mcstat
