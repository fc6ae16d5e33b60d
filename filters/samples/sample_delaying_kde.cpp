// Pajot et al. 2011, Algorithm 1 with the learning phase (section 4.1), ADR (section 4.2, eq. 4),
// ROT (section 4.4, eq. 5) and the hybrid switch (section 4.6). The rules the paper leaves open are
// listed in include/mcstat/filters/samples/sample_delaying_kde.h; docs/pajot.md explains them.
#include "mcstat/filters/samples/sample_delaying_kde.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "mcstat/core/color_space.h"
#include "mcstat/core/moments.h"
#include "mcstat/core/params.h"

namespace mcstat {

namespace {

constexpr float kNoMode = -std::numeric_limits<float>::infinity();

/// Epanechnikov kernel (eq. 3's K, normalised on [-1, 1]).
inline double epanechnikov(double u) { return std::fabs(u) < 1.0 ? 0.75 * (1.0 - u * u) : 0.0; }

/// Kernels of bandwidths ha, hb centred at a <= b overlap, or the values are equal.
inline bool overlaps(double a, double b, double ha, double hb) { return a == b || b - a < ha + hb; }

double adrDensityOf(const std::vector<PajotMode>& modes, int64_t n, double x, double h);

int64_t totalSamples(const std::vector<PajotMode>& modes) {
    int64_t n = 0;
    for (const PajotMode& m : modes) n += m.n;
    return n;
}

/// t clamped to [-2^62, 2^62], NaN to -2^62: a window index beyond a mode's 2^32 values (a
/// spacing far below the bandwidth, e.g. denormal gaps beside values of order 1) stays beyond
/// them, and converting it to int64_t is defined (beyond 2^63 it is not). The window then holds
/// the mode's values the bandwidth reaches, and an index of NaN none.
inline double clampIndex(double t) {
    constexpr double kMax = 4611686018427387904.0;  // 2^62
    return t < kMax ? (t > -kMax ? t : -kMax) : (t >= kMax ? kMax : -kMax);
}

/// int64_t(std::floor(t)) and int64_t(std::ceil(t)), inline (without SSE4.1 the library's are
/// calls): for |t| < 2^52 truncation is exact and one step corrects it; beyond, the library's
/// own expression of the clamped value, so every input whose conversion was defined gives what
/// it gave before.
inline int64_t floorToInt(double t) {
    if (!(std::fabs(t) < 4503599627370496.0)) return int64_t(std::floor(clampIndex(t)));
    const int64_t i = int64_t(t);
    return double(i) > t ? i - 1 : i;
}
inline int64_t ceilToInt(double t) {
    if (!(std::fabs(t) < 4503599627370496.0)) return int64_t(std::ceil(clampIndex(t)));
    const int64_t i = int64_t(t);
    return double(i) < t ? i + 1 : i;
}

/// cnt (cnt - 1) / 2 and (cnt - 1) cnt (2 cnt - 1) / 6 for cnt = c as modeKernelSum computes them
/// in double: below 2^17 every product is an exact integer in double and divisible, so integer
/// arithmetic gives the same values without a division; above, the double expressions.
inline void indexSums(int64_t c, double& sj, double& sj2) {
    const double cnt = double(c);
    if (c < (int64_t(1) << 17)) {
        sj = double(c * (c - 1) / 2);
        sj2 = double((c - 1) * c * (2 * c - 1) / 6);
    } else {
        sj = cnt * (cnt - 1.0) / 2.0;
        sj2 = (cnt - 1.0) * cnt * (2.0 * cnt - 1.0) / 6.0;
    }
}

/// Sum over the n regularly spaced values of `m` of (1 - u^2) for |u| < 1, u = (x - value) / h:
/// closed form over the index range inside the window, relative to its first index so that the
/// sums stay small (no cancellation even for modes of millions of samples).
double modeKernelSum(const PajotMode& m, double x, double h) {
    const double lo = m.lo, hi = m.hi;
    if (m.n == 1 || lo == hi) return double(m.n) * epanechnikov((x - lo) / h) / 0.75;
    const double s = (hi - lo) / double(m.n - 1);
    const double tLo = (x - h - lo) / s, tHi = (x + h - lo) / s;
    const int64_t last = int64_t(m.n) - 1;
    const int64_t i0 = std::max<int64_t>(0, floorToInt(tLo) + 1);
    const int64_t i1 = std::min<int64_t>(last, ceilToInt(tHi) - 1);
    if (i0 > i1) return 0.0;
    const double cnt = double(i1 - i0 + 1);
    const double a = (x - (lo + double(i0) * s)) / h, b = s / h;
    double sj = 0, sj2 = 0;  // sum of j and of j^2, j < cnt
    indexSums(i1 - i0 + 1, sj, sj2);
    // sum_j 1 - (a - b j)^2 = cnt (1 - a^2) + 2 a b sum j - b^2 sum j^2
    return std::max(0.0, cnt * (1.0 - a * a) + 2.0 * a * b * sj - b * b * sj2);
}

/// Mean nearest-neighbour distance of the approximate distribution (adrNearestNeighbour) given its
/// sample count.
double nearestNeighbourOf(const std::vector<PajotMode>& modes, int64_t n) {
    if (n < 2) return 0.0;
    const double inf = std::numeric_limits<double>::infinity();
    double sum = 0;
    for (size_t k = 0; k < modes.size(); ++k) {
        const PajotMode& m = modes[k];
        const double below = k > 0 ? double(m.lo) - double(modes[k - 1].hi) : inf;
        const double above = k + 1 < modes.size() ? double(modes[k + 1].lo) - double(m.hi) : inf;
        if (m.n == 1) {
            sum += std::min(below, above);
        } else {
            const double s = (double(m.hi) - double(m.lo)) / double(m.n - 1);
            sum += std::min(s, below) + std::min(s, above) + double(m.n - 2) * s;
        }
    }
    return sum / double(n);
}

// ---- one ADR update's densities -----------------------------------------------------------------
// An update evaluates the pilot density (eq. 3, bandwidth nn) at up to 16 points per mode for eq.
// 4's geometric mean, then at three points for the bandwidths, all over the same modes with the
// same nn. AdrDensities holds what every one of those evaluations used to recompute (each mode's
// bounds in double, the spacing of its values and spacing / nn, n nn) and evaluates with the same
// operations in the same order, so that every density is the same double as adrDensityOf's.

/// A mode with the values modeKernelSum derives from it for bandwidth h.
struct ModeSpan {
    double lo = 0, hi = 0;
    double s = 0;  ///< (hi - lo) / (n - 1), extended modes with lo < hi
    double b = 0;  ///< s / h
    uint32_t n = 0;
};

/// modeKernelSum(m, x, h) with xmh = x - h and xph = x + h.
inline double spanKernelSum(const ModeSpan& m, double x, double xmh, double xph, double h) {
    if (m.n == 1 || m.lo == m.hi) return double(m.n) * epanechnikov((x - m.lo) / h) / 0.75;
    const double tLo = (xmh - m.lo) / m.s, tHi = (xph - m.lo) / m.s;
    const int64_t last = int64_t(m.n) - 1;
    const int64_t i0 = std::max<int64_t>(0, floorToInt(tLo) + 1);
    const int64_t i1 = std::min<int64_t>(last, ceilToInt(tHi) - 1);
    if (i0 > i1) return 0.0;
    const double cnt = double(i1 - i0 + 1);
    const double a = (x - (m.lo + double(i0) * m.s)) / h;
    double sj = 0, sj2 = 0;
    indexSums(i1 - i0 + 1, sj, sj2);
    return std::max(0.0, cnt * (1.0 - a * a) + 2.0 * a * m.b * sj - m.b * m.b * sj2);
}

class AdrDensities {
  public:
    /// Prepares the densities over `modes` (n samples) with bandwidth h > 0.
    void prepare(const std::vector<PajotMode>& modes, int64_t n, double h) {
        h_ = h;
        nh_ = double(n) * h;
        spans_.resize(modes.size());
        for (size_t k = 0; k < modes.size(); ++k) {
            const PajotMode& m = modes[k];
            ModeSpan& sp = spans_[k];
            sp.lo = m.lo;
            sp.hi = m.hi;
            sp.n = m.n;
            if (m.n != 1 && sp.lo != sp.hi) {
                sp.s = (sp.hi - sp.lo) / double(m.n - 1);
                sp.b = sp.s / h;
            }
        }
        first_ = 0;
    }
    /// adrDensityOf(modes, n, x, h). Consecutive calls at increasing x (the quadrature points of
    /// eq. 4, mode after mode) move the window's first mode forward instead of searching for it.
    double at(double x) {
        const double xmh = x - h_, xph = x + h_;
        const size_t count = spans_.size();
        // The first mode whose hi exceeds x - h (std::lower_bound's answer), from the last one.
        while (first_ < count && spans_[first_].hi <= xmh) ++first_;
        while (first_ > 0 && spans_[first_ - 1].hi > xmh) --first_;
        double sum = 0;
        for (size_t i = first_; i < count && spans_[i].lo < xph; ++i)
            sum += spanKernelSum(spans_[i], x, xmh, xph, h_);
        return 0.75 * sum / nh_;
    }

