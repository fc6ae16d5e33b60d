// PajotPixel against the plain re-implementation of tests/filters/samples/pajot_reference.h,
// sample by sample, bit for bit: the estimator's speed-ups (issue 24: cached per-mode quantities,
// a sliding window, reused densities and logs, scratch instead of allocations) must leave every
// decision, and so the whole state, as the equations computed the obvious way give it.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "mcstat/filters/samples/sample_delaying_kde.h"
#include "pajot_reference.h"

namespace mcstat {
namespace {

using Rgb = std::array<float, 3>;

/// The kinds of pixels the streams imitate.
enum class Kind {
    Body,        ///< log-normal body, black samples, rare fireflies
    Caustic,     ///< a bright cluster that starts recurring a third of the way in
    Levels,      ///< values from a few levels: runs of equal values, modes of zero width
    HeavyTail,   ///< Pareto-like: a long tail of single modes (ADR's Table 1 growth)
    Signs,       ///< negative components (some sum to Y <= 0), and NaN / Inf refused
    Constant,    ///< all equal, then other values late
    Magnitudes,  ///< 1e-30 .. 1e30 and denormal luminances
};
constexpr Kind kKinds[] = {Kind::Body,  Kind::Caustic,  Kind::Levels,    Kind::HeavyTail,
                           Kind::Signs, Kind::Constant, Kind::Magnitudes};

std::vector<Rgb> stream(Kind kind, int count, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::normal_distribution<double> gauss(0.0, 1.0);
    const double level = std::exp(gauss(rng)), spread = 0.2 + 1.3 * u(rng);
    const Rgb tint{float(0.7 + 0.6 * u(rng)), 1.f, float(0.7 + 0.6 * u(rng))};
    auto grey = [&](double y) { return Rgb{float(y * tint[0]), float(y), float(y * tint[2])}; };
    std::vector<Rgb> out;
    for (int i = 0; i < count; ++i) {
        const double r = u(rng);
        double y = level * std::exp(spread * gauss(rng));
        switch (kind) {
            case Kind::Body:
                if (r < 0.05) y = 0.0;
                if (r > 0.99) y *= 100.0 + 1e4 * u(rng);
                break;
            case Kind::Caustic:
                if (i > count / 3 && r < 0.12) y = 60.0 * level * (1.0 + 0.1 * gauss(rng));
                if (r > 0.995) y *= 1e3;
                break;
            case Kind::Levels: {
                const double levels[] = {0.25, 0.5, 1.0, 2.0};
                if (r < 0.9) y = level * levels[size_t(4.0 * u(rng)) % 4];
                break;
            }
            case Kind::HeavyTail:
                y = level * std::pow(std::max(u(rng), 1e-12), -1.5);
                break;
            case Kind::Signs:
                if (r < 0.01) {
                    out.push_back({std::numeric_limits<float>::quiet_NaN(), 1.f, 1.f});
                    continue;
                }
                if (r < 0.02) {
                    out.push_back({1.f, std::numeric_limits<float>::infinity(), 1.f});
                    continue;
                }
                if (r < 0.2) {  // one negative component; the sum may or may not stay positive
                    out.push_back({float(y), float(-y * 2.0 * u(rng)), float(y * u(rng))});
                    continue;
                }
                break;
            case Kind::Constant:
                y = i < count * 3 / 4 || r < 0.5 ? level : level * (1.0 + 3.0 * u(rng));
                break;
            case Kind::Magnitudes:
                y = std::pow(10.0, -30.0 + 60.0 * u(rng));
                if (r < 0.05) y = 1e-40;
                break;
        }
        out.push_back(grey(y));
    }
    return out;
}

struct Case {
    const char* name;
    int learning, maxDelayed, T;
    double delta;
};
constexpr Case kCases[] = {
    {"paper", 50, 64, 2, 0.0},   // the paper's defaults (section 5)
    {"short", 5, 3, 1, 0.3},     // short learning, a full dubious list, a quick hybrid switch
    {"one", 1, 0, 2, 0.0},       // learning ends at the first sample; nothing can be delayed
    {"middle", 20, 8, 3, 0.05},  //
};

/// Feeds `samples` to PajotPixel and to the reference; false with `where` at the first sample
/// after which anything differs.
bool sameAllAlong(const std::vector<Rgb>& samples, const PajotParams& p, std::string& where) {
    PajotPixel px;
    pajot_ref::Pixel ref;
    for (size_t i = 0; i < samples.size(); ++i) {
        const bool a = px.add(samples[i].data(), p), b = ref.add(samples[i].data(), p);
        std::string diff =
            a != b ? "add()'s answer" : pajot_ref::firstDifference(px.state(), ref.s);
        const float ma = px.acceptance(), mb = ref.m();
        if (diff.empty() && std::memcmp(&ma, &mb, sizeof ma) != 0) diff = "acceptance";
        if (!diff.empty()) {
            where = "sample " + std::to_string(i) + ": " + diff;
            return false;
        }
    }
    return true;
}

class PajotReference : public ::testing::TestWithParam<PajotMethod> {};

TEST_P(PajotReference, EverySampleLeavesTheStateOfThePlainImplementation) {
    int pixels = 0, modesSeen = 0, delayedSeen = 0, switched = 0;
    for (const Case& c : kCases) {
        PajotParams p;
        p.method = GetParam();
        p.learning = c.learning;
        p.maxDelayed = c.maxDelayed;
        p.T = c.T;
        p.delta = c.delta;
        for (const Kind kind : kKinds)
            for (uint64_t seed = 1; seed <= 5; ++seed) {
                const std::vector<Rgb> s = stream(kind, 1000, seed * 7919 + uint64_t(kind));
                std::string where;
                EXPECT_TRUE(sameAllAlong(s, p, where))
                    << c.name << ", kind " << int(kind) << ", seed " << seed << ": " << where;
                PajotPixel px;
                for (const Rgb& v : s) px.add(v.data(), p);
                modesSeen = std::max(modesSeen, int(px.state().modes.size()));
                delayedSeen += int(px.state().delayed.size() + px.state().discarded);
                switched += p.method == PajotMethod::Hybrid && px.state().phase == PajotPhase::ROT;
                ++pixels;
            }
    }
    // The streams reach what the speed-ups touch: many modes, delayed samples, the switch.
    if (GetParam() != PajotMethod::ROT) {
        EXPECT_GT(modesSeen, 30);
    }
    EXPECT_GT(delayedSeen, pixels);
    if (GetParam() == PajotMethod::Hybrid) {
        EXPECT_GT(switched, 0);
    }
}

TEST_P(PajotReference, ALongTailOfModes) {
    // Thousands of samples with a heavy tail: ADR's modes number in the hundreds, so an update's
    // window slides over many modes of every width.
    PajotParams p;
    p.method = GetParam();
    const std::vector<Rgb> s = stream(Kind::HeavyTail, 10000, 424242);
    std::string where;
    EXPECT_TRUE(sameAllAlong(s, p, where)) << where;
    PajotPixel px;
    for (const Rgb& v : s) px.add(v.data(), p);
    if (GetParam() == PajotMethod::ADR) {
        EXPECT_GT(px.state().modes.size(), 100u);
    }
}

/// The same double, bit for bit (NaN payloads and the sign of zero included).
bool sameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

std::string traceText(const AdrUpdateTrace& t) {
    char buf[200];
    std::snprintf(buf, sizeof buf, "inserted %d nn %.17g g %.17g h %.17g below %.17g above %.17g",
                  int(t.inserted), t.nn, t.g, t.h, t.hBelow, t.hAbove);
    return buf;
}

TEST(PajotReferenceAdr, EveryUpdateComputesTheSameDoubles) {
    // The decisions of an update rarely sit within a rounding of their threshold, so the states
    // above would survive most one-ulp changes; here every double an update derives them from
    // (nn, G, the three bandwidths), the learning's eq. 4 bandwidths, the densities and the mean
    // nearest-neighbour distance must be the reference's, bit for bit.
    int updates = 0, densities = 0;
    for (const Kind kind : kKinds)
        for (uint64_t seed = 1; seed <= 8; ++seed) {
            std::vector<float> l;
            for (const Rgb& v : stream(kind, 1500, seed * 104729 + uint64_t(kind))) {
                if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2])) continue;
                const float x = pajot_ref::logLuminance(v.data(), PajotParams().luma);
                if (x != pajot_ref::kNone) l.push_back(x);
            }
            ASSERT_GT(l.size(), 60u);
            std::vector<float> sorted(l.begin(), l.begin() + 50);
            std::sort(sorted.begin(), sorted.end());
            const std::vector<double> h = adaptiveBandwidths(sorted),
                                      hRef = pajot_ref::learningBandwidths(sorted);
            for (size_t i = 0; i < h.size(); ++i)
                ASSERT_TRUE(sameBits(h[i], hRef[i]))
                    << "learning bandwidth " << i << ": " << h[i] << " vs " << hRef[i];
            std::vector<PajotMode> modes = aggregateModes(sorted, h),
                                   ref = pajot_ref::aggregate(sorted, hRef);
            PajotState a, b;
            for (size_t i = 50; i < l.size(); ++i) {
                AdrUpdateTrace ta, tb;
                adrUpdate(modes, l[i], &ta);
                pajot_ref::updateModes(ref, l[i], &tb);
                const std::string where = "kind " + std::to_string(int(kind)) + ", seed " +
                                          std::to_string(seed) + ", value " + std::to_string(i);
                ASSERT_TRUE(ta.inserted == tb.inserted && sameBits(ta.nn, tb.nn) &&
                            sameBits(ta.g, tb.g) && sameBits(ta.h, tb.h) &&
                            sameBits(ta.hBelow, tb.hBelow) && sameBits(ta.hAbove, tb.hAbove))
                    << where << "\n  " << traceText(ta) << "\n  " << traceText(tb);
                a.modes = modes;
                b.modes = ref;
                ASSERT_EQ(pajot_ref::firstDifference(a, b), "") << where;
                updates += ta.inserted;
                if (i % 50 != 0) continue;
                ASSERT_TRUE(sameBits(adrNearestNeighbour(modes), pajot_ref::nearestNeighbour(ref)))
                    << where;
                // Densities at every mode's ends and middle and between modes, at nn and wider.
                const double nn = pajot_ref::nearestNeighbour(ref);
                for (size_t k = 0; k < ref.size(); ++k) {
                    const double lo = ref[k].lo, hi = ref[k].hi;
                    const double next = k + 1 < ref.size() ? double(ref[k + 1].lo) : hi + 1.0;
                    for (const double x : {lo, hi, 0.5 * (lo + hi), 0.5 * (hi + next)})
                        for (const double bw : {nn, 3.0 * nn + 1e-3, 0.37}) {
                            ASSERT_TRUE(
                                sameBits(adrDensity(modes, x, bw), pajot_ref::density(ref, x, bw)))
                                << where << ", x " << x << ", h " << bw;
                            ++densities;
                        }
                }
            }
        }
    EXPECT_GT(updates, 4000);
    EXPECT_GT(densities, 20000);
}

