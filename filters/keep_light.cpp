// The residual given back at a scale the data choose (include/mcstat/filters/keep_light.h).
#include "mcstat/filters/keep_light.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "keep_light_rows.h"
#include "mcstat/core/parallel.h"

namespace mcstat {

namespace {

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

namespace keeplight {

bool HeldRows::sends(size_t p) const {
    if (active) return active[p] != 0;  // the caller's flag: the same test, once per pixel
    for (size_t c = 0; c < nc; ++c) {
        const double v = residual[p * nc + c];
        if (v != 0.0 && std::isfinite(v)) return true;
    }
    return false;
}

int haloRows(const KeepLightParams& params) { return std::max(1, params.maxRadius); }

}  // namespace keeplight

void keepLightScales(const float* d, const float* se, const float* robustY, const uint8_t* active,
                     int width, int height, const KeepLightParams& params, uint8_t* scale,
                     int nthreads, uint8_t* restScale, float* restShare, float* bias,
                     float* level) {
    keeplight::HeldRows held = keeplight::HeldRows::whole(width, height);
    held.d = d;
    held.se = se;
    held.robustY = robustY;
    held.active = active;
    keeplight::scalesRows(
        held, params, 0, height, scale, restScale && restShare ? restScale : nullptr,
        restScale && restShare ? restShare : nullptr, bias && level ? bias : nullptr,
        bias && level ? level : nullptr, nthreads);
}

namespace {

/// The tent's weights summed over [0, n) around c, in closed form: (r + 1) for the centre and
/// sum_{k=1..a} (r + 1 - k) for each side reaching a pixels into the image. Exact in double.
double tentSumClosed(int c, int r, int n) {
    const double a = double(std::min(r, c)), b = double(std::min(r, n - 1 - c)), r1 = double(r + 1);
    return r1 + a * r1 - a * (a + 1.0) / 2.0 + b * r1 - b * (b + 1.0) / 2.0;
}

/// The line passes' scratch, one per thread and kept between calls: the bands call them for every
/// radius, and fresh buffers cost an allocation, its zeros and its page faults each time. No pass
/// calls another while it holds it.
struct LineScratch {
    std::vector<double> mid, pre, suf, col;
    std::vector<int> idx;
};

LineScratch& lineScratch() {
    thread_local LineScratch scratch;
    return scratch;
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
    // Every element of [0, span L) is written below: growing is enough, no clearing.
    if (pre.size() < span * L) pre.resize(span * L);
    if (suf.size() < span * L) suf.resize(span * L);
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

/// One gather of a radius over nc interleaved channels, for the output rows [outFirst, outFirst +
/// outRows) of a source of srcRows rows: into[(y - outFirst) * width * nc + x * nc + c] += sum
/// over p within r of (x, y) (inside the source) of tent((x, y) - p) source[p * nc + c], where
/// only rows y with rowHas[y] hold sources (the others are not read). Rows first, then columns,
/// each by tentSparseLine. Every output sums only the sources inside its window: a pixel that none
/// reaches gets exactly 0. Columns are split among threads, rows too; no result depends on the
/// split. `rows` (srcRows rows) is scratch.
void gatherTent(const std::vector<double>& source, const std::vector<uint8_t>& rowHas, int width,
                int srcRows, int r, size_t nc, std::vector<double>& rows, std::vector<double>& into,
                int outFirst, int outRows, int nthreads) {
    const size_t w = size_t(width), rowLen = w * nc;
    std::vector<uint8_t> rowUsed(size_t(srcRows), 0);
    parallelFor(0, srcRows, 0, nthreads, [&](int64_t yb, int64_t ye) {
        LineScratch& t = lineScratch();
        std::vector<int>& xs = t.idx;
        std::vector<double>&mid = t.mid, &pre = t.pre, &suf = t.suf;
        for (int y = int(yb); y < int(ye); ++y) {
            const double* src = source.data() + size_t(y) * rowLen;
            double* dst = rows.data() + size_t(y) * rowLen;
            xs.clear();
            if (rowHas[size_t(y)]) nonzeroElements(src, nc, width, nc, xs);
            rowUsed[size_t(y)] = !xs.empty();
            if (!xs.empty()) tentSparseLine(src, nc, width, r, nc, xs, dst, nc, mid, pre, suf);
        }
    });
    // Columns: the rows within r of a used row and of an output row, in strips of columns.
    int first = srcRows, last = -1;
    for (int y = 0; y < srcRows; ++y)
        if (rowUsed[size_t(y)]) {
            first = std::min(first, y);
            last = y;
        }
    if (last < 0) return;
    const int y0 = std::max({0, first - r, outFirst - r});
    const int y1 = std::min({srcRows, last + r + 1, outFirst + outRows + r});
    if (y0 >= y1) return;
    // The rows outside [first, last] hold no source: their horizontal sums are 0.
    for (int y = y0; y < y1; ++y)
        if (!rowUsed[size_t(y)])
            std::fill(rows.data() + size_t(y) * rowLen, rows.data() + size_t(y + 1) * rowLen, 0.0);
    const int o0 = std::max(y0, outFirst), o1 = std::min(y1, outFirst + outRows);
    constexpr size_t kStrip = 64;
    const int64_t strips = int64_t((rowLen + kStrip - 1) / kStrip);
    parallelFor(0, strips, 0, nthreads, [&](int64_t sb, int64_t se) {
        LineScratch& t = lineScratch();
        std::vector<double>&mid = t.mid, &pre = t.pre, &suf = t.suf, &col = t.col;
        std::vector<int>& js = t.idx;
        for (int64_t s = sb; s < se; ++s) {
            const size_t l0 = size_t(s) * kStrip, L = std::min(kStrip, rowLen - l0);
            const int n = y1 - y0;
            const double* base = rows.data() + size_t(y0) * rowLen + l0;
            nonzeroElements(base, rowLen, n, L, js);
            if (js.empty()) continue;
            col.resize(size_t(n) * L);
            tentSparseLine(base, rowLen, n, r, L, js, col.data(), L, mid, pre, suf);
            for (int y = o0; y < o1; ++y) {
                double* d = into.data() + size_t(y - outFirst) * rowLen + l0;
                const double* c = col.data() + size_t(y - y0) * L;
                for (size_t l = 0; l < L; ++l) d[l] += c[l];
            }
        }
    });
}

/// guideSums' buffers, kept across the radii of one normsRows.
struct GuideScratch {
    std::vector<double> g, rows, sums;
    std::vector<uint8_t> rowHas;
};

/// The guide's tent sums of radius r at every pixel of rows [y0, y1), into s.sums: sum over q
/// within r of p, inside the image, of tent(q - p) guide[q] (rows, then columns, by tentLine), row
/// y0 first.
void guideSums(const keeplight::HeldRows& held, const float* guide, int y0, int y1, int r,
               GuideScratch& s, int nthreads) {
    const int s0 = std::max(0, y0 - r), s1 = std::min(held.height, y1 + r);
    const size_t w = size_t(held.width);
    const float* from = guide + held.at(0, s0);
    s.g.assign(from, from + size_t(s1 - s0) * w);
    s.rows.resize(s.g.size());  // gatherTent writes every row it reads
    s.sums.assign(size_t(y1 - y0) * w, 0.0);
    s.rowHas.assign(size_t(s1 - s0), 1);
    gatherTent(s.g, s.rowHas, held.width, s1 - s0, r, 1, s.rows, s.sums, y0 - s0, y1 - y0,
               nthreads);
}

/// The sources of one gather over rows [s0, s0 + nRows) of the image: at each sender p whose
/// need[p] (row s0 first) is `mine`, its residual times the part it sends here, factor(p), divided
/// by its window's weight sum share(p, x, y) (p as held.at gives it, y the image row); 0
/// elsewhere (a row that held something and holds no sender now is cleared). rowHas[i]: source
/// row i holds a nonzero value.
template <class Share, class Factor>
void senderRows(const keeplight::HeldRows& held, int s0, int nRows,
                const std::vector<uint8_t>& need, const std::vector<uint8_t>& rowNeed, uint8_t mine,
                Share share, Factor factor, std::vector<double>& source,
                std::vector<uint8_t>& rowHas, int nthreads) {
    const size_t w = size_t(held.width), nc = held.nc;
    parallelFor(0, nRows, 0, nthreads, [&](int64_t ib, int64_t ie) {
        for (int i = int(ib); i < int(ie); ++i) {
            double* row = source.data() + size_t(i) * w * nc;
            if (!rowNeed[size_t(i)]) {
                if (rowHas[size_t(i)]) std::fill(row, row + w * nc, 0.0);
                rowHas[size_t(i)] = 0;
                continue;
            }
            const int y = s0 + i;
            bool any = false;
            for (int x = 0; x < held.width; ++x) {
                const size_t p = held.at(x, y);
                const bool from = need[size_t(i) * w + size_t(x)] == mine;
                const double sum = from ? share(p, x, y) : 1.0, part = from ? factor(p) : 0.0;
                for (size_t c = 0; c < nc; ++c) {
                    const double v = held.residual[p * nc + c];
                    double s = 0.0;
                    if (from && v != 0.0 && std::isfinite(v)) {
                        s = v * part / sum;  // part 1 (all of it): v / sum, bit for bit
                        any = any || s != 0.0;
                    }
                    row[size_t(x) * nc + c] = s;
                }
            }
            rowHas[size_t(i)] = any;
        }
    });
}

/// need[i * width + x]: pixel (x, s0 + i) sends light at radius index k (its scale's, or with
/// `rest` its rest's, rules 6 and 8); rowNeed[i]: its row holds such a pixel. False when none does.
bool sendersAt(const keeplight::HeldRows& held, size_t k, bool rest, int s0, int nRows,
               std::vector<uint8_t>& need, std::vector<uint8_t>& rowNeed, int nthreads) {
    if (rest && !held.restShare) return false;
    const size_t w = size_t(held.width);
    need.assign(size_t(nRows) * w, 0);
    rowNeed.assign(size_t(nRows), 0);
    parallelFor(0, nRows, 0, nthreads, [&](int64_t ib, int64_t ie) {
        for (int i = int(ib); i < int(ie); ++i) {
            bool any = false;
            for (int x = 0; x < held.width; ++x) {
                const size_t p = held.at(x, s0 + i);
                const uint8_t n = rest ? held.restScale[p] == k && held.sendsRest(p)
                                       : held.scale[p] == k && held.sends(p);
                need[size_t(i) * w + size_t(x)] = n;
                any = any || n;
            }
            rowNeed[size_t(i)] = any;
        }
    });
    return std::any_of(rowNeed.begin(), rowNeed.end(), [](uint8_t v) { return v != 0; });
}

/// Each sender's kernel, once: need[p] (sendersAt's, row s0 first) becomes 1 + kernelOf(p) where
/// it was set. Returns the kernels some sender takes, bit k for kernel k.
template <class KernelOf>
uint8_t markKernels(const keeplight::HeldRows& held, int s0, int nRows,
                    const std::vector<uint8_t>& rowNeed, KernelOf kernelOf,
                    std::vector<uint8_t>& need, std::vector<uint8_t>& rowUsed, int nthreads) {
    const size_t w = size_t(held.width);
    rowUsed.assign(size_t(nRows), 0);
    parallelFor(0, nRows, 0, nthreads, [&](int64_t ib, int64_t ie) {
        for (int i = int(ib); i < int(ie); ++i) {
            if (!rowNeed[size_t(i)]) continue;
            uint8_t mask = 0;
            for (int x = 0; x < held.width; ++x) {
                uint8_t& code = need[size_t(i) * w + size_t(x)];
                if (!code) continue;
                const int kernel = int(kernelOf(held.at(x, s0 + i)));
                code = uint8_t(1 + kernel);
                mask = uint8_t(mask | (1u << kernel));
            }
            rowUsed[size_t(i)] = mask;
        }
    });
    uint8_t used = 0;
    for (uint8_t m : rowUsed) used = uint8_t(used | m);
    return used;
}

/// The scale choice's values of rows [s0, s1), two per pixel: d and se^2 (non-finite as 0).
void decisionValues(const keeplight::HeldRows& held, int s0, int s1, std::vector<double>& vals,
                    int nthreads) {
    const size_t w2 = 2 * size_t(held.width);
    vals.resize(size_t(s1 - s0) * w2);
    parallelFor(s0, s1, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y)
            for (int x = 0; x < held.width; ++x) {
                const size_t p = held.at(x, y);
                const double se = finiteOrZero(held.se[p]);
                double* v = vals.data() + size_t(y - s0) * w2 + 2 * size_t(x);
                v[0] = finiteOrZero(held.d[p]);
                v[1] = se * se;
            }
    });
}

/// The scale choice's window sums at radius r for the pixels of rows [y0, y1): out[2 p] the sum of
/// d, out[2 p + 1] the sum of se^2 over the window of radius r around p inside the image, p
/// counted from row y0, from decisionValues' `vals` of rows [s0, s1) (every row within r of
/// [y0, y1) inside the image). Columns, then rows, by van Herk's blocks (boxForward, no
/// subtraction: a firefly of 1e38 leaves no rounding in a window that does not hold it), the
/// blocks aligned on the image's rows and columns, so that the sums are the same bits whatever
/// rows the caller holds. Strips of columns, then rows, in parallel: each sum is the same at any
/// thread count.
void windowSums(const std::vector<double>& vals, int width, int s0, int s1, int r, int y0, int y1,
                std::vector<double>& out, std::vector<double>& cols, int nthreads) {
    const int B = 2 * r + 1;
    const size_t w2 = 2 * size_t(width);
    // Element t of the columns is the image's row a0 + t, a0 a multiple of B: sum j covers rows
    // a0 + j to a0 + j + 2r, the window of row a0 + j + r.
    const int a0 = (y0 - r) >= 0 ? (y0 - r) / B * B : -((r - y0 + B - 1) / B) * B;
    const int first = y0 - r - a0, rows = y1 - r - a0;
    cols.resize(size_t(rows) * w2);
    constexpr size_t kStrip = 256;
    const int64_t strips = int64_t((w2 + kStrip - 1) / kStrip);
    parallelFor(0, strips, 0, nthreads, [&](int64_t sb, int64_t se) {
        LineScratch& t = lineScratch();
        std::vector<double>&pre = t.pre, &suf = t.suf;
        for (int64_t st = sb; st < se; ++st) {
            const size_t l0 = size_t(st) * kStrip, L = std::min(kStrip, w2 - l0);
            boxForward(vals.data() + l0, w2, s0 - a0, s1 - s0, rows, 2 * r, L, cols.data() + l0, w2,
                       pre, suf);
        }
    });
    // Along each row, element t is column t - r: the same blocks for every row.
    out.resize(size_t(y1 - y0) * w2);
    parallelFor(first, rows, 0, nthreads, [&](int64_t jb, int64_t je) {
        LineScratch& t = lineScratch();
        std::vector<double>&pre = t.pre, &suf = t.suf;
        for (int j = int(jb); j < int(je); ++j)
            boxForward(cols.data() + size_t(j) * w2, 2, r, width, width, 2 * r, 2,
                       out.data() + size_t(j - first) * w2, 2, pre, suf);
    });
}

/// The median of value(q) over p's 3 x 3 window, or its 8 neighbours with `withoutP` (finite
/// values only; NaN where none is). Beyond the image the window takes the nearest pixel inside
/// it, so a border pixel's own row or column counts twice and the median is one of nine values
/// (a clipped window of six averages its two middle ones, and that midpoint kept fireflies on
/// the fixture's border rows). Rules 5 and 8 ask the neighbours this way.
template <class Value>
double windowMedian(const keeplight::HeldRows& held, int x, int y, bool withoutP, Value value) {
    std::array<double, 9> v;
    size_t n = 0;
    for (int j = y - 1; j <= y + 1; ++j)
        for (int i = x - 1; i <= x + 1; ++i) {
            if (withoutP && i == x && j == y) continue;
            const double m =
                value(held.at(std::clamp(i, 0, held.width - 1), std::clamp(j, 0, held.height - 1)));
            if (std::isfinite(m)) v[n++] = m;
        }
    if (n == 0) return std::numeric_limits<double>::quiet_NaN();
    // Insertion sort of at most nine (std::sort's 16-element insertion pass trips GCC 12's
    // array-bounds warning on a shorter array).
    for (size_t i = 1; i < n; ++i)
        for (size_t j = i; j > 0 && v[j] < v[j - 1]; --j) std::swap(v[j], v[j - 1]);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// Whether p's neighbours say that its plain mean is a better estimate than its robust value:
/// the median of the robust luminance over the 3 x 3 window (windowMedian) lies nearer the
/// mean's luminance, robustY + d, than the robust one. At the edge of a bright surface a pixel
/// that the surface covers in part sees it in a few samples, which a robust estimator takes for
/// fireflies; its neighbours along the edge and on the surface, whose robust values hold that
/// light, put the median above the midpoint between the robust value and the mean. A firefly's
/// neighbours are its surface's robust values, near its own.
bool meanNearerNeighbours(const keeplight::HeldRows& held, int x, int y) {
    const size_t p = held.at(x, y);
    const double robust = held.robustY[p], d = held.d[p];
    if (!std::isfinite(robust) || !std::isfinite(d)) return false;
    // Not NaN: p's own robust value is finite.
    const double median =
        windowMedian(held, x, y, false, [&](size_t q) { return double(held.robustY[q]); });
    return std::fabs(robust + d - median) < std::fabs(robust - median);
}

/// Rule 9: whether p's residual is its own light, to keep in place: a gain (d < 0: the robust
/// value lies above the mean, so no firefly inflated the mean and nothing was removed; spread, it
/// would darken other pixels, below 0 beside a light whose edge a mode-seeking estimator filled),
/// or a loss beyond ownZ of its own standard errors, d > ownZ se (se 0: any d > 0). A filter
/// across pixels takes a bright pixel's light to its neighbours and gives a dark pixel beside it
/// theirs; a median of many buffers takes a dark one where many hold a light's samples. Either
/// way the pixel's own buffers hold the light, and the pixel is its mean. A lone firefly's d / se
/// is about 1 (one buffer's event), so it never passes.
bool ownLight(const keeplight::HeldRows& held, size_t p, double ownZ) {
    const double d = held.d[p], se = held.se[p];
    if (!std::isfinite(d) || !std::isfinite(se) || d == 0.0) return false;
    return d < 0.0 || d > ownZ * std::max(se, 0.0);
}

/// Rule 8's level: the median of p's 8 neighbours' plain-mean luminance, robustY + d
/// (windowMedian; NaN where none is finite). A pixel's own mean stays out: a firefly's is its own
/// evidence, which its neighbours are asked about. The median (of eight, the mean of the two
/// middle values) ignores up to three bright neighbours: an emitter's edge beside it.
double neighboursLevel(const keeplight::HeldRows& held, int x, int y) {
    return windowMedian(held, x, y, true,
                        [&](size_t q) { return double(held.robustY[q]) + double(held.d[q]); });
}

/// Rule 8: the share of p's residual that p keeps in place, min(d, neighbourShare x (level -
/// robust)) / d (neighboursLevel), 0 where d <= 0 or nothing is finite.
double keptByNeighbours(const keeplight::HeldRows& held, int x, int y, double share) {
    const size_t p = held.at(x, y);
    const double robust = held.robustY[p], d = held.d[p];
    if (!(d > 0.0) || !std::isfinite(robust) || !std::isfinite(d) || !(share > 0.0)) return 0.0;
    const double gap = neighboursLevel(held, x, y) - robust;
    if (!(gap > 0.0)) return 0.0;  // NaN too
    return std::min(d, share * gap) / d;
}

}  // namespace

namespace keeplight {

void scalesRows(const HeldRows& held, const KeepLightParams& params, int y0, int y1, uint8_t* scale,
                uint8_t* restScale, float* restShare, float* bias, float* level, int nthreads) {
    const std::vector<int> radii = keepLightRadii(params.maxRadius);
    const int width = held.width, height = held.height;
    const size_t n = size_t(y1 - y0) * size_t(width);
    std::fill(scale, scale + n, uint8_t(0));
    if (restShare) {
        std::fill(restScale, restScale + n, uint8_t(0));
        std::fill(restShare, restShare + n, 1.f);
    }
    const double gamma = params.gamma;
    const int halo = haloRows(params);
    // By chunks of rows, each radius's window sums (and radius 1's, the support test's) at once.
    constexpr int kChunk = 64;
    std::vector<std::vector<double>> sums(radii.size() + 1);
    // The support test's windows of radius 1: the radii's own where they hold it.
    const size_t oneAt = size_t(std::find(radii.begin(), radii.end(), 1) - radii.begin());
    std::vector<double> vals, cols;
    for (int c0 = y0; c0 < y1; c0 += kChunk) {
        const int c1 = std::min(y1, c0 + kChunk);
        const int s0 = std::max(0, c0 - halo), s1 = std::min(height, c1 + halo);
        decisionValues(held, s0, s1, vals, nthreads);
        for (size_t k = 0; k < radii.size(); ++k)
            windowSums(vals, width, s0, s1, radii[k], c0, c1, sums[k], cols, nthreads);
        if (oneAt == radii.size())  // no window of radius 1 among the radii (maxRadius 0)
            windowSums(vals, width, s0, s1, 1, c0, c1, sums[oneAt], cols, nthreads);
        parallelFor(c0, c1, 0, nthreads, [&](int64_t yb, int64_t ye) {
            for (int y = int(yb); y < int(ye); ++y)
                for (int x = 0; x < width; ++x) {
                    const bool active = held.active[held.at(x, y)] != 0;
                    if (!active && !bias) continue;
                    const size_t i = 2 * (size_t(y - c0) * size_t(width) + size_t(x));
                    const size_t o = size_t(y - y0) * size_t(width) + size_t(x);
                    // Intersect the windows' intervals from the smallest up; keep the last radius
                    // whose intersection is not empty, and its window's mean (rule 7's bias).
                    auto areaOf = [&](size_t k) {  // window k's pixels inside the image
                        const auto [x0, x1] = clipped(x, radii[k], width);
                        const auto [wy0, wy1] = clipped(y, radii[k], height);
                        return double(x1 - x0) * double(wy1 - wy0);
                    };
                    double lo = -std::numeric_limits<double>::infinity();
                    double hi = std::numeric_limits<double>::infinity();
                    uint8_t chosen = 0;
                    double estimate = 0.0;
                    for (size_t k = 0; k < radii.size(); ++k) {
                        const double area = areaOf(k);
                        const double m = sums[k][i] / area;
                        const double s = std::sqrt(std::max(0.0, sums[k][i + 1])) / area;
                        lo = std::max(lo, m - gamma * s);
                        hi = std::min(hi, m + gamma * s);
                        if (!(lo <= hi)) break;
                        chosen = uint8_t(k);
                        estimate = m;
                    }
                    if (bias) {  // ICI's estimate, and the largest window's mean
                        const size_t K = radii.size() - 1;
                        bias[o] = float(std::max(0.0, estimate));
                        level[o] = float(std::max(0.0, sums[K][i] / areaOf(K)));
                    }
                    if (!active) continue;
                    // Light its 3 x 3 neighbours' buffers support together (a caustic too small
                    // for the intervals to tell from a few fireflies) stays within a pixel.
                    const std::vector<double>& one = sums[oneAt];
                    const uint8_t ici = chosen;
                    const double z = one[i + 1] > 0.0 ? one[i] / std::sqrt(one[i + 1]) : 0.0;
                    const bool supported = one[i + 1] > 0.0 && z >= params.supportZ;
                    if (supported) chosen = std::min<uint8_t>(chosen, uint8_t(1));
                    // Light that the neighbours' robust values say belongs to this pixel (the
                    // edge of a bright surface) stays in it: the pixel is its plain mean.
                    if (chosen != 0 && held.robustY && meanNearerNeighbours(held, x, y)) chosen = 0;
                    // Rule 9: a gain, and a loss beyond ownZ standard errors, are the pixel's own
                    // light (a 3D filter moved it; a median of many buffers missed it).
                    if (chosen != 0 && ownLight(held, held.at(x, y), params.ownZ)) chosen = 0;
                    scale[o] = chosen;
                    if (!restShare) continue;
                    restScale[o] = chosen;
                    if (supported && chosen == 1 && ici > 1) {
                        // Rule 6: of a cluster the test capped, the Wiener share of its signal,
                        // 1 - (supportZ / Z)^2, stays; the rest goes to ICI's own radius.
                        const double q = params.supportZ / z;
                        restShare[o] = float(std::clamp(1.0 - q * q, 0.0, 1.0));
                        restScale[o] = ici;
                    } else if (!supported && chosen != 0 && held.robustY) {
                        // Rule 8: the light its neighbours' plain means hold stays in place (a
                        // rest of radius 0); the rest of it goes as rules 1 to 7 say.
                        const double kept = keptByNeighbours(held, x, y, params.neighbourShare);
                        if (kept > 0.0) {
                            restShare[o] = float(1.0 - kept);
                            restScale[o] = 0;
                        }
                    }
                }
        });
    }
}

void normsRows(const HeldRows& held, const std::vector<int>& radii, int y0, int y1, double* norm,
               double* clusterNorm, double* lightNorm, double* biasNorm, int nthreads) {
    const size_t w = size_t(held.width), n = size_t(y1 - y0) * w;
    if (norm) std::fill(norm, norm + n, 0.0);
    if (clusterNorm) std::fill(clusterNorm, clusterNorm + n, 0.0);
    if (lightNorm) std::fill(lightNorm, lightNorm + n, 0.0);
    if (biasNorm) std::fill(biasNorm, biasNorm + n, 0.0);
    std::vector<uint8_t> need, rowNeed;
    GuideScratch scratch;
    const std::vector<double>& sums = scratch.sums;
    for (size_t k = 0; k < radii.size(); ++k) {
        const int r = radii[k];
        // The rest's windows (rules 6 and 8): the light guide's sums.
        if (held.light && lightNorm &&
            sendersAt(held, k, true, y0, y1 - y0, need, rowNeed, nthreads)) {
            guideSums(held, held.light, y0, y1, r, scratch, nthreads);
            for (size_t i = 0; i < n; ++i)
                if (need[i]) lightNorm[i] = sums[i];
        }
        // The senders' own windows: the cluster guide's (radius 1), the bias guide's (rule 7),
        // the guide's.
        const float* guides[3] = {held.cluster && clusterNorm && r == 1 ? held.cluster : nullptr,
                                  held.byBias(r) && biasNorm ? held.biasGuide : nullptr,
                                  norm ? held.guide : nullptr};
        double* const into[3] = {clusterNorm, biasNorm, norm};
        if (!(guides[0] || guides[1] || guides[2]) ||
            !sendersAt(held, k, false, y0, y1 - y0, need, rowNeed, nthreads))
            continue;
        // A sender whose window one guide covers takes that one (gatherRows' kernelOf): the
        // later guides' sums are needed only where the earlier ones are 0.
        for (int pass = 0; pass < 3; ++pass) {
            if (!guides[pass]) continue;
            guideSums(held, guides[pass], y0, y1, r, scratch, nthreads);
            bool left = false;
            for (size_t i = 0; i < n; ++i) {
                if (!need[i]) continue;
                into[pass][i] = sums[i];
                need[i] = !(sums[i] > 0.0);
                left = left || need[i];
            }
            if (!left) break;
        }
    }
}

void gatherRows(const HeldRows& held, const std::vector<int>& radii, int y0, int y1, double* add,
                GatherScratch& scratch, int nthreads) {
    const size_t w = size_t(held.width), nc = held.nc, n = size_t(y1 - y0) * w;
    const int width = held.width, height = held.height;
    // What each pixel receives, per channel: `plain` by the tent alone; `guided`, `clustered`,
    // `lit` and `biased` to be multiplied by the pixel's guide, cluster, light and bias guide
    // values.
    std::vector<double>&plain = scratch.plain, &guided = scratch.guided,
    &clustered = scratch.clustered, &lit = scratch.lit;
    plain.assign(n * nc, 0.0);
    guided.assign(held.guide ? n * nc : 0, 0.0);
    clustered.assign(held.cluster ? n * nc : 0, 0.0);
    const bool byLight = held.light && held.restShare;
    lit.assign(byLight ? n * nc : 0, 0.0);
    std::vector<double>& biased = scratch.biased;
    biased.assign(held.biasGuide ? n * nc : 0, 0.0);
    // The sources of a radius, the rows within r of [y0, y1): a source row i whose rowHas[i] is 0
    // holds zeros, from one radius and one call to the next (senderRows clears the rows it
    // leaves), so only the rows that held something are written again.
    std::vector<double>&source = scratch.source, &rows = scratch.rows;
    std::vector<uint8_t>&need = scratch.need, &rowNeed = scratch.rowNeed, &rowHas = scratch.rowHas;
    if (scratch.rowLength != w * nc) {
        source.clear();
        rowHas.clear();
        scratch.rowLength = w * nc;
    }
    int maxRadius = 0;
    for (int r : radii) maxRadius = std::max(maxRadius, r);
    const size_t most = size_t(std::min(height, y1 + maxRadius) - std::max(0, y0 - maxRadius));
    if (rowHas.size() < most) {
        source.resize(most * w * nc, 0.0);
        rowHas.resize(most, 0);
    }
    rows.resize(source.size());
    // need: the pixel sends light at the radius at hand (then 1 + its kernel, markKernels);
    // rowNeed: its row holds such a pixel; rowHas: the source's row holds a nonzero value (the
    // others are 0). Per radius, the senders are the rows within r of [y0, y1).
    for (size_t k = 0; k < radii.size(); ++k) {
        const int r = radii[k];
        const int s0 = std::max(0, y0 - r), s1 = std::min(height, y1 + r), nRows = s1 - s0;
        // With a guide, p's light goes to q in proportion to tent(q - p) guide[q]: its weights
        // over the window sum to 1 when divided by the guide's tent sum at p (normsRows). A
        // window whose guide is 0 everywhere (no surface to put the light on) takes the next:
        // the cluster guide (radius 1 only), the bias guide (radii 2 to biasRadius, rule 7), the
        // guide, the tent alone. A rest (rule 6: a cluster's luck; rule 8: radius 0) goes by the
        // light guide, else the tent.
        enum Kernel : int { kByCluster, kByBias, kByGuide, kByLight, kByTent };
        const bool byCluster = held.cluster && r == 1, byBias = held.byBias(r);
        for (const bool rest : {false, true}) {
            if (!sendersAt(held, k, rest, s0, nRows, need, rowNeed, nthreads)) continue;
            auto kernelOf = [&](size_t p) {
                if (rest) return byLight && held.lightNorm[p] > 0.0 ? kByLight : kByTent;
                if (byCluster && held.clusterNorm[p] > 0.0) return kByCluster;
                if (byBias && held.biasNorm[p] > 0.0) return kByBias;
                if (held.guide && held.norm[p] > 0.0) return kByGuide;
                return kByTent;
            };
            auto part = [&](size_t p) { return rest ? 1.0 - held.share(p) : held.share(p); };
            // Only the kernels some sender takes get a pass over the rows; the others' would only
            // write zeros (the tent alone, where a guide covers every window, is the rule).
            const uint8_t used =
                markKernels(held, s0, nRows, rowNeed, kernelOf, need, scratch.rowUsed, nthreads);
            for (const Kernel kernel : {kByCluster, kByBias, kByGuide, kByLight, kByTent}) {
                if (!(used & (1u << kernel))) continue;
                auto share = [&](size_t p, int x, int y) {
                    return kernel == kByCluster ? held.clusterNorm[p]
                           : kernel == kByBias  ? held.biasNorm[p]
                           : kernel == kByGuide ? held.norm[p]
                           : kernel == kByLight
                               ? held.lightNorm[p]
                               : tentSumClosed(x, r, width) * tentSumClosed(y, r, height);
                };
                senderRows(held, s0, nRows, need, rowNeed, uint8_t(1 + kernel), share, part, source,
                           rowHas, nthreads);
                if (std::any_of(rowHas.begin(), rowHas.end(), [](uint8_t v) { return v != 0; }))
                    gatherTent(source, rowHas, width, nRows, r, nc, rows,
                               kernel == kByCluster ? clustered
                               : kernel == kByBias  ? biased
                               : kernel == kByGuide ? guided
                               : kernel == kByLight ? lit
                                                    : plain,
                               y0 - s0, y1 - y0, nthreads);
            }
        }
    }
    parallelFor(0, int64_t(n), 0, nthreads, [&](int64_t b, int64_t e) {
        for (size_t q = size_t(b); q < size_t(e); ++q) {
            const size_t h = held.at(int(q % w), y0 + int(q / w));
            for (size_t c = 0; c < nc; ++c) {
                const size_t i = q * nc + c;
                add[i] = plain[i] + (held.guide ? double(held.guide[h]) * guided[i] : 0.0) +
                         (held.cluster ? double(held.cluster[h]) * clustered[i] : 0.0) +
                         (byLight ? double(held.light[h]) * lit[i] : 0.0) +
                         (held.biasGuide ? double(held.biasGuide[h]) * biased[i] : 0.0);
            }
        }
    });
}

namespace {

/// The plain mean's luminance at q, robustY + d (robustY null: 0), 0 where negative or not finite.
double plainLight(const HeldRows& held, size_t q) {
    const double m = (held.robustY ? double(held.robustY[q]) : 0.0) + double(held.d[q]);
    return std::isfinite(m) && m > 0.0 ? m : 0.0;
}

/// The light guide at (x, y): its plain light, at most the brightest of its 8 neighbours'.
double lightAt(const HeldRows& held, int x, int y) {
    double brightest = 0.0;  // of the 8 neighbours inside the image
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            const int qx = x + dx, qy = y + dy;
            if ((dx == 0 && dy == 0) || qx < 0 || qy < 0 || qx >= held.width || qy >= held.height)
                continue;
            brightest = std::max(brightest, plainLight(held, held.at(qx, qy)));
        }
    return std::min(plainLight(held, held.at(x, y)), brightest);
}

/// The 3 x 3 tent's weighted mean of the positive residual at (x, y).
double tentOfLoss(const HeldRows& held, int x, int y) {
    double sum = 0.0, weight = 0.0;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            const int qx = x + dx, qy = y + dy;
            if (qx < 0 || qy < 0 || qx >= held.width || qy >= held.height) continue;
            const double t = double((2 - std::abs(dx)) * (2 - std::abs(dy)));
            const float v = held.d[held.at(qx, qy)];
            sum += t * (std::isfinite(v) && v > 0.f ? double(v) : 0.0);
            weight += t;
        }
    return sum / weight;
}

}  // namespace

void guideRows(const HeldRows& held, int y0, int y1, float* cluster, float* light, int nthreads) {
    parallelFor(y0, y1, 0, nthreads, [&](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y)
            for (int x = 0; x < held.width; ++x) {
                const size_t o = size_t(y - y0) * size_t(held.width) + size_t(x);
                const double m = lightAt(held, x, y);
                if (light) light[o] = float(m);
                if (!cluster) continue;
                const double c = tentOfLoss(held, x, y);
                // Beyond a float (a residual near 1e38): the largest float, so that a window's
                // weights still sum to a finite value and its light returns whole.
                const double g = c * std::sqrt(m + c);
                cluster[o] = float(std::min(g, double(std::numeric_limits<float>::max())));
            }
    });
}