    /// Scratch of the geometric mean: the density and its log at every quadrature point.
    std::vector<double>& points() { return points_; }
    std::vector<double>& logs() { return logs_; }

  private:
    std::vector<ModeSpan> spans_;
    std::vector<double> points_, logs_;
    double h_ = 0, nh_ = 0;
    size_t first_ = 0;
};

/// double(t) / double(q - 1) for 0 <= t < q <= 16: the positions of eq. 4's quadrature points
/// within a mode, computed once.
const double* quadraturePositions(int64_t q) {
    static const std::array<std::array<double, 16>, 17> table = [] {
        std::array<std::array<double, 16>, 17> t{};
        for (int64_t n = 2; n <= 16; ++n)
            for (int64_t i = 0; i < n; ++i) t[size_t(n)][size_t(i)] = double(i) / double(n - 1);
        return t;
    }();
    return table[size_t(q)].data();
}

/// Mode j is a single sample at least nn from both neighbouring modes: its pilot density (eq. 3,
/// bandwidth nn) sees only its own kernel, exactly 0.75 / (n nn).
inline bool isolatedSingle(const std::vector<PajotMode>& modes, size_t j, double nn) {
    const PajotMode& m = modes[j];
    return m.n == 1 && (j == 0 || double(m.lo) - double(modes[j - 1].hi) >= nn) &&
           (j + 1 == modes.size() || double(modes[j + 1].lo) - double(m.hi) >= nn);
}

/// A density already evaluated at x (a quadrature point), kept for the bandwidths.
struct KnownDensity {
    double x = std::numeric_limits<double>::quiet_NaN();
    double p = 0;
};

/// Geometric mean of the pilot density over the approximate distribution (eq. 4's numerator).
/// Modes of at most 16 values use every value; larger ones 16 evenly spread values, each standing
/// for n / 16 of them (the density varies slowly inside an extended mode; this bounds the cost of
/// an update by the number of modes, not of samples). The densities at the last point of mode
/// k - 1, the point of mode k and the first point of mode k + 1 are kept in `known`.
double adrGeometricMeanDensity(const std::vector<PajotMode>& modes, int64_t total, double nn,
                               AdrDensities& density, size_t k, KnownDensity known[3]) {
    // A single mode farther than nn from both neighbours sees only its own kernel: its density is
    // exactly 0.75 / (n nn), no search needed. ADR accumulates many of those in the tails (section
    // 4.3, Table 1), so this keeps an update linear in the number of modes with a small constant.
    const double isolatedLog = std::log(0.75 / (double(total) * nn));
    // First every point's density (one sweep of the window over the modes), then the logs (calls
    // independent of each other), then the sum in the order of the points.
    std::vector<double>& p = density.points();
    p.clear();
    double lastX = std::numeric_limits<double>::quiet_NaN(), lastP = 0;
    for (size_t j = 0; j < modes.size(); ++j) {
        const PajotMode& m = modes[j];
        if (isolatedSingle(modes, j, nn)) continue;
        const int64_t q = std::min<int64_t>(m.n, 16);
        const double* pos = quadraturePositions(q);
        const double lo = m.lo, width = double(m.hi) - double(m.lo);
        for (int64_t t = 0; t < q; ++t) {
            const double x = lo + width * (q == 1 ? 0.0 : pos[t]);
            if (x != lastX) {
                lastX = x;
                lastP = density.at(x);
            }
            p.push_back(lastP);
            if (j + 1 == k && t == q - 1) known[0] = {x, lastP};
            if (j == k) known[1] = {x, lastP};
            if (j == k + 1 && t == 0) known[2] = {x, lastP};
        }
    }
    std::vector<double>& logs = density.logs();
    logs.resize(p.size());
    for (size_t i = 0; i < p.size(); ++i)
        logs[i] = i > 0 && p[i] == p[i - 1] ? logs[i - 1] : std::log(p[i]);
    double logSum = 0, weight = 0;
    size_t i = 0;
    for (size_t j = 0; j < modes.size(); ++j) {
        const PajotMode& m = modes[j];
        if (isolatedSingle(modes, j, nn)) {
            logSum += isolatedLog;
            weight += 1;
            continue;
        }
        const int64_t q = std::min<int64_t>(m.n, 16);
        const double w = double(m.n) / double(q);
        for (int64_t t = 0; t < q; ++t, ++i) {
            logSum += w * logs[i];
            weight += w;
        }
    }
    return std::exp(logSum / weight);
}

// ---- certified decisions: bounds of eq. 4's G without the quadrature's densities ----------------
// Pajot, Barthe, Paulin 2011, section 4.2, eq. 3-4: an update's modes depend on G only through two
// comparisons, d < h(x) + h(l) with h(x) = nn (G / p(x))^(1/2). Every pilot density is
// p(x) = 0.75 S(x) / (n nn), S(x) the sum of (1 - u^2), u = (x - v) / nn, over the values v of the
// approximate distribution with |u| < 1, so G = 0.75 / (n nn) times the weighted geometric mean of
// S at the quadrature points. Bounds of S at each point give bounds of G; when the comparisons come
// out the same at both bounds (with a margin for rounding), they are the exact code's comparisons.

/// F(t), the integral of (1 - u^2) over [0, t], t in [0, 1].
inline double kernelIntegral(double t) { return t - t * t * t * (1.0 / 3.0); }

/// A mode as the bounds see it: its values' spacing over nn, r, and 1 / r (0 for single modes and
/// modes of equal values).
struct BoundSpan {
    double r = 0, invR = 0;
};

/// Adds bounds of S at x from the values of mode `m` (spacing `sp`) when x lies outside
/// [m.lo, m.hi], gap nn from its nearest value (0 < gap < 1). Its values lie at gap + i r
/// (i < n), where the kernel decreases: r times their sum lies between the kernel's integral from
/// gap to gap + n r and its value at gap plus the integral from gap to gap + (n - 1) r (both cut
/// at 1); the nearest value alone gives 1 - gap^2.
inline void neighbourBounds(const PajotMode& m, const BoundSpan& sp, double gap, double& lo,
                            double& hi) {
    const double near = 1.0 - gap * gap;
    if (sp.invR == 0.0) {
        lo += double(m.n) * near;
        hi += double(m.n) * near;
        return;
    }
    const double fGap = kernelIntegral(gap);
    lo +=
        std::max(near, (kernelIntegral(std::min(1.0, gap + double(m.n) * sp.r)) - fGap) * sp.invR);
    hi += std::min(
        double(m.n) * near,
        near + (kernelIntegral(std::min(1.0, gap + double(m.n - 1) * sp.r)) - fGap) * sp.invR);
}

/// neighbourBounds of the modes around mode j that a point's window reaches: modes [from, j)
/// below it, their gap from xBelow, and modes (j, to) above it, their gap from xAbove.
inline void neighboursBounds(const std::vector<PajotMode>& modes,
                             const std::vector<BoundSpan>& spans, size_t from, size_t j, size_t to,
                             double xBelow, double xAbove, double invNn, double& lo, double& hi) {
    for (size_t i = from; i < j; ++i) {
        const double gap = (xBelow - double(modes[i].hi)) * invNn;
        if (gap < 1.0) neighbourBounds(modes[i], spans[i], gap, lo, hi);
    }
    for (size_t i = j + 1; i < to; ++i) {
        const double gap = (double(modes[i].lo) - xAbove) * invNn;
        if (gap < 1.0) neighbourBounds(modes[i], spans[i], gap, lo, hi);
    }
}

/// The spans of the modes (see BoundSpan) and `absSlack`, the exact code's rounding of its points,
/// values and closed forms (an absolute error per term of a few ulps of the values over nn, at most
/// `total` terms). False when no certificate can be had: a window index beyond 2^52, or a slack of
/// 1e-3 or more.
bool boundSpans(const std::vector<PajotMode>& modes, int64_t total, double invNn,
                std::vector<BoundSpan>& spans, double& absSlack) {
    const double eps = std::numeric_limits<double>::epsilon();
    double maxAbs = 0;
    spans.resize(modes.size());
    for (size_t j = 0; j < modes.size(); ++j) {
        const PajotMode& m = modes[j];
        maxAbs = std::max(maxAbs, std::max(std::fabs(double(m.lo)), std::fabs(double(m.hi))));
        BoundSpan& sp = spans[j];
        sp = BoundSpan();
        if (m.n != 1 && m.lo != m.hi) {
            sp.r = (double(m.hi) - double(m.lo)) / double(m.n - 1) * invNn;
            sp.invR = 1.0 / sp.r;
            // The closed form's window indices (x -+ nn - lo) / s, up to n - 1 + 2 / r in size,
            // must stay below 2^52, where its floor and ceiling are exact (beyond, the exact
            // code's conversions to int64_t give what they give): no certificate otherwise.
            if (!(sp.invR < 281474976710656.0)) return false;
        }
    }
    absSlack = (16.0 * eps * maxAbs * invNn + 64.0 * eps) * double(total);
    return absSlack < 1e-3;
}

/// One mode j, not an isolated single one, as the bounds at its points see it.
struct ModeBounds {
    /// The modes with values within nn of mode j's [lo, hi], and what its points share.
    ModeBounds(const std::vector<PajotMode>& modes_, const std::vector<BoundSpan>& spans_,
               size_t j_, double nn, double invNn_, double absSlack_)
        : modes(modes_),
          spans(spans_),
          j(j_),
          below(j_),
          above(j_ + 1),
          q(std::min<int64_t>(modes_[j_].n, 16)),
          lo(modes_[j_].lo),
          hi(modes_[j_].hi),
          width(hi - lo),
          invNn(invNn_),
          absSlack(absSlack_) {
        while (below > 0 && double(modes[below - 1].hi) > lo - nn) --below;
        while (above < modes.size() && double(modes[above].lo) < hi + nn) ++above;
    }