TEST(PajotReferenceAdr, TheArithmeticsEdgesGiveTheSameDoubles) {
    // Windows whose ends fall exactly on a mode's values (the floor and ceiling of an integer
    // quotient), modes of equal values, single modes, and bandwidths from learning values that are
    // equal or one float apart.
    const std::vector<PajotMode> modes{{0, 4, 5}, {6, 6, 1}, {7, 7, 3}, {8, 10, 3}, {12, 20, 9}};
    int checked = 0;
    for (double x = -2.0; x <= 22.0; x += 0.25)
        for (const double h : {0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 8.0}) {
            ASSERT_TRUE(sameBits(adrDensity(modes, x, h), pajot_ref::density(modes, x, h)))
                << "x " << x << ", h " << h;
            ++checked;
        }
    EXPECT_EQ(checked, 97 * 7);
    const float one = 1.f, next = std::nextafter(1.f, 2.f), after = std::nextafter(next, 2.f);
    const std::vector<std::vector<float>> learning{
        {one, one, one, next, 2.f, 2.f, 3.f},
        {one, next, after, 1.5f, 1.5f, 1.5f, 4.f, 4.f},
        {-3.f, -3.f, 0.f, 0.f, 0.f, 1e-30f, 2e-30f, 7.f},
        {5.f, 5.f, 5.f, 5.f},
    };
    for (const std::vector<float>& l : learning) {
        const std::vector<double> h = adaptiveBandwidths(l), ref = pajot_ref::learningBandwidths(l);
        ASSERT_EQ(h.size(), ref.size());
        for (size_t i = 0; i < h.size(); ++i)
            EXPECT_TRUE(sameBits(h[i], ref[i])) << i << ": " << h[i] << " vs " << ref[i];
    }
    // Updates next to modes of equal values and into gaps of exactly one window.
    std::vector<PajotMode> a = modes, b = modes;
    for (const float l : {5.f, 11.f, 6.5f, 21.f, -1.f, 11.5f, 25.f, 7.5f, 23.f}) {
        AdrUpdateTrace ta, tb;
        adrUpdate(a, l, &ta);
        pajot_ref::updateModes(b, l, &tb);
        EXPECT_TRUE(ta.inserted == tb.inserted && sameBits(ta.nn, tb.nn) && sameBits(ta.g, tb.g) &&
                    sameBits(ta.h, tb.h) && sameBits(ta.hBelow, tb.hBelow) &&
                    sameBits(ta.hAbove, tb.hAbove))
            << "value " << l << "\n  " << traceText(ta) << "\n  " << traceText(tb);
        PajotState sa, sb;
        sa.modes = a;
        sb.modes = b;
        ASSERT_EQ(pajot_ref::firstDifference(sa, sb), "") << "value " << l;
    }
}

