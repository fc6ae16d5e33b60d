// The comparison's verdict from every p-value (comparison.h): the rejection thresholds by the
// rule, the strongest findings, the counts, Mitsuba 3's pass fraction and the test's power.
#include <map>

#include "comparison.h"

namespace mcstat::detail {

namespace {

/// Whether p-value `p` is rejected at threshold `thr` (a NaN never is).
bool rejectedAt(float p, double thr) { return !std::isnan(p) && double(p) <= thr; }

/// Of `n` pixels or tiles (quantity qi's p-value of place i at p[qi * n + i], Q quantities), how
/// many have a tested quantity not rejected at `thr`.
size_t countNotRejected(const std::vector<float>& p, size_t n, size_t Q, double thr) {
    size_t count = 0;
    for (size_t i = 0; i < n; ++i)
        for (size_t qi = 0; qi < Q; ++qi) {
            const float pv = p[qi * n + i];
            if (!std::isnan(pv) && !rejectedAt(pv, thr)) {
                ++count;
                break;
            }
        }
    return count;
}

/// The median of `v` (reordered); NaN when empty.
double medianOf(std::vector<double>& v) {
    if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
    const auto mid = v.begin() + long(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    if (v.size() % 2) return *mid;
    return 0.5 * (*mid + *std::max_element(v.begin(), mid));
}

}  // namespace

/// Mitsuba 3's verdict (src/render/tests/test_renders.py): every pixel's channel tests at the
/// Sidak level 1 - (1 - level)^(1 / pixels); a pass when at least passFraction of the pixels pass,
/// counting passed channel tests / channels. A channel test without a p-value (NaN) does not pass,
/// as NaN > alpha is false there.
void Comparison::finishMitsuba() {
    const double alpha = out_.threshold;
    out_.channelTests = p_.size();
    out_.channelTestsPassed =
        size_t(std::count_if(p_.begin(), p_.end(), [&](float p) { return double(p) > alpha; }));
    out_.fail =
        double(out_.channelTestsPassed) / double(q_.size()) < opt_.passFraction * double(P_);
}

void Comparison::setThresholds() {
    const bool equivalence = opt_.test == TwoSampleTest::Equivalence;
    size_t mp = 0, mt = 0;
    if (opt_.rule == CompareOptions::Rule::Mitsuba) {
        // Sidak: 1 - (1 - level)^(1 / pixels), the pixels' count as Mitsuba 3 takes it (all of
        // them; its three channel tests per pixel are not counted).
        out_.threshold = -std::expm1(std::log1p(-opt_.level) / double(P_));
        out_.hypotheses = p_.size();
    } else if (!equivalence) {
        // Two families, pixels and tiles, each at half the level (Bonferroni over the two), so
        // that the verdict's error rate stays at the level: one family would drown a few hundred
        // tiles among millions of pixels, whose count sets the step-up's slope.
        const double q = T_ > 0 ? opt_.level / 2.0 : opt_.level;
        out_.threshold = rejectionThreshold(p_, q, opt_.control, &mp);
        out_.tileThreshold = T_ > 0 ? rejectionThreshold(tileP_, q, opt_.control, &mt) : -1.0;
        out_.hypotheses = mp + mt;
    } else {
        // Equivalence: the intersection-union principle (Berger, Statistical Science 17(4), 1996)
        // shows "all agree" when every hypothesis is rejected at the level itself, with no
        // correction. It is decided on the tiles when there are any (a single pixel's noise rarely
        // allows showing it), else on the pixels.
        out_.threshold = rejectionThreshold(p_, opt_.level, Multiplicity::None, &mp);
        out_.tileThreshold =
            T_ > 0 ? rejectionThreshold(tileP_, opt_.level, Multiplicity::None, &mt) : -1.0;
        out_.hypotheses = T_ > 0 ? mt : mp;
    }
}

// The strongest finding: the rejected hypothesis of largest |z| (difference; none rejected: the
// largest |z| tested), the tested one of largest p (equivalence).
bool Comparison::strongerFinding(float p, float z, const CompareFinding& f, double thr) const {
    if (!f.valid) return true;
    if (opt_.test == TwoSampleTest::Equivalence) return double(p) > f.result.p;
    const bool rp = rejectedAt(p, thr), rf = rejectedAt(float(f.result.p), thr);
    if (rp != rf) return rp;
    return std::fabs(double(z)) > std::fabs(f.result.z);
}

void Comparison::fillFinding(CompareFinding& f, bool tile, size_t index, size_t qi, float p,
                             float z, float d, float a) const {
    f.valid = true;
    f.tile = tile;
    const size_t W = tile ? size_t(tilesX_) : size_t(out_.width);
    const int scale = tile ? out_.tile : 1;
    f.x = out_.originX + int(index % W) * scale;
    f.y = out_.originY + int(index / W) * scale;
    f.quantity = q_[qi].name;
    f.a = a;
    f.b = double(a) + double(d);
    f.result.p = p;
    f.result.z = z;
    f.result.difference = d;
    f.result.se = std::isfinite(z) && z != 0.f ? double(d) / double(z) : 0.0;
    f.result.margin = margin(f.a, f.b);
}

void Comparison::findStrongest(size_t& pixRejected, size_t& tileRejected) {
    // Per pixel and tile: rejected in any quantity.
    const size_t Q = q_.size();
    pixRejected = 0;
    for (size_t p = 0; p < P_; ++p) {
        bool any = false;
        for (size_t qi = 0; qi < Q; ++qi) {
            const size_t h = qi * P_ + p;
            const float pv = p_[h];
            if (std::isnan(pv)) continue;
            if (rejectedAt(pv, out_.threshold)) {
                any = true;
                if (std::isfinite(z_[h])) {
                    ++out_.rejectedNoisy;
                    if (z_[h] < 0.f) ++out_.rejectedDarker;
                }
            }
            if (pixelNonFinite_[p] == 0 &&
                strongerFinding(pv, z_[h], out_.strongest, out_.threshold))
                fillFinding(out_.strongest, false, p, qi, pv, z_[h], effect_[h], aEst_[h]);
        }
        if (any) ++pixRejected;
    }
    tileRejected = 0;
    for (size_t t = 0; t < T_; ++t) {
        bool any = false;
        for (size_t qi = 0; qi < Q; ++qi) {
            const size_t h = qi * T_ + t;
            if (std::isnan(tileP_[h])) continue;
            if (rejectedAt(tileP_[h], out_.tileThreshold)) any = true;
            if (strongerFinding(tileP_[h], tileZ_[h], out_.strongestTile, out_.tileThreshold))
                fillFinding(out_.strongestTile, true, t, qi, tileP_[h], tileZ_[h], tileEffect_[h],
                            tileA_[h]);
        }
        if (any) ++tileRejected;
    }
}

void Comparison::countNotEquivalent(size_t& pixNot, size_t& tileNot) const {
    // Rejected means "shown equivalent": what counts is what was not.
    pixNot = countNotRejected(p_, P_, q_.size(), out_.threshold);
    tileNot = countNotRejected(tileP_, T_, q_.size(), out_.tileThreshold);
}

void Comparison::finish() {
    out_.pixels = P_;
    out_.tiles = T_;
    out_.pixelsTested = tally_.pixelsTested;
    out_.tilesTested = tally_.tilesTested;
    out_.nonFiniteOneSide = tally_.nonFiniteOneSide;
    out_.nonFiniteBoth = tally_.nonFiniteBoth;
    out_.constantEqual = tally_.constantEqual;
    out_.fewBuffers = tally_.fewBuffers;
    out_.identical = tally_.allZero && tally_.pixelsTested > 0 && tally_.nonFiniteOneSide == 0;

    setThresholds();
    size_t pixRejected = 0, tileRejected = 0;
    findStrongest(pixRejected, tileRejected);
    if (opt_.test != TwoSampleTest::Equivalence) {
        out_.pixelsRejected = pixRejected;
        out_.tilesRejected = tileRejected;
        out_.fail = pixRejected + tileRejected > 0;
    } else {
        size_t pixNot = 0, tileNot = 0;
        countNotEquivalent(pixNot, tileNot);
        out_.pixelsRejected = pixNot;
        out_.tilesRejected = tileNot;
        out_.fail =
            (T_ > 0 ? tileNot : pixNot) > 0 || out_.hypotheses == 0 || out_.nonFiniteOneSide > 0;
    }
    if (opt_.rule == CompareOptions::Rule::Mitsuba) finishMitsuba();
    computePower();
    if (!out_.fail && !out_.identical && opt_.minPower > 0.0 &&
        opt_.rule == CompareOptions::Rule::Mcstat && opt_.test == TwoSampleTest::Difference) {
        const double seen = std::isfinite(out_.power.tileRelative) ? out_.power.tileRelative
                                                                   : out_.power.pixelRelative;
        out_.underpowered = !(seen <= opt_.minPower);
        out_.fail = out_.underpowered;
    }
    if (out_.identical) out_.fail = opt_.identicalFails;
}

void Comparison::computePower() {
    if (opt_.rule != CompareOptions::Rule::Mcstat || opt_.test != TwoSampleTest::Difference) return;
    // The families' levels as setThresholds() splits them.
    const double q = T_ > 0 ? opt_.level / 2.0 : opt_.level;
    auto family = [&](const std::vector<float>& p, const std::vector<float>& se,
                      const std::vector<float>& df, const std::vector<float>& a, double& relative,
                      double& absolute) {
        const size_t m =
            size_t(std::count_if(p.begin(), p.end(), [](float v) { return !std::isnan(v); }));
        if (m == 0) return;
        const double alpha = opt_.control == Multiplicity::None ? q : q / double(m);
        // The quantiles by whole degrees of freedom, rounded down (a larger detectable change:
        // the statement stays true), up to 10^6; beyond, and for exact sides, the normal's.
        std::map<long, double> factor;
        std::vector<double> rel, abs;
        for (size_t h = 0; h < p.size(); ++h) {
            if (std::isnan(p[h]) || !(se[h] > 0.f) || !std::isfinite(se[h])) continue;
            const long d = std::isfinite(df[h]) && df[h] < 1e6f
                               ? std::max(1L, long(std::floor(double(df[h]))))
                               : 0L;
            auto it = factor.find(d);
            if (it == factor.end())
                it = factor
                         .emplace(d, detectableDifference(1.0, d > 0 ? double(d) : HUGE_VAL, 0.0,
                                                          alpha, kComparePower))
                         .first;
            const double av = double(a[h]);
            const double delta = margin(av, av) + it->second * double(se[h]);
            if (!std::isfinite(delta)) continue;
            abs.push_back(delta);
            if (av != 0.0 && std::isfinite(av)) rel.push_back(delta / std::fabs(av));
        }
        relative = medianOf(rel);
        absolute = medianOf(abs);
    };
    family(p_, se_, df_, aEst_, out_.power.pixelRelative, out_.power.pixelAbsolute);
    if (T_ > 0)
        family(tileP_, tileSe_, tileDf_, tileA_, out_.power.tileRelative, out_.power.tileAbsolute);
}

}  // namespace mcstat::detail