    const std::vector<PajotMode>& modes;
    const std::vector<BoundSpan>& spans;
    size_t j;
    size_t below, above;  ///< the modes [below, above) have values within nn of [lo, hi]
    int64_t q;            ///< its quadrature points
    double lo, hi, width, invNn, absSlack;
};

/// A mode's grid sums: the whole grid's sum, within [gridLo, gridHi], which is also the own values'
/// sum at a point whose window lies inside [lo, hi] (a, b >= 1; no other mode reaches such a
/// point), within [innerLo, innerHi] with the bounds at values and between them, n and the
/// rounding. All 0 for a mode of equal values.
struct GridSums {
    double gridLo = 0, gridHi = 0, innerLo = 0, innerHi = 0;
};

/// The grid sums of mode mb.j; only gridHi when `onlyHi` (the coarse bounds read no other).
GridSums gridSums(const ModeBounds& mb, bool onlyHi) {
    const PajotMode& m = mb.modes[mb.j];
    const BoundSpan own = mb.spans[mb.j];
    const double r = own.r;
    GridSums g;
    if (own.invR != 0.0) {
        g.gridHi = 4.0 / 3.0 * own.invR + r * (1.0 / 6.0) + 0.04 * r * r;
        if (!onlyHi) {
            g.gridLo = 4.0 / 3.0 * own.invR - r * (1.0 / 3.0) - 0.04 * r * r;
            g.innerLo = std::max(g.gridLo, mb.q == m.n ? 1.0 : r < 2.0 ? 1.0 - 0.25 * r * r : 0.0);
            g.innerHi = std::min(g.gridHi, double(m.n));
            g.innerLo = std::max(0.0, g.innerLo * (1.0 - 1e-9) - mb.absSlack);
            g.innerHi = g.innerHi * (1.0 + 1e-9) + mb.absSlack;
        }
    }
    return g;
}

/// The coarse bounds: one pair of bounds of S for every point of the mode, each multiplied into
/// prodLo, prodHi once per point. Own values: at least (F(min(a, 1)) + F(min(b, 1))) / r less
/// min(1, r/3 + 0.04 r^2) (the unimodal bound; the grid less its tails), a + b = w / nn with F
/// concave and F(0) = 0, so at least F(min(w / nn, 1)) / r less that; at least 1 at values,
/// 1 - (r/2)^2 elsewhere; at most the whole grid's sum, n and 4 / (3 r) + 1. Neighbours: at most
/// what they add at the mode's nearest end (their upper bound decreases with the gap), at least 0.
void coarseProducts(const ModeBounds& mb, double& prodLo, double& prodHi) {
    const PajotMode& m = mb.modes[mb.j];
    const BoundSpan own = mb.spans[mb.j];
    const double r = own.r;
    double sLo = double(m.n), sHi = double(m.n);
    if (own.invR != 0.0) {
        const double gridHi = gridSums(mb, true).gridHi;
        const double fw = kernelIntegral(std::min(1.0, mb.width * mb.invNn));
        sLo = std::max(fw * own.invR - std::min(1.0, r * (1.0 / 3.0) + 0.04 * r * r),
                       mb.q == m.n ? 1.0
                       : r < 2.0   ? 1.0 - 0.25 * r * r
                                   : 0.0);
        sHi = std::min(double(m.n), std::min(gridHi, 4.0 / 3.0 * own.invR + 1.0));
    }
    double unused = 0;
    neighboursBounds(mb.modes, mb.spans, mb.below, mb.j, mb.above, mb.lo, mb.hi, mb.invNn, unused,
                     sHi);
    sLo = std::max(0.0, sLo * (1.0 - 1e-9) - mb.absSlack);
    sHi = sHi * (1.0 + 1e-9) + mb.absSlack;
    for (int64_t t = 0; t < mb.q; ++t) {
        prodLo *= sLo;
        prodHi *= sHi;
    }
}

/// Bounds of the sum of a mode's own values (spacing r nn, not all equal) in the window of its
/// quadrature point t, x, within nn of an end (a = (x - lo) / nn < 1 or b = (hi - x) / nn < 1):
/// the grid's sum less its tails beyond lo and hi, the half grid at an end, the integral over the
/// window's part inside [lo, hi] within 1, and the bounds at values and between them.
void ownValuesBounds(const ModeBounds& mb, const GridSums& g, int64_t t, double x, double a,
                     double b, double& sLo, double& sHi) {
    const PajotMode& m = mb.modes[mb.j];
    const BoundSpan own = mb.spans[mb.j];
    const double r = own.r;
    const double full = kernelIntegral(1.0);
    // The grid's sum less its tails beyond lo and hi.
    double fa = full, fb = full, tailLo = 0, tailHi = 0;
    if (a < 1.0) {
        fa = kernelIntegral(std::max(0.0, a));
        tailHi += (full - fa) * own.invR;
        tailLo += (full - kernelIntegral(std::min(1.0, std::max(0.0, a) + r))) * own.invR;
    }
    if (b < 1.0) {
        fb = kernelIntegral(std::max(0.0, b));
        tailHi += (full - fb) * own.invR;
        tailLo += (full - kernelIntegral(std::min(1.0, std::max(0.0, b) + r))) * own.invR;
    }
    sLo = g.gridLo - tailHi;
    sHi = std::min(double(m.n), g.gridHi - tailLo);
    if ((x == mb.lo && b >= 1.0) || (x == mb.hi && a >= 1.0)) {
        sLo = std::max(sLo, 0.5 * (g.gridLo + 1.0));
        sHi = std::min(sHi, 0.5 * (g.gridHi + 1.0));
    }
    const double mid = (fa + fb) * own.invR;
    sLo = std::max(sLo, mid - 1.0);
    sHi = std::min(sHi, mid + 1.0);
    if (mb.q == m.n || t == 0 || t == mb.q - 1)
        sLo = std::max(sLo, 1.0);
    else if (r < 2.0)
        sLo = std::max(sLo, 1.0 - 0.25 * r * r);
}

/// The bounds per point: bounds of S at each of the mode's quadrature points (own values and the
/// neighbours that reach the point), multiplied into prodLo, prodHi.
void pointProducts(const ModeBounds& mb, double& prodLo, double& prodHi) {
    const PajotMode& m = mb.modes[mb.j];
    const BoundSpan own = mb.spans[mb.j];
    const GridSums g = gridSums(mb, false);
    const double* pos = quadraturePositions(mb.q);
    for (int64_t t = 0; t < mb.q; ++t) {
        const double x = mb.lo + mb.width * (mb.q == 1 ? 0.0 : pos[t]);
        const double a = (x - mb.lo) * mb.invNn, b = (mb.hi - x) * mb.invNn;
        if (a >= 1.0 && b >= 1.0 && own.invR != 0.0) {
            prodLo *= g.innerLo;
            prodHi *= g.innerHi;
            continue;
        }
        double sLo, sHi;
        if (own.invR == 0.0)
            sLo = sHi = double(m.n);
        else
            ownValuesBounds(mb, g, t, x, a, b, sLo, sHi);
        // Beyond nn from an end, no neighbour on that side is within nn of x.
        neighboursBounds(mb.modes, mb.spans, a < 1.0 ? mb.below : mb.j, mb.j,
                         b < 1.0 ? mb.above : mb.j + 1, x, x, mb.invNn, sLo, sHi);
        prodLo *= std::max(0.0, sLo * (1.0 - 1e-9) - mb.absSlack);
        prodHi *= sHi * (1.0 + 1e-9) + mb.absSlack;
    }
}

/// Sums of w log S over the points, lower and upper: modes of up to 16 values have w = 1, so their
/// bounds go into one running product (one log when it leaves [1e-200, 1e200], and at the end).
struct LogSums {
    double logLo = 0, logHi = 0, weight = 0;
    double unitLo = 1, unitHi = 1;
    int64_t terms = 0;