/// The modes' floats and counts, bit for bit.
bool sameModes(const std::vector<PajotMode>& a, const std::vector<PajotMode>& b) {
    if (a.size() != b.size()) return false;
    for (size_t i = 0; i < a.size(); ++i)
        if (std::memcmp(&a[i].lo, &b[i].lo, sizeof(float)) != 0 ||
            std::memcmp(&a[i].hi, &b[i].hi, sizeof(float)) != 0 || a[i].n != b[i].n)
            return false;
    return true;
}

/// Log-luminance streams for the certified updates: the shapes whose bounds are loosest or
/// whose arithmetic is the most fragile.
enum class LogKind { Clustered, HeavyTail, Equal, TinyGaps, Denormal, Mixed };

std::vector<float> logStream(LogKind kind, int count, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::normal_distribution<double> gauss(0.0, 1.0);
    const double centre = 4.0 * gauss(rng);
    std::vector<float> out;
    for (int i = 0; i < count; ++i) {
        const double r = u(rng);
        double l = centre + gauss(rng);
        switch (kind) {
            case LogKind::Clustered:  // three tight clusters and scattered values between them
                l = centre + 2.0 * double(int(3.0 * u(rng))) + 0.05 * gauss(rng);
                if (r < 0.1) l = centre - 1.0 + 6.0 * u(rng);
                break;
            case LogKind::HeavyTail:  // log of a Pareto variable: a long tail of single modes
                l = centre + 1.5 * -std::log(std::max(u(rng), 1e-300));
                break;
            case LogKind::Equal:  // a few levels: runs of equal values, modes of zero width
                l = centre + 0.25 * double(int(4.0 * u(rng)));
                if (r < 0.15) l += 0.01 * gauss(rng);
                break;
            case LogKind::TinyGaps: {  // values one float apart or a few
                float v = float(centre);
                for (int k = int(40.0 * u(rng)); k > 0; --k) v = std::nextafter(v, 1e30f);
                out.push_back(r < 0.05 ? float(centre + gauss(rng)) : v);
                continue;
            }
            case LogKind::Denormal:  // denormal floats: gaps of 1.4e-45
                out.push_back(float(double(int(200.0 * u(rng) * u(rng))) * 1.401298464324817e-45));
                continue;
            // The above together; denormal values only alone (beside values of order 1 their
            // spacings overflow the exact code's int64_t window indices: undefined behaviour, as
            // before the certified decisions).
            case LogKind::Mixed:
                if (r < 0.2) {
                    l = centre + 0.25 * double(int(4.0 * u(rng)));
                } else if (r < 0.3) {
                    l = centre + 1.5 * -std::log(std::max(u(rng), 1e-300));
                } else if (r < 0.4) {
                    float v = float(centre + 2.0);
                    for (int k = int(8.0 * u(rng)); k > 0; --k) v = std::nextafter(v, 1e30f);
                    out.push_back(v);
                    continue;
                }
                break;
        }
        out.push_back(float(l));
    }
    return out;
}