void biasGuideRows(const float* bias, const float* level, const float* guide, size_t n,
                   double floor, float* out, int nthreads) {
    parallelFor(0, int64_t(n), 0, nthreads, [&](int64_t b, int64_t e) {
        for (size_t p = size_t(b); p < size_t(e); ++p) {
            const double g = std::isfinite(guide[p]) && guide[p] > 0.f ? double(guide[p]) : 0.0;
            out[p] = g > 0.0 ? float(double(bias[p]) + floor * g * double(level[p])) : 0.f;
        }
    });
}

}  // namespace keeplight

void returnResidual(const float* robust, const double* residual, const uint8_t* scale,
                    const std::vector<int>& radii, int width, int height, int nch, float* out,
                    int nthreads, const float* guide, const float* clusterGuide,
                    const uint8_t* restScale, const float* restShare, const float* lightGuide,
                    const float* biasGuide, int biasRadius) {
    const size_t n = size_t(width) * size_t(height), nc = size_t(nch);
    keeplight::HeldRows held = keeplight::HeldRows::whole(width, height);
    held.nc = nc;
    held.residual = residual;
    held.scale = scale;
    held.guide = guide;
    held.cluster = clusterGuide;
    if (restScale && restShare) {
        held.restScale = restScale;
        held.restShare = restShare;
        held.light = lightGuide;
    }
    if (biasGuide && biasRadius >= 2) {
        held.biasGuide = biasGuide;
        held.biasRadius = biasRadius;
    }
    std::vector<double> norm(guide ? n : 0), clusterNorm(clusterGuide ? n : 0),
        lightNorm(held.light ? n : 0), biasNorm(held.biasGuide ? n : 0), add(n * nc);
    keeplight::normsRows(held, radii, 0, height, guide ? norm.data() : nullptr,
                         clusterGuide ? clusterNorm.data() : nullptr,
                         held.light ? lightNorm.data() : nullptr,
                         held.biasGuide ? biasNorm.data() : nullptr, nthreads);
    held.norm = norm.data();
    held.clusterNorm = clusterNorm.data();
    held.lightNorm = held.light ? lightNorm.data() : nullptr;
    held.biasNorm = held.biasGuide ? biasNorm.data() : nullptr;
    keeplight::GatherScratch scratch;
    keeplight::gatherRows(held, radii, 0, height, add.data(), scratch, nthreads);
    parallelFor(0, int64_t(n * nc), 0, nthreads, [&](int64_t b, int64_t e) {
        for (size_t i = size_t(b); i < size_t(e); ++i)
            out[i] = withReturnedLight(robust[i], add[i]);
    });
}

std::vector<float> keepLightClusterGuide(const float* robustY, const float* d, int width,
                                         int height, int nthreads) {
    keeplight::HeldRows held = keeplight::HeldRows::whole(width, height);
    held.robustY = robustY;
    held.d = d;
    std::vector<float> g(size_t(width) * size_t(height), 0.f);
    keeplight::guideRows(held, 0, height, g.data(), nullptr, nthreads);
    return g;
}

std::vector<float> keepLightLightGuide(const float* robustY, const float* d, int width, int height,
                                       int nthreads) {
    keeplight::HeldRows held = keeplight::HeldRows::whole(width, height);
    held.robustY = robustY;
    held.d = d;
    std::vector<float> g(size_t(width) * size_t(height), 0.f);
    keeplight::guideRows(held, 0, height, nullptr, g.data(), nthreads);
    return g;
}

std::vector<float> keepLightBiasGuide(const float* bias, const float* level, const float* guide,
                                      int width, int height, double floor) {
    const size_t n = size_t(width) * size_t(height);
    std::vector<float> g(n, 0.f);
    keeplight::biasGuideRows(bias, level, guide, n, floor, g.data(), 0);
    return g;
}

}  // namespace mcstat
