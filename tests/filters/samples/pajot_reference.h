// A deliberately plain re-implementation of Pajot et al. 2011's per-pixel estimator (Algorithm 1
// with the learning phase of section 4.1, ADR's update of section 4.2 with eq. 3-4, ROT's eq. 5 of
// section 4.4, the hybrid switch of section 4.6), with the conventions of
// include/mcstat/filters/samples/sample_delaying_kde.h, for the tests that pin PajotPixel to it bit
// for bit.
//
// Plain on purpose: every density is a scan over all modes, recomputed wherever it is needed; every
// log is taken where the equation has it; nothing is cached, reused or reordered; floor and ceil
// are the library's. The floating-point operations of each formula are the ones the estimator
// must perform (the same expressions in the same order), so an optimisation of PajotPixel that
// changes any double it derives a decision from makes the states differ here.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "mcstat/filters/samples/sample_delaying_kde.h"

namespace mcstat::pajot_ref {

inline constexpr float kNone = -std::numeric_limits<float>::infinity();

/// Epanechnikov kernel on [-1, 1] (eq. 3's K).
inline double kernel(double u) { return std::fabs(u) < 1.0 ? 0.75 * (1.0 - u * u) : 0.0; }

/// Kernels of bandwidths ha, hb at a <= b overlap, or the values are equal.
inline bool overlap(double a, double b, double ha, double hb) { return a == b || b - a < ha + hb; }

inline float logLuminance(const float rgb[3], const std::array<double, 3>& luma) {
    const double y = luma[0] * double(rgb[0]) + luma[1] * double(rgb[1]) + luma[2] * double(rgb[2]);
    if (!(y > 0.0)) return kNone;
    return float(std::log(y));
}

inline int64_t sampleCount(const std::vector<PajotMode>& modes) {
    int64_t n = 0;
    for (const PajotMode& m : modes) n += m.n;
    return n;
}

/// Sum of 4/3 K((x - v) / h) over the n regularly spaced values v of mode m (section 4.2's
/// approximate distribution), in closed form over the indices inside the window.
inline double modeSum(const PajotMode& m, double x, double h) {
    const double lo = m.lo, hi = m.hi;
    if (m.n == 1 || lo == hi) return double(m.n) * kernel((x - lo) / h) / 0.75;
    const double s = (hi - lo) / double(m.n - 1);
    const double tLo = (x - h - lo) / s, tHi = (x + h - lo) / s;
    // Window indices clamped to +-2^62 (NaN: -2^62) before the conversion, which beyond 2^63 is
    // undefined: a mode's spacing can be far below the bandwidth (denormal gaps).
    auto clamp = [](double t) {
        return t < 0x1p62 ? (t > -0x1p62 ? t : -0x1p62) : (t >= 0x1p62 ? 0x1p62 : -0x1p62);
    };
    const int64_t i0 = std::max<int64_t>(0, int64_t(std::floor(clamp(tLo))) + 1);
    const int64_t i1 = std::min<int64_t>(int64_t(m.n) - 1, int64_t(std::ceil(clamp(tHi))) - 1);
    if (i0 > i1) return 0.0;
    const double cnt = double(i1 - i0 + 1);
    const double a = (x - (lo + double(i0) * s)) / h, b = s / h;
    const double sj = cnt * (cnt - 1.0) / 2.0;
    const double sj2 = (cnt - 1.0) * cnt * (2.0 * cnt - 1.0) / 6.0;
    return std::max(0.0, cnt * (1.0 - a * a) + 2.0 * a * b * sj - b * b * sj2);
}

/// Eq. 3 at x with bandwidth h over the approximate distribution: every mode whose values can
/// reach x, in order.
inline double density(const std::vector<PajotMode>& modes, double x, double h) {
    const int64_t n = sampleCount(modes);
    if (n == 0 || !(h > 0.0)) return 0.0;
    double sum = 0;
    for (const PajotMode& m : modes) {
        if (double(m.hi) <= x - h) continue;  // wholly below the window
        if (!(double(m.lo) < x + h)) break;   // this one and every later one above it
        sum += modeSum(m, x, h);
    }
    return 0.75 * sum / (double(n) * h);
}

/// Mean nearest-neighbour distance of the approximate distribution.
inline double nearestNeighbour(const std::vector<PajotMode>& modes) {
    const int64_t n = sampleCount(modes);
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

/// Eq. 4's G: the geometric mean of the pilot density over min(n, 16) evenly spread points of
/// each mode (weight n / 16 each), a single mode at least nn from both neighbours counting its
/// own kernel's 0.75 / (n nn).
inline double geometricMean(const std::vector<PajotMode>& modes, double nn) {
    const int64_t total = sampleCount(modes);
    double logSum = 0, weight = 0;
    for (size_t k = 0; k < modes.size(); ++k) {
        const PajotMode& m = modes[k];
        const bool farBelow = k == 0 || double(m.lo) - double(modes[k - 1].hi) >= nn;
        const bool farAbove = k + 1 == modes.size() || double(modes[k + 1].lo) - double(m.hi) >= nn;
        if (m.n == 1 && farBelow && farAbove) {
            logSum += std::log(0.75 / (double(total) * nn));
            weight += 1;
            continue;
        }
        const int64_t q = std::min<int64_t>(m.n, 16);
        const double w = double(m.n) / double(q);
        for (int64_t t = 0; t < q; ++t) {
            const double pos = q == 1 ? 0.0 : double(t) / double(q - 1);
            const double x = double(m.lo) + (double(m.hi) - double(m.lo)) * pos;
            logSum += w * std::log(density(modes, x, nn));
            weight += w;
        }
    }
    return std::exp(logSum / weight);
}

/// Section 4.2's update by a non-black value l; what it computed in `trace` when given.
inline void updateModes(std::vector<PajotMode>& modes, float l, AdrUpdateTrace* trace = nullptr) {
    if (trace) *trace = AdrUpdateTrace();
    size_t k = 0;
    while (k < modes.size() && modes[k].hi < l) ++k;
    if (k < modes.size() && modes[k].lo <= l) {
        if (modes[k].n < UINT32_MAX) ++modes[k].n;
        return;
    }
    modes.insert(modes.begin() + std::ptrdiff_t(k), PajotMode{l, l, 1});
    const double nn = nearestNeighbour(modes);
    const double g = nn > 0.0 ? geometricMean(modes, nn) : 0.0;
    auto h = [&](double x) { return nn > 0.0 ? nn * std::sqrt(g / density(modes, x, nn)) : 0.0; };
    const double hl = h(l);
    const double hBelow = k > 0 ? h(modes[k - 1].hi) : 0.0;
    const double hAbove = k + 1 < modes.size() ? h(modes[k + 1].lo) : 0.0;
    if (trace) *trace = {true, nn, g, hl, hBelow, hAbove};
    const bool below = k > 0 && overlap(modes[k - 1].hi, l, hBelow, hl);
    const bool above = k + 1 < modes.size() && overlap(l, modes[k + 1].lo, hl, hAbove);
    const size_t first = below ? k - 1 : k, last = above ? k + 1 : k;
    if (first == last) return;
    uint64_t n = 0;
    for (size_t i = first; i <= last; ++i) n += modes[i].n;
    modes[first] = {modes[first].lo, modes[last].hi, uint32_t(std::min<uint64_t>(n, UINT32_MAX))};
    modes.erase(modes.begin() + std::ptrdiff_t(first) + 1,
                modes.begin() + std::ptrdiff_t(last) + 1);
}

/// The modes of sorted values with per-value bandwidths (section 4.2, initial learning).
inline std::vector<PajotMode> aggregate(const std::vector<float>& l, const std::vector<double>& h) {
    std::vector<PajotMode> modes;
    for (size_t i = 0; i < l.size(); ++i) {
        if (i > 0 && overlap(l[i - 1], l[i], h[i - 1], h[i]) && modes.back().n < UINT32_MAX) {
            modes.back().hi = l[i];
            ++modes.back().n;
        } else {
            modes.push_back({l[i], l[i], 1});
        }
    }
    return modes;
}

/// Eq. 4 over exact sorted values: h_i = nn (G / p(l_i))^(1/2), p with bandwidth nn.
inline std::vector<double> learningBandwidths(const std::vector<float>& l) {
    const size_t n = l.size();
    std::vector<double> h(n, 0.0);
    if (n < 2) return h;
    double nn = 0;
    for (size_t i = 0; i < n; ++i) {
        const double below = i > 0 ? double(l[i]) - double(l[i - 1]) : HUGE_VAL;
        const double above = i + 1 < n ? double(l[i + 1]) - double(l[i]) : HUGE_VAL;
        nn += std::min(below, above);
    }
    nn /= double(n);
    if (!(nn > 0.0)) return h;
    std::vector<double> pilot(n);
    double logSum = 0;
    for (size_t i = 0; i < n; ++i) {
        size_t first = 0;  // the first value within nn below l_i
        while (double(l[i]) - double(l[first]) >= nn) ++first;
        double sum = 0;
        for (size_t j = first; j < n && double(l[j]) - double(l[i]) < nn; ++j)
            sum += kernel((double(l[i]) - double(l[j])) / nn);
        pilot[i] = sum / (double(n) * nn);
        logSum += std::log(pilot[i]);
    }
    const double g = std::exp(logSum / double(n));
    for (size_t i = 0; i < n; ++i) h[i] = nn * std::sqrt(g / pilot[i]);
    return h;
}

inline float lastExtended(const std::vector<PajotMode>& modes) {
    for (size_t k = modes.size(); k-- > 0;)
        if (modes[k].n >= 2) return modes[k].hi;
    return kNone;
}

/// Eq. 5.
inline double rotH(int64_t n, double sigma) {
    return n < 1 ? 0.0 : std::pow(25.0 * double(n), -0.2) * sigma;
}

/// Welford's update of ROT's statistics, and their standard deviation (unbiased).
inline void rotAdd(PajotState& s, float l) {
    double n = double(s.rotN) + 1.0;
    const double d = double(l) - s.rotMean;
    s.rotMean += d / n;
    s.rotM2 += d * (double(l) - s.rotMean);
    ++s.rotN;
}
inline double rotSigma(const PajotState& s) {
    const double n = double(s.rotN);
    return std::sqrt(n > 1.0 ? s.rotM2 / (n - 1.0) : 0.0);
}

/// Section 4.4's regrouping of the singles above m with bandwidth h; returns the new m.
inline float rotRegroup(std::vector<float>& singles, float m, double h) {
    float top = m;
    size_t i = 0;
    if (m != kNone)
        while (i < singles.size() && overlap(top, singles[i], h, h)) top = singles[i++];
    float newM = top;
    for (size_t g = i; g < singles.size();) {
        size_t e = g;
        while (e + 1 < singles.size() && overlap(singles[e], singles[e + 1], h, h)) ++e;
        if (e > g) newM = singles[e];
        g = e + 1;
    }
    std::vector<float> kept;
    for (float v : singles)
        if (v > newM) kept.push_back(v);
    singles = kept;
    return newM;
}

/// Section 4.6's |m_rot - m_adr| / |m_adr|.
inline double hybridDistance(float mAdr, float mRot) {
    if (mAdr == mRot) return 0.0;
    if (mAdr == kNone || mRot == kNone || mAdr == 0.f) return HUGE_VAL;
    return std::fabs(double(mRot) - double(mAdr)) / std::fabs(double(mAdr));
}

/// One pixel: Algorithm 1.
class Pixel {
  public:
    PajotState s;

    bool add(const float rgb[3], const PajotParams& p) {
        if (!std::isfinite(rgb[0]) || !std::isfinite(rgb[1]) || !std::isfinite(rgb[2]))
            return false;
        ++s.taken;
        const PajotSample smp{{rgb[0], rgb[1], rgb[2]}, logLuminance(rgb, p.luma), -1};
        if (s.phase == PajotPhase::Learning) {
            s.learning.push_back(smp);
            if (int64_t(s.learning.size()) >= p.learning) endLearning(p);
            return true;
        }
        if (smp.l != kNone) {
            const float oldM = m(), oldAdr = s.mAdr, oldRot = s.mRot;
            if (s.phase == PajotPhase::ADR) {
                updateModes(s.modes, smp.l);
                s.mAdr = lastExtended(s.modes);
            }
            if (p.method != PajotMethod::ADR) {
                rotAdd(s, smp.l);
                if (smp.l > s.mRot) {
                    s.rotSingles.push_back(smp.l);
                    std::stable_sort(s.rotSingles.begin(), s.rotSingles.end());
                    s.mRot = rotRegroup(s.rotSingles, s.mRot, rotH(s.rotN, rotSigma(s)));
                }
            }
            if (p.method == PajotMethod::Hybrid && s.phase == PajotPhase::ADR &&
                (s.mAdr != oldAdr || s.mRot != oldRot))
                countDistance(p, s.run + 1);
            if (m() != oldM) retest();
        }
        offer(smp, p);
        return true;
    }

    float m() const {
        if (s.phase == PajotPhase::ADR) return s.mAdr;
        if (s.phase == PajotPhase::ROT) return s.mRot;
        return kNone;
    }

  private:
    void endLearning(const PajotParams& p) {
        std::vector<float> l;
        for (const PajotSample& smp : s.learning)
            if (smp.l != kNone) l.push_back(smp.l);
        std::vector<float> sorted = l;
        std::sort(sorted.begin(), sorted.end());
        s.mAdr = s.mRot = kNone;
        if (p.method != PajotMethod::ROT) {
            s.modes = aggregate(sorted, learningBandwidths(sorted));
            s.mAdr = lastExtended(s.modes);
        }
        if (p.method != PajotMethod::ADR) {
            for (float v : l) rotAdd(s, v);
            const double h = rotH(s.rotN, rotSigma(s));
            s.mRot = lastExtended(aggregate(sorted, std::vector<double>(sorted.size(), h)));
            for (float v : sorted)
                if (v > s.mRot) s.rotSingles.push_back(v);
        }
        s.phase = p.method == PajotMethod::ROT ? PajotPhase::ROT : PajotPhase::ADR;
        if (p.method == PajotMethod::Hybrid && (s.mAdr != kNone || s.mRot != kNone))
            countDistance(p, 1);
        const std::vector<PajotSample> learned = s.learning;
        s.learning.clear();
        s.learning.shrink_to_fit();
        for (const PajotSample& smp : learned) offer(smp, p);
    }

    /// Counts one distance between the maxima (`next`: the run if it is small); T small ones in
    /// a row switch the pixel to ROT alone, releasing ADR's modes.
    void countDistance(const PajotParams& p, int next) {
        s.run = hybridDistance(s.mAdr, s.mRot) <= p.delta ? next : 0;
        if (s.run >= p.T) {
            s.phase = PajotPhase::ROT;
            s.modes.clear();
        }
    }

    void offer(const PajotSample& smp, const PajotParams& p) {
        if (smp.l == kNone || smp.l <= m()) {
            splat(smp);
            return;
        }
        if (int64_t(s.delayed.size()) < int64_t(p.maxDelayed)) {
            s.delayed.push_back(smp);
            return;
        }
        ++s.discarded;
        if (s.delayed.empty()) return;
        size_t worst = 0;  // the first of the largest
        for (size_t i = 1; i < s.delayed.size(); ++i)
            if (s.delayed[worst].l < s.delayed[i].l) worst = i;
        if (s.delayed[worst].l > smp.l) {
            s.delayed.erase(s.delayed.begin() + std::ptrdiff_t(worst));
            s.delayed.push_back(smp);
        }
    }

    void splat(const PajotSample& smp) {
        for (size_t c = 0; c < 3; ++c) s.sum[c] += double(smp.rgb[c]);
        ++s.splatted;
    }

    void retest() {
        std::vector<PajotSample> still;
        for (const PajotSample& d : s.delayed) {
            if (d.l <= m())
                splat(d);
            else
                still.push_back(d);
        }
        s.delayed = still;
    }
};

/// The first field in which two states differ, bit for bit (doubles and floats by their bit
/// patterns), or "" when they are the same.
inline std::string firstDifference(const PajotState& a, const PajotState& b) {
    // n == 0 first: an empty vector's data() may be null, which memcmp must not be given.
    auto same = [](const void* x, const void* y, size_t n) {
        return n == 0 || std::memcmp(x, y, n) == 0;
    };
    auto sameSamples = [&](const std::vector<PajotSample>& x, const std::vector<PajotSample>& y) {
        if (x.size() != y.size()) return false;
        for (size_t i = 0; i < x.size(); ++i)
            if (!same(x[i].rgb.data(), y[i].rgb.data(), sizeof(float) * 3) ||
                !same(&x[i].l, &y[i].l, sizeof(float)) || x[i].tag != y[i].tag)
                return false;
        return true;
    };
    if (a.phase != b.phase) return "phase";
    if (!same(a.sum.data(), b.sum.data(), sizeof(double) * 3)) return "sum";
    if (a.splatted != b.splatted) return "splatted";
    if (a.discarded != b.discarded) return "discarded";
    if (a.taken != b.taken) return "taken";
    if (!sameSamples(a.learning, b.learning)) return "learning";
    if (!sameSamples(a.delayed, b.delayed)) return "delayed";
    if (a.modes.size() != b.modes.size()) return "modes (count)";
    for (size_t i = 0; i < a.modes.size(); ++i)
        if (!same(&a.modes[i].lo, &b.modes[i].lo, sizeof(float)) ||
            !same(&a.modes[i].hi, &b.modes[i].hi, sizeof(float)) || a.modes[i].n != b.modes[i].n)
            return "modes[" + std::to_string(i) + "]";
    if (!same(&a.mAdr, &b.mAdr, sizeof(float))) return "mAdr";
    if (a.rotN != b.rotN) return "rotN";
    if (!same(&a.rotMean, &b.rotMean, sizeof(double))) return "rotMean";
    if (!same(&a.rotM2, &b.rotM2, sizeof(double))) return "rotM2";
    if (!same(&a.mRot, &b.mRot, sizeof(float))) return "mRot";
    if (a.rotSingles.size() != b.rotSingles.size() ||
        !same(a.rotSingles.data(), b.rotSingles.data(), sizeof(float) * a.rotSingles.size()))
        return "rotSingles";
    if (a.run != b.run) return "run";
    return "";
}

}  // namespace mcstat::pajot_ref