TEST(PajotReferenceAdr, CertifiedUpdatesKeepEveryDecision) {
    // Without a trace an update decides its merges from bounds of eq. 4's G when they settle them
    // (filters/samples/sample_delaying_kde.cpp, adrGeometricMeanBounds). Every sample goes through
    // that update, through the traced update (the exact G, which also records what the bounds
    // decided) and through the plain reference; the modes must agree after every sample, the
    // bounds must hold G and agree with the exact decisions wherever they settled them, and they
    // must settle a good share of the updates (else the test tests nothing).
    const LogKind kinds[] = {LogKind::Clustered, LogKind::HeavyTail, LogKind::Equal,
                             LogKind::TinyGaps,  LogKind::Denormal,  LogKind::Mixed};
    int64_t inserted = 0, certified = 0, settledTraced = 0;
    for (const LogKind kind : kinds) {
        int64_t kindInserted = 0, kindCertified = 0;
        for (uint64_t seed = 1; seed <= 10; ++seed) {
            const std::vector<float> l = logStream(kind, 2000, seed * 7919 + uint64_t(kind));
            std::vector<float> sorted(l.begin(), l.begin() + 50);
            std::sort(sorted.begin(), sorted.end());
            std::vector<PajotMode> modes = aggregateModes(sorted, adaptiveBandwidths(sorted));
            std::vector<PajotMode> traced = modes, ref = modes;
            for (size_t i = 50; i < l.size(); ++i) {
                const uint64_t before = adrCertifiedUpdates();
                AdrUpdateTrace t;
                adrUpdate(modes, l[i]);
                adrUpdate(traced, l[i], &t);
                pajot_ref::updateModes(ref, l[i]);
                const std::string where = "kind " + std::to_string(int(kind)) + ", seed " +
                                          std::to_string(seed) + ", value " + std::to_string(i);
                ASSERT_TRUE(sameModes(modes, ref)) << where;
                ASSERT_TRUE(sameModes(traced, ref)) << where;
                const uint64_t now = adrCertifiedUpdates() - before;
                ASSERT_LE(now, uint64_t(t.inserted)) << where;
                kindInserted += t.inserted;
                kindCertified += int64_t(now);
                if (!t.inserted) continue;
                // Certified without a trace exactly when the traced update's bounds settled both.
                ASSERT_EQ(now == 1, t.certBelow >= 0 && t.certAbove >= 0) << where;
                if (t.certBelow >= 0) {
                    ASSERT_EQ(t.certBelow == 1, t.below) << where;
                }
                if (t.certAbove >= 0) {
                    ASSERT_EQ(t.certAbove == 1, t.above) << where;
                }
                if (t.gHi > 0.0) {
                    ASSERT_LE(t.gLo, t.g) << where;
                    ASSERT_LE(t.g, t.gHi) << where;
                }
                settledTraced += t.certBelow >= 0 && t.certAbove >= 0;
            }
        }
        std::printf("kind %d: %lld of %lld updates certified\n", int(kind),
                    static_cast<long long>(kindCertified), static_cast<long long>(kindInserted));
        inserted += kindInserted;
        certified += kindCertified;
    }
    EXPECT_EQ(certified, settledTraced);
    EXPECT_GT(inserted, 7000);
    EXPECT_GT(certified * 4, inserted * 3) << certified << " of " << inserted;
}