    /// An isolated single mode: S = 1 exactly.
    void addIsolated() {
        weight += 1;
        ++terms;
    }

    /// A mode of n values and q points whose bounds of S multiply to prodLo, prodHi.
    void addMode(int64_t n, int64_t q, double prodLo, double prodHi) {
        weight += double(n);
        terms += q;
        if (q == n) {
            unitLo *= prodLo;
            unitHi *= prodHi;
            if (!(unitHi < 1e200) || unitLo < 1e-200) {
                logLo += std::log(unitLo);  // -inf when a bound is 0: gLo = 0
                logHi += std::log(unitHi);
                unitLo = unitHi = 1;
            }
        } else {
            const double w = double(n) / double(q);
            logLo += w * std::log(prodLo);
            logHi += w * std::log(prodHi);
        }
    }

    /// gLo, gHi from the sums: 0.75 / (total nn) times the weighted geometric means, widened for
    /// the exact code's logs, weighted sum and exp (a few ulps of up to about 750 per term). False
    /// when a density could overflow or the slack is too large.
    bool bounds(int64_t total, double nn, double& gLo, double& gHi) {
        const double eps = std::numeric_limits<double>::epsilon();
        logLo += std::log(unitLo);
        logHi += std::log(unitHi);
        const double scale = 0.75 / (double(total) * nn);
        const double relSlack = 1e-9 + 4096.0 * eps * double(terms);
        // Every density the exact code computes, at most 0.75 total / (total nn), must be finite.
        if (!(relSlack < 1e-3) || !(scale > 0.0) || !(scale * double(total) < 1e300)) return false;
        gLo = scale * std::exp(logLo / weight) * (1.0 - relSlack);
        gHi = scale * std::exp(logHi / weight) * (1.0 + relSlack);
        return gHi < HUGE_VAL;
    }
};

/// Bounds of eq. 4's G as adrGeometricMeanDensity computes it (rounding included), over the same
/// quadrature points, without their densities. At a point x of a mode of spacing s = r nn (values
/// lo + i s, i < n, x in [lo, hi], a = (x - lo) / nn, b = (hi - x) / nn), the mode's own values in
/// the window sum to
///   - the sum over the infinite grid lo + i s, i in Z, which is 4 / (3 r) within
///     [-r/3 - 0.04 r^2, r/6 + 0.04 r^2] whatever the grid's offset (Euler-Maclaurin with the
///     periodic Bernoulli functions: the kernel's derivative jumps by 2 at both ends of the
///     window, B2 / 2 lies in [-1/24, 1/12], and the integral of B3 / 6 against the constant
///     second derivative -2 over the window is at most 0.04 r^2 in size), less the grid's tails
///     beyond lo and hi, whose values lie at a + i r and b + i r (i >= 1) where the kernel
///     decreases: r times a tail lies between the kernel's integral from a + r to 1 and from a to
///     1;
///   - at an end of the mode with the other end beyond the window, (the grid's sum at a value + 1)
///     / 2, by symmetry;
///   - within 1 of the kernel's integral over the window's part inside [lo, hi], over r (the sum of
///     a unimodal function at points spaced r that reach both ends of an interval differs from its
///     integral over r by at most its maximum);
///   - at least 1 at the mode's own values (every point of a mode of up to 16 values, the ends of
///     larger ones), at least 1 - (r/2)^2 elsewhere (a value lies within s/2);
///   - at most n.
/// The neighbouring modes within nn add what neighbourBounds says; single modes and modes of equal
/// values give n (1 - u^2) exactly. Every bound is widened for the exact code's rounding: its
/// points, values and closed forms (an absolute error per term of a few ulps of the values over nn,
/// at most `total` terms), its logs, weighted sum and exp (a few ulps of up to about 750 per
/// term). `coarse`: one pair of bounds per mode instead (cheaper, looser; coarseProducts). Returns
/// false when no bounds can be formed (positions too coarse against nn, a product out of range);
/// gLo may be 0.
bool adrGeometricMeanBounds(const std::vector<PajotMode>& modes, int64_t total, double nn,
                            std::vector<BoundSpan>& spans, bool coarse, double& gLo, double& gHi) {
    const double invNn = 1.0 / nn;
    double absSlack = 0;
    if (!boundSpans(modes, total, invNn, spans, absSlack)) return false;
    LogSums sums;
    for (size_t j = 0; j < modes.size(); ++j) {
        if (isolatedSingle(modes, j, nn)) {
            sums.addIsolated();
            continue;
        }
        const ModeBounds mb(modes, spans, j, nn, invNn, absSlack);
        double prodLo = 1, prodHi = 1;
        if (coarse)
            coarseProducts(mb, prodLo, prodHi);
        else
            pointProducts(mb, prodLo, prodHi);
        if (!(prodHi < 1e200)) return false;  // at most 16 factors of at most 2^32 each
        sums.addMode(modes[j].n, mb.q, prodLo, prodHi);
    }
    return sums.bounds(total, nn, gLo, gHi);
}

}  // namespace

const char* pajotMethodName(PajotMethod m) {
    switch (m) {
        case PajotMethod::ADR:
            return "adr";
        case PajotMethod::ROT:
            return "rot";
        case PajotMethod::Hybrid:
            return "hybrid";
    }
    return "?";
}

bool parsePajotMethod(const std::string& text, PajotMethod& out) {
    if (text == "adr")
        out = PajotMethod::ADR;
    else if (text == "rot")
        out = PajotMethod::ROT;
    else if (text == "hybrid")
        out = PajotMethod::Hybrid;
    else
        return false;
    return true;
}

bool validatePajotParams(const PajotParams& p, std::string& err) {
    if (p.learning < 1 || p.learning > 1000000) {
        err = "pajot: n (learning samples) must be in [1, 1000000], not " +
              std::to_string(p.learning);
        return false;
    }
    if (p.maxDelayed < 0 || p.maxDelayed > 1000000) {
        err = "pajot: delayed (dubious list bound) must be in [0, 1000000], not " +
              std::to_string(p.maxDelayed);
        return false;
    }
    if (p.T < 1 || p.T > 1000000) {
        err = "pajot: t must be in [1, 1000000], not " + std::to_string(p.T);
        return false;
    }
    if (!(p.delta >= 0.0) || !std::isfinite(p.delta)) {
        err = "pajot: delta must be a finite number >= 0";
        return false;
    }
    for (double w : p.luma)
        if (!std::isfinite(w)) {
            err = "pajot: luma coefficients must be finite";
            return false;
        }
    return true;
}

float pajotLogLuminance(const float rgb[3], const std::array<double, 3>& luma) {
    const double y = luminance(luma, rgb);
    if (!(y > 0.0)) return kNoMode;  // black: zero, or negative components summing to <= 0
    return float(std::log(y));
}

double adrNearestNeighbour(const std::vector<PajotMode>& modes) {
    return nearestNeighbourOf(modes, totalSamples(modes));
}

double adrDensity(const std::vector<PajotMode>& modes, double x, double h) {
    return adrDensityOf(modes, totalSamples(modes), x, h);
}

namespace {

double adrDensityOf(const std::vector<PajotMode>& modes, int64_t n, double x, double h) {
    if (n == 0 || !(h > 0.0)) return 0.0;
    // Modes are sorted and disjoint: start at the first whose hi reaches the window.
    auto it = std::lower_bound(modes.begin(), modes.end(), x - h,
                               [](const PajotMode& m, double v) { return double(m.hi) <= v; });
    double sum = 0;
    for (; it != modes.end() && double(it->lo) < x + h; ++it) sum += modeKernelSum(*it, x, h);
    return 0.75 * sum / (double(n) * h);
}

}  // namespace

double rotBandwidth(int64_t n, double sigma) {
    if (n < 1) return 0.0;
    return std::pow(25.0 * double(n), -0.2) * sigma;  // eq. 5
}

namespace {

/// aggregateModes into `modes` (emptied first).
void aggregateModesInto(const std::vector<float>& l, const std::vector<double>& h,
                        std::vector<PajotMode>& modes) {
    modes.clear();
    for (size_t i = 0; i < l.size(); ++i) {
        if (i > 0 && overlaps(l[i - 1], l[i], h[i - 1], h[i]) && modes.back().n < UINT32_MAX) {
            modes.back().hi = l[i];
            ++modes.back().n;
        } else {
            modes.push_back({l[i], l[i], 1});
        }
    }
}

/// adaptiveBandwidths into `h`, with `pilot` as scratch.
void adaptiveBandwidthsInto(const std::vector<float>& l, std::vector<double>& h,
                            std::vector<double>& pilot) {
    const size_t n = l.size();
    h.assign(n, 0.0);
    if (n < 2) return;
    double nn = 0;  // mean nearest-neighbour distance
    for (size_t i = 0; i < n; ++i) {
        const double below = i > 0 ? double(l[i]) - double(l[i - 1]) : HUGE_VAL;
        const double above = i + 1 < n ? double(l[i + 1]) - double(l[i]) : HUGE_VAL;
        nn += std::min(below, above);
    }
    nn /= double(n);
    if (!(nn > 0.0)) return;  // all equal: zero bandwidths, one mode of equal values
    // Pilot density at every value with bandwidth nn (eq. 3), a window over the sorted values.
    pilot.resize(n);
    double logSum = 0, lastLog = 0;
    size_t first = 0;
    for (size_t i = 0; i < n; ++i) {
        if (i > 0 && l[i] == l[i - 1]) {  // the same window, the same sum: the same density
            pilot[i] = pilot[i - 1];
            logSum += lastLog;
            continue;
        }
        while (double(l[i]) - double(l[first]) >= nn) ++first;
        double sum = 0;
        for (size_t j = first; j < n && double(l[j]) - double(l[i]) < nn; ++j)
            sum += epanechnikov((double(l[i]) - double(l[j])) / nn);
        pilot[i] = sum / (double(n) * nn);
        lastLog = std::log(pilot[i]);
        logSum += lastLog;
    }
    const double g = std::exp(logSum / double(n));
    for (size_t i = 0; i < n; ++i) h[i] = nn * std::sqrt(g / pilot[i]);  // eq. 4
}

/// lastExtendedUpperBound(aggregateModes(l, h for every value)) without building the modes: the
/// last value that joins its predecessor's mode ends the last extended mode.
float lastExtendedUpperBoundOf(const std::vector<float>& l, double h) {
    for (size_t i = l.size(); i-- > 1;)
        if (overlaps(l[i - 1], l[i], h, h)) return l[i];
    return kNoMode;
}

}  // namespace

std::vector<PajotMode> aggregateModes(const std::vector<float>& l, const std::vector<double>& h) {
    std::vector<PajotMode> modes;
    aggregateModesInto(l, h, modes);
    return modes;
}

std::vector<double> adaptiveBandwidths(const std::vector<float>& l) {
    std::vector<double> h, pilot;
    adaptiveBandwidthsInto(l, h, pilot);
    return h;
}

float lastExtendedUpperBound(const std::vector<PajotMode>& modes) {
    for (auto it = modes.rbegin(); it != modes.rend(); ++it)
        if (it->extended()) return it->hi;
    return kNoMode;
}

// ---- the per-pixel estimator --------------------------------------------------------------------

namespace {
thread_local uint64_t certifiedUpdates = 0;
}  // namespace

uint64_t adrCertifiedUpdates() { return certifiedUpdates; }

void adrUpdate(std::vector<PajotMode>& modes, float l, AdrUpdateTrace* trace) {
    if (trace) *trace = AdrUpdateTrace();
    auto it = std::lower_bound(modes.begin(), modes.end(), l,
                               [](const PajotMode& m, float v) { return m.hi < v; });
    if (it != modes.end() && it->lo <= l) {  // inside [lo, hi] of a mode: one more sample
        if (it->n < UINT32_MAX) ++it->n;
        return;
    }
    // A new single mode; its kernel (bandwidth from eq. 4 over the approximate distribution that
    // now includes it) may overlap the neighbouring modes' extreme samples' kernels.
    const size_t k = size_t(it - modes.begin());
    modes.insert(it, PajotMode{l, l, 1});
    const int64_t total = totalSamples(modes);
    const double nn = nearestNeighbourOf(modes, total);
    // Scratch of the thread's updates: no allocation per sample once it has grown.
    thread_local AdrDensities scratch;
    AdrDensities& density = scratch;
    // Certified decisions (Pajot, Barthe, Paulin 2011, section 4.2, eq. 3-4): the modes depend on
    // G only through the two comparisons d < h(x) + h(l), h(x) = nn (G / p(x))^(1/2). With bounds
    // gLo <= G <= gHi (adrGeometricMeanBounds) and the three densities, a comparison that comes
    // out the same at both bounds, with a relative margin of 1e-9 for the rounding of the
    // bandwidths and their sum, comes out so at G: its h sum is nn sqrt(G) (p(x)^(-1/2) +
    // p(l)^(-1/2)), increasing in G. Only when one sits between them is the exact G computed. The
    // trace wants the exact values, and records what the bounds decided beside them.
    // `ia`, `ib` are p(a)^(-1/2), p(b)^(-1/2) and `hLo`, `hHi` nn sqrt(gLo), nn sqrt(gHi), each
    // computed once per update (per pair of bounds) instead of in every comparison: the same
    // doubles from the same expressions, so the same decisions.
    auto verdict = [](double a, double b, double ia, double ib, double hLo, double hHi) {
        if (a == b) return 1;  // overlaps() without bandwidths
        const double d = b - a, inv = ia + ib;
        if (d < hLo * inv * (1.0 - 1e-9)) return 1;
        if (d >= hHi * inv * (1.0 + 1e-9)) return 0;
        return -1;
    };
    int certBelow = -1, certAbove = -1;  // -1: not settled by the bounds
    double gLo = 0, gHi = 0;
    // The densities at l and at the neighbouring ends, once the bounds have asked for them (NaN
    // before): the exact bandwidths reuse them.
    double pl = std::numeric_limits<double>::quiet_NaN(), pb = pl, pa = pl;
    if (nn > 0.0) {
        density.prepare(modes, total, nn);
        thread_local std::vector<BoundSpan> spans;
        // Coarse bounds first (one pair per mode), then bounds per point, then the exact G.
        if (adrGeometricMeanBounds(modes, total, nn, spans, true, gLo, gHi)) {
            pl = density.at(l);
            if (k > 0) pb = density.at(modes[k - 1].hi);
            if (k + 1 < modes.size()) pa = density.at(modes[k + 1].lo);
            auto usable = [](double p) { return p > 0.0 && p < HUGE_VAL; };
            if (usable(pl) && (k == 0 || usable(pb)) && (k + 1 == modes.size() || usable(pa))) {
                const double il = 1.0 / std::sqrt(pl);
                const double ib = k > 0 ? 1.0 / std::sqrt(pb) : 0.0;
                const double ia = k + 1 < modes.size() ? 1.0 / std::sqrt(pa) : 0.0;
                auto decide = [&] {
                    const double hLo = nn * std::sqrt(gLo), hHi = nn * std::sqrt(gHi);
                    certBelow = k > 0 ? verdict(modes[k - 1].hi, l, ib, il, hLo, hHi) : 0;
                    certAbove =
                        k + 1 < modes.size() ? verdict(l, modes[k + 1].lo, il, ia, hLo, hHi) : 0;
                    return certBelow >= 0 && certAbove >= 0;
                };
                if (!decide() && adrGeometricMeanBounds(modes, total, nn, spans, false, gLo, gHi))
                    decide();
            }
        }
    }
    bool below = certBelow == 1, above = certAbove == 1;
    if (!trace && certBelow >= 0 && certAbove >= 0) {
        ++certifiedUpdates;
    } else {
        // The exact G (eq. 4 over the quadrature points) and bandwidths.
        KnownDensity known[3];
        double g = 0.0;
        if (nn > 0.0) g = adrGeometricMeanDensity(modes, total, nn, density, k, known);
        // h = nn (G / p(x))^(1/2) (eq. 4), p(x) from the geometric mean's points when it is one,
        // else the bounds' `p` when they computed it (NaN when not).
        auto bandwidth = [&density, nn, g](double x, const KnownDensity& kd, double p) {
            if (!(nn > 0.0)) return 0.0;
            return nn * std::sqrt(g / (kd.x == x ? kd.p : std::isnan(p) ? density.at(x) : p));
        };
        const double hl = bandwidth(l, known[1], pl);
        const double hBelow = k > 0 ? bandwidth(modes[k - 1].hi, known[0], pb) : 0.0;
        const double hAbove = k + 1 < modes.size() ? bandwidth(modes[k + 1].lo, known[2], pa) : 0.0;
        below = k > 0 && overlaps(modes[k - 1].hi, l, hBelow, hl);
        above = k + 1 < modes.size() && overlaps(l, modes[k + 1].lo, hl, hAbove);
        if (trace)
            *trace = {true,  nn,    g,         hl,        hBelow, hAbove,
                      below, above, certBelow, certAbove, gLo,    gHi};
    }
    // Merging on both sides replaces the two modes and the new sample by one extended mode.
    size_t first = k, last = k;
    if (below) first = k - 1;
    if (above) last = k + 1;
    if (first == last) return;
    PajotMode merged{modes[first].lo, modes[last].hi, 0};
    uint64_t n = 0;
    for (size_t i = first; i <= last; ++i) n += modes[i].n;
    merged.n = uint32_t(std::min<uint64_t>(n, UINT32_MAX));
    modes[first] = merged;
    modes.erase(modes.begin() + std::ptrdiff_t(first) + 1,
                modes.begin() + std::ptrdiff_t(last) + 1);
}

namespace {

/// ROT's modes above m from the sorted singles with the constant bandwidth h (section 4.4): the
/// singles chained to the last extended mode extend it; a group of overlapping singles above
/// becomes the new last extended mode. Returns the new m and drops the singles at or below it.
float rotRebuild(std::vector<float>& singles, float m, double h) {
    float top = m;
    size_t i = 0;
    if (m != kNoMode)
        while (i < singles.size() && overlaps(top, singles[i], h, h)) top = singles[i++];
    float newM = top;
    for (size_t g = i; g < singles.size();) {
        size_t e = g;
        while (e + 1 < singles.size() && overlaps(singles[e], singles[e + 1], h, h)) ++e;
        if (e > g) newM = singles[e];
        g = e + 1;
    }
    singles.erase(singles.begin(), std::upper_bound(singles.begin(), singles.end(), newM));
    return newM;
}

/// ROT's statistics as the running moments they are (core/moments.h); the state keeps their
/// fields, the file stores them exactly.
RunningMoments rotMoments(const PajotState& s) { return {double(s.rotN), s.rotMean, s.rotM2}; }

double rotSigma(const PajotState& s) { return rotMoments(s).sigma(); }

void welford(PajotState& s, float l) {
    RunningMoments m = rotMoments(s);
    m.add(double(l));
    ++s.rotN;
    s.rotMean = m.mean;
    s.rotM2 = m.m2;
}

/// Section 4.6's relative distance |m_rot - m_adr| / |m_adr|; equal values (both absent
/// included) are 0, one absent or m_adr = 0 with m_rot != 0 is infinite.
double hybridDistance(float mAdr, float mRot) {
    if (mAdr == mRot) return 0.0;
    if (mAdr == kNoMode || mRot == kNoMode || mAdr == 0.f) return HUGE_VAL;
    return std::fabs(double(mRot) - double(mAdr)) / std::fabs(double(mAdr));
}

}  // namespace

bool PajotPixel::add(const float rgb[3], const PajotParams& p, int64_t tag) {
    if (!std::isfinite(rgb[0]) || !std::isfinite(rgb[1]) || !std::isfinite(rgb[2])) return false;
    ++s_.taken;
    const PajotSample smp{{rgb[0], rgb[1], rgb[2]}, pajotLogLuminance(rgb, p.luma), tag};
    if (s_.phase == PajotPhase::Learning) {
        // One allocation for the learning samples (the usual N; a large N grows as it comes).
        if (s_.learning.empty() && p.learning <= 4096) s_.learning.reserve(size_t(p.learning));
        s_.learning.push_back(smp);
        if (int64_t(s_.learning.size()) >= p.learning) finishLearning(p);
        return true;
    }
    if (smp.l != kNoMode) {
        const float oldM = acceptance();
        const float oldAdr = s_.mAdr, oldRot = s_.mRot;
        if (s_.phase == PajotPhase::ADR) {
            adrUpdate(s_.modes, smp.l);
            s_.mAdr = lastExtendedUpperBound(s_.modes);
        }
        if (p.method != PajotMethod::ADR) {
            welford(s_, smp.l);
            if (smp.l > s_.mRot) {
                s_.rotSingles.insert(
                    std::upper_bound(s_.rotSingles.begin(), s_.rotSingles.end(), smp.l), smp.l);
                s_.mRot = rotRebuild(s_.rotSingles, s_.mRot, rotBandwidth(s_.rotN, rotSigma(s_)));
            }
        }
        if (p.method == PajotMethod::Hybrid && s_.phase == PajotPhase::ADR &&
            (s_.mAdr != oldAdr || s_.mRot != oldRot)) {
            s_.run = hybridDistance(s_.mAdr, s_.mRot) <= p.delta ? s_.run + 1 : 0;
            if (s_.run >= p.T) {  // ROT alone from now on; ADR's data is released
                s_.phase = PajotPhase::ROT;
                std::vector<PajotMode>().swap(s_.modes);
            }
        }
        if (acceptance() != oldM) retest();
    }
    offer(smp, p);
    return true;
}

void PajotPixel::finishLearning(const PajotParams& p) {
    // Scratch of the thread's learning phases: no allocation per pixel once it has grown.
    struct Scratch {
        std::vector<float> l, sorted;
        std::vector<double> h, pilot;
    };
    thread_local Scratch sc;
    std::vector<float>& l = sc.l;  // non-black log-luminances in the order taken
    l.clear();
    for (const PajotSample& smp : s_.learning)
        if (smp.l != kNoMode) l.push_back(smp.l);
    std::vector<float>& sorted = sc.sorted;
    sorted.assign(l.begin(), l.end());
    std::sort(sorted.begin(), sorted.end());
    s_.mAdr = s_.mRot = kNoMode;
    if (p.method != PajotMethod::ROT) {
        adaptiveBandwidthsInto(sorted, sc.h, sc.pilot);
        aggregateModesInto(sorted, sc.h, s_.modes);
        s_.mAdr = lastExtendedUpperBound(s_.modes);
    }
    if (p.method != PajotMethod::ADR) {
        for (float v : l) welford(s_, v);
        s_.mRot = lastExtendedUpperBoundOf(sorted, rotBandwidth(s_.rotN, rotSigma(s_)));
        // Modes at or below m are released (section 4.4); above m every mode is single.
        s_.rotSingles.assign(std::upper_bound(sorted.begin(), sorted.end(), s_.mRot), sorted.end());
    }
    s_.phase = p.method == PajotMethod::ROT ? PajotPhase::ROT : PajotPhase::ADR;
    if (p.method == PajotMethod::Hybrid && (s_.mAdr != kNoMode || s_.mRot != kNoMode)) {
        s_.run = hybridDistance(s_.mAdr, s_.mRot) <= p.delta ? 1 : 0;
        if (s_.run >= p.T) {
            s_.phase = PajotPhase::ROT;
            std::vector<PajotMode>().swap(s_.modes);
        }
    }
    std::vector<PajotSample> learned;
    learned.swap(s_.learning);
    for (const PajotSample& smp : learned) offer(smp, p);
}

float PajotPixel::acceptance() const {
    switch (s_.phase) {
        case PajotPhase::ADR:
            return s_.mAdr;
        case PajotPhase::ROT:
            return s_.mRot;
        case PajotPhase::Learning:
            break;
    }
    return kNoMode;
}

void PajotPixel::offer(const PajotSample& smp, const PajotParams& p) {
    if (smp.l == kNoMode || smp.l <= acceptance())
        splat(smp);
    else
        delay(smp, p);
}

void PajotPixel::splat(const PajotSample& smp) {
    for (int c = 0; c < 3; ++c) s_.sum[size_t(c)] += double(smp.rgb[size_t(c)]);
    ++s_.splatted;
    if (splatLog_) splatLog_->push_back(smp.tag);
}

std::vector<int64_t> PajotPixel::splatTags(const std::vector<int64_t>& log) const {
    if (s_.phase != PajotPhase::Learning) return log;
    std::vector<int64_t> tags;
    for (const PajotSample& smp : s_.learning) tags.push_back(smp.tag);
    return tags;
}

void PajotPixel::delay(const PajotSample& smp, const PajotParams& p) {
    if (int64_t(s_.delayed.size()) < int64_t(p.maxDelayed)) {
        s_.delayed.push_back(smp);
        return;
    }
    ++s_.discarded;  // full: the largest log-luminance of the list and the newcomer goes
    if (s_.delayed.empty()) return;
    auto worst =
        std::max_element(s_.delayed.begin(), s_.delayed.end(),
                         [](const PajotSample& a, const PajotSample& b) { return a.l < b.l; });
    if (worst->l > smp.l) {
        s_.delayed.erase(worst);
        s_.delayed.push_back(smp);
    }
}

void PajotPixel::retest() {
    const float m = acceptance();
    size_t kept = 0;
    for (size_t i = 0; i < s_.delayed.size(); ++i) {
        if (s_.delayed[i].l <= m)
            splat(s_.delayed[i]);
        else
            s_.delayed[kept++] = s_.delayed[i];
    }
    s_.delayed.resize(kept);
}

std::array<float, 3> PajotPixel::estimate() const {
    std::array<double, 3> sum{0, 0, 0};
    int64_t n = 0;
    if (s_.phase == PajotPhase::Learning) {  // nothing classified yet: the plain mean
        for (const PajotSample& smp : s_.learning)
            for (size_t c = 0; c < 3; ++c) sum[c] += double(smp.rgb[c]);
        n = int64_t(s_.learning.size());
    } else {
        sum = s_.sum;
        n = s_.splatted;
    }
    if (n == 0) return {0.f, 0.f, 0.f};
    return {float(sum[0] / double(n)), float(sum[1] / double(n)), float(sum[2] / double(n))};
}

PajotCounts PajotPixel::counts() const {
    PajotCounts c;
    for (const PajotMode& m : s_.modes) (m.extended() ? c.extendedModes : c.singleModes) += 1;
    if (s_.phase != PajotPhase::Learning && (s_.rotN > 0 || s_.phase == PajotPhase::ROT)) {
        c.singleModes += int64_t(s_.rotSingles.size());
        if (s_.mRot != kNoMode) c.extendedModes += 1;
    }
    c.delayed = int64_t(s_.delayed.size());
    c.bytes = int64_t(s_.modes.size() * sizeof(PajotMode) + s_.rotSingles.size() * sizeof(float) +
                      (s_.delayed.size() + s_.learning.size()) * sizeof(PajotSample));
    return c;
}

}  // namespace mcstat