TEST(PajotReferenceAdr, DenormalGapsBesideOrdinaryValuesKeepEveryDecision) {
    // Log-luminances a few denormals apart (a mode's spacing near 1e-45) beside values of order 1
    // (nn and the bandwidths near 0.01-1): a density's window index (x - h - lo) / spacing is
    // near 1e43, beyond int64_t. The indices are clamped before the conversion (which was
    // undefined: the sanitizer build stopped here), so the window holds the mode's values the
    // bandwidth reaches. The update and the reference agree after every sample, and the result
    // is a state with finite bounds.
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int run = 0; run < 20; ++run) {
        std::vector<float> l;
        for (int i = 0; i < 600; ++i) {
            const double r = u(rng);
            l.push_back(r < 0.5 ? float(double(int(50.0 * u(rng))) * 1.401298464324817e-45)
                                : float(0.5 + 2.0 * u(rng)));
        }
        std::vector<float> sorted(l.begin(), l.begin() + 50);
        std::sort(sorted.begin(), sorted.end());
        std::vector<PajotMode> modes = aggregateModes(sorted, adaptiveBandwidths(sorted));
        std::vector<PajotMode> ref = modes;
        for (size_t i = 50; i < l.size(); ++i) {
            adrUpdate(modes, l[i]);
            pajot_ref::updateModes(ref, l[i]);
            ASSERT_TRUE(sameModes(modes, ref)) << "run " << run << ", value " << i;
        }
        for (const PajotMode& m : modes) {
            ASSERT_TRUE(std::isfinite(m.lo) && std::isfinite(m.hi) && m.lo <= m.hi);
        }
        // The denormal values gathered into a mode of many samples.
        uint32_t most = 0;
        for (const PajotMode& m : modes)
            if (m.hi < 1e-30f) most = std::max(most, m.n);
        EXPECT_GT(most, 100u) << "run " << run;
    }
}

INSTANTIATE_TEST_SUITE_P(Methods, PajotReference,
                         ::testing::Values(PajotMethod::ADR, PajotMethod::ROT, PajotMethod::Hybrid),
                         [](const ::testing::TestParamInfo<PajotMethod>& param) {
                             return std::string(pajotMethodName(param.param));
                         });

}  // namespace
}  // namespace mcstat
