// Noise-aware comparison of two renders from their sub-buffers (include/mcstat/compare/compare.h,
// docs/compare.md). Both sides are read by the same blocks of rows, aligned to the tiles, so a
// tile is always whole inside one block; a block's tiles are the parallel tasks, each testing its
// pixels and then itself. The multiple-testing threshold needs every p-value, so they are kept (4
// bytes per hypothesis) with the maps; the sub-buffers are not.
#include "mcstat/compare/compare.h"

#include <OpenImageIO/strutil.h>
#include <fmt/format.h>
#include <fnmatch.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <numeric>

#include "mcstat/core/colour_space.h"
#include "mcstat/core/float_rounding.h"
#include "mcstat/core/parallel.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"

namespace mcstat {

namespace {

constexpr float kNaNf = std::numeric_limits<float>::quiet_NaN();

/// What is tested per pixel: the luminance, a colour channel or an AOV channel.
struct Quantity {
    enum Kind { Luminance, Channel, Aov } kind = Luminance;
    int channel = 0;         ///< R, G, B index (Channel)
    int aovA = 0, aovB = 0;  ///< AOV index in each side's header (Aov)
    std::string name;        ///< "luminance", "R", the AOV's name
    std::string suffix;      ///< map channel suffix: "", ".R", ".<aov>"
};

/// One side of the comparison: a statistics source read by blocks, or a reference image.
struct Side {
    StatsBlockSource* src = nullptr;
    const OIIO::ImageBuf* ref = nullptr;
    std::vector<float> refRGB;  ///< the reference's R, G, B, row by row from its data window
    /// The reference's per-sample variance of R, G, B (Mitsuba 3's variance image), or empty.
    std::vector<float> refVar;
    StatsImage block;
    int aovCount = 0;
};

/// Buffer values of quantity `q` of pixel p (local to the block) of a statistics side.
void gatherBuffers(const Side& s, const Quantity& q, bool sideB, size_t p,
                   const std::array<double, 3>& luma, std::vector<double>& values,
                   std::vector<double>& counts) {
    const PixelBuffers pb = s.block.pixelBuffers(p);
    values.resize(size_t(pb.M));
    counts.resize(size_t(pb.M));
    const size_t k0 = s.block.bufferBegin(p);
    for (int j = 0; j < pb.M; ++j) {
        const float* m = pb.mean + size_t(j) * 3;
        double v = 0.0;
        switch (q.kind) {
            case Quantity::Luminance:
                v = luminance(luma, m);
                break;
            case Quantity::Channel:
                v = double(m[q.channel]);
                break;
            case Quantity::Aov:
                v = double(s.block.aov[(k0 + size_t(j)) * size_t(s.aovCount) +
                                       size_t(sideB ? q.aovB : q.aovA)]);
                break;
        }
        values[size_t(j)] = v;
        counts[size_t(j)] = double(pb.count[j]);
    }
}

/// A compact file's pixel that keeps only its mean (one buffer where the file has M > 1): the
/// summary meanSummary gives on the full file's buffers, from what the compact file kept of them
/// (FORMAT.md "Version 6"): the valid buffers M', the mean and the between-buffer covariance of
/// R, G, B, s^2 = c^T C c for the quantity's weights c, variance s^2 / N, df = M' - 1. Yuen's
/// trimmed mean of such a pixel is its mean (G-MoN trimmed nothing), tested as Welch's.
bool compactSummary(const Side& s, const Quantity& q, size_t p, const std::array<double, 3>& luma,
                    SideSummary& out) {
    const float* sp = s.block.meanOnlySpread(p);
    if (!sp) return false;
    const PixelBuffers pb = s.block.pixelBuffers(p);
    std::array<double, 3> w{0.0, 0.0, 0.0};
    if (q.kind == Quantity::Channel)
        w[size_t(q.channel)] = 1.0;
    else
        w = luma;
    double est = 0.0, s2 = 0.0;
    for (int c = 0; c < 3; ++c) {
        est += w[size_t(c)] * double(pb.mean[c]);
        for (int d = 0; d < 3; ++d)
            s2 += w[size_t(c)] * w[size_t(d)] * double(sp[spreadIndex(c, d)]);
    }
    out = SideSummary();
    out.estimate = est;
    out.buffers = int(sp[0]);
    const double n = double(pb.count[0]);
    if (out.buffers >= 2 && n > 0.0 && std::isfinite(s2)) {
        out.df = double(out.buffers - 1);
        out.variance = std::max(0.0, s2) / n;
    }
    return true;
}

/// The reference image's value of quantity `q` at pixel (x, y) of the block's rows.
double referenceValue(const Side& s, const Quantity& q, int x, int y,
                      const std::array<double, 3>& luma) {
    const float* rgb = &s.refRGB[(size_t(y) * size_t(s.ref->roi().width()) + size_t(x)) * 3];
    if (q.kind == Quantity::Channel) return double(rgb[q.channel]);
    return luminance(luma, rgb);
}

/// The reference's per-sample variance of quantity `q` at pixel (x, y): a channel's, or for the
/// luminance sum w_c^2 var_c (the variance image holds no covariances: R, G and B of one pixel are
/// taken as independent, which understates the luminance's variance where they correlate).
double referenceVariance(const Side& s, const Quantity& q, int x, int y,
                         const std::array<double, 3>& luma) {
    const float* v = &s.refVar[(size_t(y) * size_t(s.ref->roi().width()) + size_t(x)) * 3];
    if (q.kind == Quantity::Channel) return double(v[q.channel]);
    return luma[0] * luma[0] * v[0] + luma[1] * luma[1] * v[1] + luma[2] * luma[2] * v[2];
}

/// A side's R, G, B mean at pixel `local` of the block (x, y in the image): the count-weighted mean
/// of its non-empty buffers, or the reference's values.
void rgbMean(const Side& s, size_t local, int x, int y, float* out) {
    if (s.ref) {
        const float* rgb = &s.refRGB[(size_t(y) * size_t(s.ref->roi().width()) + size_t(x)) * 3];
        std::copy(rgb, rgb + 3, out);
        return;
    }
    const PixelBuffers pb = s.block.pixelBuffers(local);
    double sum[3] = {0.0, 0.0, 0.0}, n = 0.0;
    for (int j = 0; j < pb.M; ++j) {
        const double c = double(pb.count[j]);
        if (!(c > 0.0)) continue;
        for (int k = 0; k < 3; ++k) sum[k] += c * double(pb.mean[size_t(j) * 3 + size_t(k)]);
        n += c;
    }
    for (int k = 0; k < 3; ++k) out[k] = n > 0.0 ? float(sum[k] / n) : kNaNf;
}

/// A tile of a side whose buffer indices differ from pixel to pixel (adaptive M, compact files:
/// a buffer-free pixel keeps only its spread), summed from its pixels' summaries: the tile's value
/// is the mean of its n pixels' estimates and, the pixels' noise being independent (each pixel's
/// samples are its own), its variance is sum v_p / n^2, with the Welch-Satterthwaite degrees of
/// freedom (sum v_p)^2 / sum (v_p^2 / df_p) (Satterthwaite, Biometrics Bulletin 2(6), 1946). A
/// pixel without a variance (one buffer) leaves the tile untested (df 0).
struct PixelSums {
    double estimate = 0.0, variance = 0.0, dfDenominator = 0.0, samples = 0.0;
    double minDf = std::numeric_limits<double>::infinity();
    bool missing = false;  ///< a pixel had no variance estimate

    void add(const SideSummary& s, double pixelSamples) {
        estimate += s.estimate;
        variance += s.variance;
        samples += pixelSamples;
        if (!(s.df > 0.0)) {
            missing = true;
            return;
        }
        minDf = std::min(minDf, s.df);
        dfDenominator += s.variance * s.variance / s.df;
    }
    SideSummary tile(double n) const {
        SideSummary t;
        t.estimate = estimate / n;
        t.variance = variance / (n * n);
        t.buffers = 0;
        if (missing || !std::isfinite(minDf)) return t;  // df 0: untested
        // All variances zero (a constant tile): the smallest df, as the pixels' tests use.
        t.df = dfDenominator > 0.0 ? variance * variance / dfDenominator : minDf;
        return t;
    }
};

/// Counts and findings of the tasks, merged under a mutex.
struct Tally {
    size_t pixelsTested = 0, nonFiniteOneSide = 0, nonFiniteBoth = 0, constantEqual = 0;
    size_t fewBuffers = 0;
    size_t tilesTested = 0;
    bool allZero = true;  ///< every difference tested was exactly 0
};

class Comparison {
  public:
    Comparison(Side& a, Side& b, const CompareOptions& opt, CompareResult& out)
        : a_(a), b_(b), opt_(opt), out_(out) {}

    bool run(std::string& err);

  private:
    bool resolveQuantities(std::string& err);
    bool processBlock(int row0, int rows, std::string& err);
    void testTile(int tx, int ty, int row0, Tally& tally);
    /// The summary of quantity `q` of pixel `local` of side `s`, its buffers' values and counts
    /// left in `v` and `c`.
    SideSummary sideSummary(const Side& s, const Quantity& q, bool sideB, size_t local,
                            std::vector<double>& v, std::vector<double>& c) const {
        gatherBuffers(s, q, sideB, local, opt_.luma, v, c);
        SideSummary out;
        if (compactSummary(s, q, local, opt_.luma, out)) return out;
        return summarize(v, c);
    }
    /// The count-weighted mean's summary of pixel `local` of side `s` (Welch's, whatever the
    /// test), from its buffers' values `v`, `c` as sideSummary left them, or its stored spread.
    SideSummary pixelMean(const Side& s, const Quantity& q, size_t local,
                          const std::vector<double>& v, const std::vector<double>& c) const {
        SideSummary out;
        if (compactSummary(s, q, local, opt_.luma, out)) return out;
        return meanSummary(v.data(), c.data(), int(v.size()));
    }
    SideSummary summarize(const std::vector<double>& v, const std::vector<double>& c) const {
        return opt_.trimmed ? trimmedSummary(v.data(), c.data(), int(v.size()), opt_.trim)
                            : meanSummary(v.data(), c.data(), int(v.size()));
    }
    double margin(double ea, double eb) const {
        return std::max(opt_.tol, opt_.reltol * std::fabs(0.5 * (ea + eb)));
    }
    /// Folds a one-sample comparison's reference noise into b's variance (see compare.h).
    void referenceNoise(SideSummary& sb, double samples) const {
        if (opt_.referenceSpp > 0.0 && samples > 0.0)
            sb.variance *= 1.0 + samples / opt_.referenceSpp;
    }
    /// The reference side's summary at (x, y): exact, or with its variance image's noise.
    SideSummary referenceSummary(const Quantity& q, int x, int y) const {
        SideSummary sa = exactSummary(referenceValue(a_, q, x, y, opt_.luma));
        if (!a_.refVar.empty() && opt_.referenceSpp > 0.0) {  // Mitsuba's rule needs no K
            sa.variance = referenceVariance(a_, q, x, y, opt_.luma) / opt_.referenceSpp;
            sa.df = opt_.referenceSpp - 1.0;
        }
        return sa;
    }
    /// One pixel's test: Welch's (or the one-sample t) by default, Mitsuba's z-test on request.
    TwoSampleResult testPixel(const SideSummary& sa, const SideSummary& sb, const Quantity& q,
                              int x, int y, double nb) const {
        if (opt_.rule == CompareOptions::Rule::Mitsuba)
            return mitsubaZTest(sb.estimate, nb, sa.estimate,
                                referenceVariance(a_, q, x, y, opt_.luma), opt_.varianceFloor);
        return welchTest(sa, sb, margin(sa.estimate, sb.estimate), opt_.test);
    }
    void finish();
    /// The rejection thresholds of the pixels and the tiles, and the count of hypotheses, by the
    /// verdict's rule.
    void setThresholds();
    /// The strongest finding among the pixels and among the tiles; counts the pixels and tiles
    /// rejected in any quantity.
    void findStrongest(size_t& pixRejected, size_t& tileRejected);
    /// Equivalence: the pixels and tiles not shown equivalent in some quantity tested.
    void countNotEquivalent(size_t& pixNot, size_t& tileNot) const;
    /// Whether p-value `p` with z-score `z` is a stronger finding than `f` at threshold `thr`.
    bool strongerFinding(float p, float z, const CompareFinding& f, double thr) const;
    /// Sets `f` to the hypothesis of quantity `qi` at pixel or tile `index`.
    void fillFinding(CompareFinding& f, bool tile, size_t index, size_t qi, float p, float z,
                     float d, float a) const;
    void finishMitsuba();
    /// CompareResult::power, from the thresholds' families.
    void computePower();
    /// A difference within float resolution of the two estimates is rounding, not evidence: the
    /// test is made again with b's estimate set to a's. `r` as testPixel or welchTest gave it.
    TwoSampleResult withoutRounding(const SideSummary& sa, SideSummary sb,
                                    const TwoSampleResult& r) const {
        if (opt_.rule == CompareOptions::Rule::Mitsuba || r.difference == 0.0 ||
            !std::isfinite(r.difference) || !withinFloatRounding(sa.estimate, sb.estimate))
            return r;
        sb.estimate = sa.estimate;
        return welchTest(sa, sb, margin(sa.estimate, sb.estimate), opt_.test);
    }
    void buildMaps();
    void buildMeans();

    Side& a_;
    Side& b_;
    const CompareOptions& opt_;
    CompareResult& out_;
    std::vector<Quantity> q_;
    int tilesX_ = 0, tilesY_ = 0, taskSide_ = 16;
    size_t P_ = 0, T_ = 0;
    // Per quantity q: pixel arrays [q * P + p], tile arrays [q * T + t].
    std::vector<float> p_, z_, effect_, aEst_, tileP_, tileZ_, tileEffect_, tileA_;
    // Per hypothesis: the difference's standard error and degrees of freedom (for the power).
    std::vector<float> se_, df_, tileSe_, tileDf_;
    std::vector<uint8_t> pixelNonFinite_;  ///< 1 one side, 2 both
    std::vector<float> meanA_, meanB_;     ///< R, G, B per pixel (CompareOptions::keepMeans)
    Tally tally_;
    std::mutex mutex_;
};

bool Comparison::resolveQuantities(std::string& err) {
    if (opt_.rgb) {
        const char* names[3] = {"R", "G", "B"};
        for (int c = 0; c < 3; ++c) {
            Quantity q;
            q.kind = Quantity::Channel;
            q.channel = c;
            q.name = names[c];
            q.suffix = std::string(".") + names[c];
            q_.push_back(q);
        }
    } else {
        Quantity q;
        q.name = "luminance";
        q_.push_back(q);
    }
    if (opt_.aovs.empty()) return true;
    if (a_.ref) {
        err = "AOVs cannot be compared against a reference image (it has no sub-buffers)";
        return false;
    }
    const StatsHeader& ha = a_.src->header();
    const StatsHeader& hb = b_.src->header();
    for (const std::string& pattern : opt_.aovs) {
        bool matched = false;
        for (size_t i = 0; i < ha.aovs.size(); ++i) {
            const std::string& name = ha.aovs[i].name;
            if (fnmatch(pattern.c_str(), name.c_str(), 0) != 0) continue;
            matched = true;
            if (std::any_of(q_.begin(), q_.end(), [&](const Quantity& e) {
                    return e.kind == Quantity::Aov && e.name == name;
                }))
                continue;
            const int ib = hb.aovIndex(name);
            if (ib < 0) {
                err = fmt::format("{} has AOV '{}', {} has not", a_.src->name(), printable(name),
                                  b_.src->name());
                return false;
            }
            Quantity q;
            q.kind = Quantity::Aov;
            q.aovA = int(i);
            q.aovB = ib;
            q.name = name;
            q.suffix = "." + name;
            q_.push_back(q);
        }
        if (!matched) {
            std::vector<std::string> names;
            for (const AovChannel& c : ha.aovs) names.push_back(c.name);
            err = fmt::format("AOV '{}' matches none of {}'s AOV channels ({})", pattern,
                              a_.src->name(),
                              names.empty() ? std::string("it has none") : printableList(names));
            return false;
        }
    }
    return true;
}

void Comparison::testTile(int tx, int ty, int row0, Tally& tally) {
    const int W = out_.width;
    const int x0 = tx * taskSide_, x1 = std::min(W, x0 + taskSide_);
    const int y0 = ty * taskSide_, y1 = std::min(out_.height, y0 + taskSide_);
    const bool tiles = out_.tile > 0;
    std::vector<double> va, ca, vb, cb;
    // When a side's buffer indices do not line up across pixels (adaptive M, compact files), the
    // tile is summed from its pixels' means and their variances instead (PixelSums), on both
    // sides alike: the two tiles must estimate one quantity (a full side's trimmed tile against a
    // compact side's mean of per-pixel values would differ by the trimming's bias, which a tile's
    // small noise turns into false alarms).
    const bool pixB = out_.adaptive, pixA = pixB && !a_.ref;
    // Otherwise tile sums per quantity and buffer: mean values and counts over the tile's pixels
    // (none for a reference side or a side summed per pixel).
    const size_t Ma = size_t(a_.ref || pixA ? 0 : out_.Ma), Mb = size_t(pixB ? 0 : out_.Mb);
    const size_t Q = q_.size();
    std::vector<double> sumA(Q * Ma, 0.0), cntA(Q * Ma, 0.0), sumB(Q * Mb, 0.0), cntB(Q * Mb, 0.0),
        refSum(Q, 0.0), refVarSum(Q, 0.0);
    std::vector<uint8_t> tileBad(Q, 0);
    std::vector<PixelSums> sumsA(pixA ? Q : 0), sumsB(pixB ? Q : 0);
    for (int y = y0; y < y1; ++y) {
        for (int x = x0; x < x1; ++x) {
            const size_t local = size_t(y - row0) * size_t(W) + size_t(x);
            const size_t pix = size_t(y) * size_t(W) + size_t(x);
            uint8_t nonFinite = 0;
            bool tested = false;
            if (opt_.keepMeans) {
                rgbMean(a_, local, x, y, &meanA_[pix * 3]);
                rgbMean(b_, local, x, y, &meanB_[pix * 3]);
            }
            for (size_t qi = 0; qi < Q; ++qi) {
                const Quantity& q = q_[qi];
                SideSummary sa, sb;
                sb = sideSummary(b_, q, true, local, vb, cb);
                double nb = 0.0;
                for (double c : cb) nb += c > 0.0 ? c : 0.0;
                if (a_.ref) {
                    sa = referenceSummary(q, x, y);
                    if (a_.refVar.empty()) referenceNoise(sb, nb);
                    if (tiles) {
                        refSum[qi] += sa.estimate;
                        refVarSum[qi] += sa.variance;
                    }
                } else {
                    sa = sideSummary(a_, q, false, local, va, ca);
                }
                if (tiles) {
                    if (!sa.finite || !sb.finite) tileBad[qi] = 1;
                    if (pixA)
                        sumsA[qi].add(opt_.trimmed ? pixelMean(a_, q, local, va, ca) : sa, 0.0);
                    if (pixB)
                        sumsB[qi].add(opt_.trimmed ? pixelMean(b_, q, local, vb, cb) : sb, nb);
                    for (size_t j = 0; j < Ma; ++j) {
                        sumA[qi * Ma + j] += va[j];
                        cntA[qi * Ma + j] += ca[j];
                    }
                    for (size_t j = 0; j < Mb; ++j) {
                        sumB[qi * Mb + j] += vb[j];
                        cntB[qi * Mb + j] += cb[j];
                    }
                }
                const size_t h = qi * P_ + pix;
                aEst_[h] = float(sa.estimate);
                if (!sa.finite || !sb.finite) {
                    // NaN / Inf on one side only: the renderer changed (p = 0); on both: untested.
                    const bool one = sa.finite != sb.finite;
                    nonFinite = std::max<uint8_t>(nonFinite, one ? 1 : 2);
                    p_[h] = one ? 0.f : kNaNf;
                    z_[h] = kNaNf;
                    effect_[h] = kNaNf;
                    if (one) tally.allZero = false;
                    continue;
                }
                const TwoSampleResult raw = testPixel(sa, sb, q, x, y, nb);
                const TwoSampleResult r = withoutRounding(sa, sb, raw);
                p_[h] = float(r.p);
                z_[h] = float(r.z);
                effect_[h] = float(r.difference);
                se_[h] = float(raw.se);
                df_[h] = float(raw.df);
                if (std::isnan(r.p)) continue;
                tested = true;
                if (raw.difference != 0.0) tally.allZero = false;
                if (r.se == 0.0 && r.difference == 0.0) ++tally.constantEqual;
            }
            if (nonFinite == 1) ++tally.nonFiniteOneSide;
            if (nonFinite == 2) ++tally.nonFiniteBoth;
            if (nonFinite == 1 || tested) ++tally.pixelsTested;
            if (nonFinite == 0 && !tested) ++tally.fewBuffers;
            pixelNonFinite_[pix] = nonFinite;
        }
    }
    if (!tiles) return;
    const size_t t = size_t(ty) * size_t(tilesX_) + size_t(tx);
    const double n = double(x1 - x0) * double(y1 - y0);
    bool tested = false;
    for (size_t qi = 0; qi < Q; ++qi) {
        const size_t h = qi * T_ + t;
        tileP_[h] = tileZ_[h] = tileEffect_[h] = tileA_[h] = kNaNf;
        if (tileBad[qi]) continue;
        // The tile's value in buffer j: the mean over its pixels of their buffer-j values, with the
        // mean count; buffers stay independent, so the tile is tested as a pixel is.
        for (size_t j = 0; j < Ma; ++j) {
            sumA[qi * Ma + j] /= n;
            cntA[qi * Ma + j] /= n;
        }
        for (size_t j = 0; j < Mb; ++j) {
            sumB[qi * Mb + j] /= n;
            cntB[qi * Mb + j] /= n;
        }
        vb.assign(sumB.begin() + long(qi * Mb), sumB.begin() + long((qi + 1) * Mb));
        cb.assign(cntB.begin() + long(qi * Mb), cntB.begin() + long((qi + 1) * Mb));
        SideSummary sb = pixB ? sumsB[qi].tile(n) : summarize(vb, cb), sa;
        if (pixB && sb.df <= 0.0) continue;  // a pixel without a variance: the tile untested
        if (a_.ref) {
            sa = exactSummary(refSum[qi] / n);
            if (!a_.refVar.empty()) {
                // The reference's pixels are independent: the tile mean's variance is the sum of
                // theirs over n^2.
                sa.variance = refVarSum[qi] / (n * n);
                sa.df = opt_.referenceSpp - 1.0;
            } else {
                double nb = 0.0;
                for (double c : cb) nb += c > 0.0 ? c : 0.0;
                referenceNoise(sb, pixB ? sumsB[qi].samples / n : nb);
            }
        } else if (pixA) {
            sa = sumsA[qi].tile(n);
            if (sa.df <= 0.0) continue;
        } else {
            va.assign(sumA.begin() + long(qi * Ma), sumA.begin() + long((qi + 1) * Ma));
            ca.assign(cntA.begin() + long(qi * Ma), cntA.begin() + long((qi + 1) * Ma));
            sa = summarize(va, ca);
        }
        const TwoSampleResult raw = welchTest(sa, sb, margin(sa.estimate, sb.estimate), opt_.test);
        const TwoSampleResult r = withoutRounding(sa, sb, raw);
        tileSe_[h] = float(raw.se);
        tileDf_[h] = float(raw.df);
        tileP_[h] = float(r.p);
        tileZ_[h] = float(r.z);
        tileEffect_[h] = float(r.difference);
        tileA_[h] = float(sa.estimate);
        if (!std::isnan(r.p)) tested = true;
    }
    if (tested) ++tally.tilesTested;
}

bool Comparison::processBlock(int row0, int rows, std::string& err) {
    const bool aovs = std::any_of(q_.begin(), q_.end(),
                                  [](const Quantity& q) { return q.kind == Quantity::Aov; });
    // A compact file's spread (what its buffer-free pixels keep for the test) is in part moments.
    const auto partsOf = [&](const Side& s) {
        return kStatsPartBuffers | (aovs ? kStatsPartAovs : 0u) |
               (s.src->header().compact ? kStatsPartMoments : 0u);
    };
    if (b_.src && !b_.src->read(row0, rows, partsOf(b_), b_.block, err)) return false;
    if (a_.src && !a_.src->read(row0, rows, partsOf(a_), a_.block, err)) return false;
    const int ty0 = row0 / taskSide_;
    const int ty1 = (row0 + rows + taskSide_ - 1) / taskSide_;
    const int64_t tasks = int64_t(ty1 - ty0) * tilesX_;
    parallelFor(0, tasks, 1, opt_.nthreads, [&](int64_t begin, int64_t end) {
        for (int64_t i = begin; i < end; ++i) {
            Tally t;
            testTile(int(i % tilesX_), ty0 + int(i / tilesX_), row0, t);
            const std::lock_guard<std::mutex> lock(mutex_);
            tally_.pixelsTested += t.pixelsTested;
            tally_.nonFiniteOneSide += t.nonFiniteOneSide;
            tally_.nonFiniteBoth += t.nonFiniteBoth;
            tally_.constantEqual += t.constantEqual;
            tally_.fewBuffers += t.fewBuffers;
            tally_.tilesTested += t.tilesTested;
            tally_.allZero = tally_.allZero && t.allZero;
        }
    });
    return true;
}

int gcdInt(int a, int b) { return b == 0 ? a : gcdInt(b, a % b); }

bool Comparison::run(std::string& err) {
    if (!resolveQuantities(err)) return false;
    out_.quantities.clear();
    for (const Quantity& q : q_) out_.quantities.push_back(q.name);
    taskSide_ = out_.tile > 0 ? out_.tile : 16;
    tilesX_ = (out_.width + taskSide_ - 1) / taskSide_;
    tilesY_ = (out_.height + taskSide_ - 1) / taskSide_;
    P_ = size_t(out_.width) * size_t(out_.height);
    T_ = out_.tile > 0 ? size_t(tilesX_) * size_t(tilesY_) : 0;
    const size_t Q = q_.size();
    p_.assign(Q * P_, kNaNf);
    z_.assign(Q * P_, kNaNf);
    effect_.assign(Q * P_, kNaNf);
    aEst_.assign(Q * P_, kNaNf);
    pixelNonFinite_.assign(P_, 0);
    tileP_.assign(Q * T_, kNaNf);
    tileZ_.assign(Q * T_, kNaNf);
    tileEffect_.assign(Q * T_, kNaNf);
    tileA_.assign(Q * T_, kNaNf);
    se_.assign(Q * P_, kNaNf);
    df_.assign(Q * P_, kNaNf);
    tileSe_.assign(Q * T_, kNaNf);
    tileDf_.assign(Q * T_, kNaNf);
    if (opt_.keepMeans) {
        meanA_.assign(3 * P_, kNaNf);
        meanB_.assign(3 * P_, kNaNf);
    }

    // Blocks of rows: whole tiles, whole chunks of both files (no chunk decoded twice), about
    // 64 MB of decoded buffers per side.
    int align = taskSide_;
    for (StatsBlockSource* s : {a_.src, b_.src}) {
        if (!s) continue;
        const int c = std::max(1, s->chunkRows());
        align = align / gcdInt(align, c) * c;
    }
    int rows = 0;
    for (StatsBlockSource* s : {a_.src, b_.src})
        if (s) rows = std::max(rows, s->blockRows(kStatsPartBuffers));
    rows = std::max(align, (rows + align - 1) / align * align);
    for (int row0 = 0; row0 < out_.height; row0 += rows) {
        const int n = std::min(rows, out_.height - row0);
        if (!processBlock(row0, n, err)) return false;
        if (opt_.progress) opt_.progress(double(row0 + n) / out_.height);
    }
    finish();
    buildMaps();
    buildMeans();
    return true;
}

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

void Comparison::buildMeans() {
    if (!opt_.keepMeans) return;
    const OIIO::ROI data(out_.originX, out_.originX + out_.width, out_.originY,
                         out_.originY + out_.height, 0, 1, 0, 3);
    for (auto [img, v] : {std::pair{&out_.meanA, &meanA_}, std::pair{&out_.meanB, &meanB_}}) {
        img->reset(floatSpec(data, {"R", "G", "B"}), OIIO::InitializePixels::No);
        img->set_pixels(data, OIIO::TypeFloat, v->data());
    }
}

/// Whether p-value `p` is rejected at threshold `thr` (a NaN never is).
bool rejectedAt(float p, double thr) { return !std::isnan(p) && double(p) <= thr; }

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

namespace {

/// The median of `v` (reordered); NaN when empty.
double medianOf(std::vector<double>& v) {
    if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
    const auto mid = v.begin() + long(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    if (v.size() % 2) return *mid;
    return 0.5 * (*mid + *std::max_element(v.begin(), mid));
}

}  // namespace

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

void Comparison::buildMaps() {
    const bool tiles = T_ > 0;
    const bool equivalence = opt_.test == TwoSampleTest::Equivalence;
    std::vector<std::string> names;
    for (const Quantity& q : q_) {
        for (const char* m : {"p", "z", "effect", "differs"}) names.push_back(m + q.suffix);
        if (tiles)
            for (const char* m : {"tile.p", "tile.z", "tile.differs"})
                names.push_back(m + q.suffix);
    }
    const OIIO::ROI data(out_.originX, out_.originX + out_.width, out_.originY,
                         out_.originY + out_.height, 0, 1, 0, int(names.size()));
    const OIIO::ImageSpec spec = floatSpec(data, names);
    out_.maps.reset(spec, OIIO::InitializePixels::No);
    const size_t C = names.size(), W = size_t(out_.width);
    auto flag = [&](float p, double thr) {
        if (std::isnan(p)) return kNaNf;
        const bool rejected = double(p) <= thr;
        return (equivalence ? !rejected : rejected) ? 1.f : 0.f;
    };
    std::vector<float> row(W * C);
    for (int y = 0; y < out_.height; ++y) {
        for (size_t x = 0; x < W; ++x) {
            const size_t p = size_t(y) * W + x;
            const size_t t =
                tiles ? size_t(y / out_.tile) * size_t(tilesX_) + x / size_t(out_.tile) : 0;
            float* o = &row[x * C];
            for (size_t qi = 0; qi < q_.size(); ++qi) {
                const size_t h = qi * P_ + p;
                *o++ = p_[h];
                *o++ = z_[h];
                *o++ = effect_[h];
                *o++ = flag(p_[h], out_.threshold);
                if (tiles) {
                    const size_t ht = qi * T_ + t;
                    *o++ = tileP_[ht];
                    *o++ = tileZ_[ht];
                    *o++ = flag(tileP_[ht], out_.tileThreshold);
                }
            }
        }
        const OIIO::ROI r(out_.originX, out_.originX + out_.width, out_.originY + y,
                          out_.originY + y + 1, 0, 1, 0, int(C));
        out_.maps.set_pixels(r, OIIO::TypeFloat, row.data());
    }
}

bool checkOptions(const CompareOptions& opt, std::string& err) {
    if (!(opt.level > 0.0 && opt.level < 1.0)) {
        err = fmt::format("level {} is not in (0, 1)", opt.level);
        return false;
    }
    if (!(opt.trim >= 0.0 && opt.trim < 0.5)) {
        err = fmt::format("trim {} is not in [0, 0.5)", opt.trim);
        return false;
    }
    if (!(opt.tol >= 0.0) || !(opt.reltol >= 0.0) || !std::isfinite(opt.tol) ||
        !std::isfinite(opt.reltol)) {
        err = "tolerances must be finite and >= 0";
        return false;
    }
    if (opt.test == TwoSampleTest::Equivalence && opt.tol == 0.0 && opt.reltol == 0.0) {
        err =
            "an equivalence test needs a tolerance (tol or reltol > 0): no data shows that two "
            "renders agree exactly";
        return false;
    }
    if (opt.tile < 0 || opt.tile > 4096) {
        err = fmt::format("tile {} is not in 0..4096", opt.tile);
        return false;
    }
    if (!(opt.referenceSpp >= 0.0) || !std::isfinite(opt.referenceSpp)) {
        err = "the reference's samples per pixel must be finite and >= 0";
        return false;
    }
    return true;
}

/// The reference's variance image (Mitsuba 3's `_var.exr`) and the rule against what they need.
bool checkReferenceVariance(const OIIO::ImageBuf* var, const OIIO::ImageBuf& ref,
                            const std::string& refName, const CompareOptions& opt,
                            std::string& err) {
    const bool mitsuba = opt.rule == CompareOptions::Rule::Mitsuba;
    if (!var) {
        if (mitsuba)
            err = fmt::format(
                "rule=mitsuba tests against the reference's per-sample variance: give "
                "refvar=VAR.exr with {}",
                refName);
        return !mitsuba;
    }
    if (var->nchannels() < 3 || var->roi().width() != ref.roi().width() ||
        var->roi().height() != ref.roi().height()) {
        err = fmt::format("{}'s variance image is {}x{} with {} channels; {} is {}x{} (R, G, B)",
                          refName, var->roi().width(), var->roi().height(), var->nchannels(),
                          refName, ref.roi().width(), ref.roi().height());
        return false;
    }
    if (!(opt.referenceSpp > 1.0) && !mitsuba) {
        err = fmt::format(
            "refvar gives {}'s per-sample variance: refspp=K (its samples per pixel, > 1) "
            "turns it into the variance of its mean",
            refName);
        return false;
    }
    if (mitsuba && (opt.trimmed || opt.test == TwoSampleTest::Equivalence || opt.tol > 0.0 ||
                    opt.reltol > 0.0)) {
        err = "rule=mitsuba is Mitsuba 3's z-test: no test=yuen, equivalence, tol or reltol";
        return false;
    }
    return true;
}

/// The result's data window (the statistics file's) and its tile side. A tile averages a buffer
/// index over its pixels; with adaptive M (compact files too) the indices do not line up, and the
/// tile is summed from its pixels' estimates and variances instead (PixelSums).
void setWindow(CompareResult& out, const StatsHeader& h, bool adaptive, const CompareOptions& opt) {
    out.width = h.width;
    out.height = h.height;
    out.originX = h.originX;
    out.originY = h.originY;
    out.adaptive = adaptive;
    out.tile = opt.tile;
}

/// The M a side's buffers give, or an error when they give no variance.
bool sideBuffers(const StatsBlockSource& s, int& M, std::string& err) {
    const StatsHeader& h = s.header();
    M = h.M;
    if (h.M < 2) {
        err = fmt::format(
            "{} has M = {} sub-buffer{}: no variance to test against (render with "
            "--M 2 or more, or ingest two or more seeds)",
            s.name(), h.M, h.M == 1 ? "" : "s");
        return false;
    }
    return true;
}

/// AOVs of a compact file: a pixel that keeps its mean alone keeps no spread of its AOVs.
bool compactQuantities(const StatsBlockSource& s, const CompareOptions& opt, std::string& err) {
    if (!s.header().compact || opt.aovs.empty()) return true;
    err = fmt::format(
        "{} is a compact file: its pixels without heavy tails keep the spread of R, G and B, not "
        "of the AOVs, so aovs= cannot be tested there; compare the full files",
        s.name());
    return false;
}

}  // namespace

bool compareStats(StatsBlockSource& a, StatsBlockSource& b, const CompareOptions& opt,
                  CompareResult& out, std::string& err) {
    out = CompareResult();
    if (!checkOptions(opt, err)) return false;
    const StatsHeader& ha = a.header();
    const StatsHeader& hb = b.header();
    if (ha.width != hb.width || ha.height != hb.height || ha.originX != hb.originX ||
        ha.originY != hb.originY) {
        err = fmt::format(
            "{} ({}x{} at {},{}) and {} ({}x{} at {},{}) have different data "
            "windows: not renders of one image",
            a.name(), ha.width, ha.height, ha.originX, ha.originY, b.name(), hb.width, hb.height,
            hb.originX, hb.originY);
        return false;
    }
    if (opt.rule == CompareOptions::Rule::Mitsuba) {
        err = fmt::format(
            "rule=mitsuba tests a render against a reference image and its variance (refvar=); "
            "{} and {} are statistics files",
            a.name(), b.name());
        return false;
    }
    if (!sideBuffers(a, out.Ma, err) || !sideBuffers(b, out.Mb, err) ||
        !compactQuantities(a, opt, err) || !compactQuantities(b, opt, err))
        return false;
    setWindow(out, ha, ha.adaptiveM || hb.adaptiveM, opt);
    Side sa, sb;
    sa.src = &a;
    sb.src = &b;
    sa.aovCount = int(ha.aovs.size());
    sb.aovCount = int(hb.aovs.size());
    Comparison c(sa, sb, opt, out);
    return c.run(err);
}

bool compareStatsToImage(const OIIO::ImageBuf& ref, const std::string& refName, StatsBlockSource& b,
                         const CompareOptions& options, CompareResult& out, std::string& err,
                         const OIIO::ImageBuf* refVar) {
    out = CompareResult();
    CompareOptions opt = options;
    if (!checkOptions(opt, err) || !checkReferenceVariance(refVar, ref, refName, opt, err))
        return false;
    if (opt.rule == CompareOptions::Rule::Mitsuba) {
        opt.rgb = true;  // Mitsuba tests each channel; no tiles
        opt.tile = 0;
    }
    const StatsHeader& hb = b.header();
    const OIIO::ROI win = ref.roi();
    if (ref.nchannels() < 3) {
        err = fmt::format("{} has {} channel(s); R, G, B are needed", refName, ref.nchannels());
        return false;
    }
    if (win.width() != hb.width || win.height() != hb.height) {
        err = fmt::format("{} is {}x{}, {} is {}x{}: not the same image", refName, win.width(),
                          win.height(), b.name(), hb.width, hb.height);
        return false;
    }
    if (!sideBuffers(b, out.Mb, err) || !compactQuantities(b, opt, err)) return false;
    if (opt.trimmed) {
        // A trimmed mean estimates the mean only for symmetric distributions; a pixel's samples
        // are skewed (rare bright paths), so it would differ from the reference's mean anyway.
        err = fmt::format(
            "test=yuen compares trimmed means, and {} holds a mean: use test=welch "
            "against a reference image",
            refName);
        return false;
    }
    out.oneSample = true;
    setWindow(out, hb, hb.adaptiveM, opt);
    Side sa, sb;
    sa.ref = &ref;
    sa.refRGB.resize(size_t(win.width()) * size_t(win.height()) * 3);
    OIIO::ROI rgb = win;
    rgb.chbegin = 0;
    rgb.chend = 3;
    if (!ref.get_pixels(rgb, OIIO::TypeFloat, sa.refRGB.data())) {
        err = fmt::format("{}: {}", refName, ref.geterror());
        return false;
    }
    if (refVar) {
        sa.refVar.resize(sa.refRGB.size());
        OIIO::ROI vr = refVar->roi();
        vr.chbegin = 0;
        vr.chend = 3;
        if (!refVar->get_pixels(vr, OIIO::TypeFloat, sa.refVar.data())) {
            err = fmt::format("{}'s variance: {}", refName, refVar->geterror());
            return false;
        }
    }
    sb.src = &b;
    sb.aovCount = int(hb.aovs.size());
    Comparison c(sa, sb, opt, out);
    return c.run(err);
}

namespace {

std::string percentText(double v) { return fmt::format("{:g}%", v * 100.0); }

std::string controlText(const CompareOptions& opt) {
    if (opt.test == TwoSampleTest::Equivalence)
        return fmt::format("each at level {}", percentText(opt.level));
    switch (opt.control) {
        case Multiplicity::FDR:
            return fmt::format("false discovery rate {}", percentText(opt.level));
        case Multiplicity::FWER:
            return fmt::format("family-wise error rate {} (Holm)", percentText(opt.level));
        case Multiplicity::None:
            return fmt::format("each at level {}, uncorrected", percentText(opt.level));
    }
    return "";
}

std::string testText(const CompareResult& r, const CompareOptions& opt) {
    const std::string t = opt.trimmed
                              ? fmt::format("Yuen's trimmed t ({} per end)", percentText(opt.trim))
                              : std::string("Welch's t");
    const char* M = r.adaptive ? "M_max" : "M";
    const std::string m = r.oneSample
                              ? fmt::format("{} = {} sub-buffers against the reference", M, r.Mb)
                              : fmt::format("{} = {} + {} sub-buffers", M, r.Ma, r.Mb);
    return fmt::format("{} on {}", t, m);
}

std::string toleranceText(const CompareOptions& opt) {
    if (opt.tol == 0.0 && opt.reltol == 0.0) return "";
    std::string s = " within ";
    if (opt.reltol > 0.0) s += percentText(opt.reltol);
    if (opt.reltol > 0.0 && opt.tol > 0.0) s += " or ";
    if (opt.tol > 0.0) s += fmt::format("{:g}", opt.tol);
    return s;
}

/// The quantities tested (luminance, R, G, B, AOV names from the files: printable()).
std::string quantitiesText(const CompareResult& r) {
    std::vector<std::string> shown;
    for (size_t i = 0; i < r.quantities.size() && i < 3; ++i)
        shown.push_back(printable(r.quantities[i]));
    if (r.quantities.size() <= 3) return fmt::format("{}", fmt::join(shown, ", "));
    return fmt::format("{} and {} more", fmt::join(shown, ", "), r.quantities.size() - 3);
}

std::string findingText(const CompareFinding& f, const CompareResult& r,
                        const CompareOptions& opt) {
    const double rel = f.a != 0.0 ? f.result.difference / std::fabs(f.a) : 0.0;
    std::string where = f.tile ? fmt::format("tile {}x{} at ({}, {})", r.tile, r.tile, f.x, f.y)
                               : fmt::format("pixel ({}, {})", f.x, f.y);
    // No standard error: against an image, only the statistics file's buffers measure noise, and
    // :refspp= scales that measure, so a noiseless file leaves the reference noiseless too.
    const char* exact = !r.oneSample ? "exact (no noise on either side)"
                        : opt.referenceSpp > 0.0
                            ? "exact (no noise in the statistics file here, so none in the "
                              "reference either: refspp scales the file's own)"
                            : "exact (no noise in the statistics file here, and the reference is "
                              "taken as exact; :refspp= gives it noise)";
    std::string size = std::isfinite(f.result.z)
                           ? fmt::format("{:+.2f} standard errors", f.result.z)
                           : std::string(exact);
    return fmt::format("{} {}: {:.6g} -> {:.6g} ({:+.4g}{}, {}), p = {:.3g}", where,
                       printable(f.quantity), f.a, f.b, f.result.difference,
                       f.a != 0.0 ? fmt::format(", {:+.2f}%", rel * 100.0) : std::string(), size,
                       f.result.p);
}

}  // namespace

/// Mitsuba 3's verdict: a few failing channel tests pass (its pass fraction).
std::string mitsubaVerdict(const CompareResult& r, const CompareOptions& opt) {
    const std::string how = fmt::format(
        "Mitsuba 3's rule: z-tests against the reference's variance floored at {:g}, "
        "Sidak-corrected level {:.3g} ({} over {} pixels), {} of the channel tests must pass",
        opt.varianceFloor, r.threshold, percentText(opt.level), r.pixels,
        percentText(opt.passFraction));
    const size_t failed = r.channelTests - r.channelTestsPassed;
    if (r.identical) return fmt::format("IDENTICAL: every pixel equals the reference ({})", how);
    if (r.fail)
        return fmt::format(
            "DIFFERENT: {} of {} pixels differ in {}: {} of {} channel tests failed ({})",
            r.pixelsRejected, r.pixels, quantitiesText(r), failed, r.channelTests, how);
    return fmt::format(
        "SAME: {} of {} pixels differ in {}, {} of {} channel tests failed: within "
        "what the rule allows ({})",
        r.pixelsRejected, r.pixels, quantitiesText(r), failed, r.channelTests, how);
}

namespace {

/// A relative change as a percentage with 2 significant digits (3.1 %, 42 %, 0.051 %).
std::string changeText(double v) { return fmt::format("{:.2g} %", v * 100.0); }

/// What a difference test could have seen, in words (CompareResult::power).
std::string powerText(const CompareResult& r) {
    const ComparePower& w = r.power;
    std::vector<std::string> parts;
    if (std::isfinite(w.tileRelative))
        parts.push_back(fmt::format("{} in one tile", changeText(w.tileRelative)));
    if (std::isfinite(w.pixelRelative))
        parts.push_back(fmt::format("{} in one pixel", changeText(w.pixelRelative)));
    if (parts.empty()) return "its power is unknown: no hypothesis it tested has noise and a value";
    return fmt::format("it finds a change of {} with probability {:g} (medians)",
                       fmt::join(parts, " or "), kComparePower);
}

}  // namespace

std::string comparePowerText(const CompareResult& r, const CompareOptions& opt) {
    if (opt.rule == CompareOptions::Rule::Mitsuba || opt.test == TwoSampleTest::Equivalence ||
        r.identical)
        return "";
    return powerText(r);
}

std::string compareVerdict(const CompareResult& r, const CompareOptions& opt) {
    if (opt.rule == CompareOptions::Rule::Mitsuba) return mitsubaVerdict(r, opt);
    const std::string how = fmt::format("{}, {}", testText(r, opt), controlText(opt));
    if (r.identical)
        return fmt::format(
            "IDENTICAL: every pixel's {} is the same on both sides (two copies of "
            "one render test nothing{}; {})",
            quantitiesText(r),
            opt.identicalFails ? ", and identical=fail makes that a failure" : "", how);
    if (r.underpowered)
        return fmt::format(
            "UNDERPOWERED: no pixel{} differs in {} beyond the noise, but {}, above "
            "minpower={:g} ({})",
            r.tile > 0 ? " or tile" : "", quantitiesText(r), powerText(r), opt.minPower, how);
    const std::string tiles =
        r.tile > 0 ? fmt::format(" and {} of {} tiles", r.tilesRejected, r.tilesTested) : "";
    if (opt.test == TwoSampleTest::Equivalence) {
        if (!r.fail)
            return fmt::format("EQUIVALENT{}: every {} agrees in {} ({})", toleranceText(opt),
                               r.tile > 0 ? "tile" : "pixel", quantitiesText(r), how);
        return fmt::format("NOT SHOWN EQUIVALENT{}: {} of {} {} not shown to agree in {} ({})",
                           toleranceText(opt), r.tile > 0 ? r.tilesRejected : r.pixelsRejected,
                           r.tile > 0 ? r.tilesTested : r.pixelsTested,
                           r.tile > 0 ? "tiles" : "pixels", quantitiesText(r), how);
    }
    if (r.fail)
        return fmt::format("DIFFERENT: {} of {} pixels{} differ{} in {} ({})", r.pixelsRejected,
                           r.pixelsTested, tiles,
                           opt.tol > 0 || opt.reltol > 0
                               ? " by more than" + toleranceText(opt).substr(7)
                               : std::string(),
                           quantitiesText(r), how);
    return fmt::format(
        "SAME: no pixel{} differs{} in {} beyond the noise; {} ({})", r.tile > 0 ? " or tile" : "",
        opt.tol > 0 || opt.reltol > 0 ? " by more than" + toleranceText(opt).substr(7)
                                      : std::string(),
        quantitiesText(r), powerText(r), how);
}

std::vector<std::string> compareEvidence(const CompareResult& r, const CompareOptions& opt) {
    std::vector<std::string> lines;
    const bool equivalence = opt.test == TwoSampleTest::Equivalence;
    lines.push_back(fmt::format(
        "pixels: {} tested of {}, {} {}{}", r.pixelsTested, r.pixels, r.pixelsRejected,
        equivalence ? "not shown equivalent" : "differ",
        r.tile > 0
            ? fmt::format("; tiles {}x{}: {} tested of {}, {} {}", r.tile, r.tile, r.tilesTested,
                          r.tiles, r.tilesRejected, equivalence ? "not shown equivalent" : "differ")
            : std::string("; no tile tests")));
    auto thr = [](double t) { return t < 0 ? std::string("none") : fmt::format("{:.3g}", t); };
    if (opt.rule == CompareOptions::Rule::Mitsuba)
        lines.push_back(fmt::format(
            "tested: {} channel tests at level {:.3g}; {} passed ({:.4g}%, {} needed)",
            r.channelTests, r.threshold, r.channelTestsPassed,
            r.channelTests ? 100.0 * double(r.channelTestsPassed) / double(r.channelTests) : 0.0,
            percentText(opt.passFraction)));
    else
        lines.push_back(fmt::format(
            "tested: {} hypotheses; largest p-value rejected: pixels {}{}", r.hypotheses,
            thr(r.threshold), r.tile > 0 ? ", tiles " + thr(r.tileThreshold) : std::string()));
    if (opt.rule == CompareOptions::Rule::Mcstat && !equivalence) {
        const ComparePower& w = r.power;
        auto one = [](double rel, double abs, const char* what) {
            return std::isfinite(abs)
                       ? fmt::format("{} ({:.4g} in the image's units) in one {}",
                                     std::isfinite(rel) ? changeText(rel) : std::string("?"), abs,
                                     what)
                       : std::string();
        };
        std::vector<std::string> parts;
        for (const std::string& t : {one(w.tileRelative, w.tileAbsolute, "tile"),
                                     one(w.pixelRelative, w.pixelAbsolute, "pixel")})
            if (!t.empty()) parts.push_back(t);
        lines.push_back(
            parts.empty()
                ? std::string("power: unknown (no tested hypothesis has noise)")
                : fmt::format("power: a change of {} is found with probability {:g} at this "
                              "level (medians over the tested hypotheses with noise){}",
                              fmt::join(parts, ", "), kComparePower,
                              opt.minPower > 0.0
                                  ? fmt::format("; minpower={:g} asks for {} per {}", opt.minPower,
                                                changeText(opt.minPower),
                                                std::isfinite(w.tileRelative) ? "tile" : "pixel")
                                  : std::string()));
    }
    const char* label = equivalence ? "least equivalent" : (r.fail ? "strongest" : "largest |z|");
    if (r.strongest.valid)
        lines.push_back(fmt::format("{}: {}", label, findingText(r.strongest, r, opt)));
    if (r.strongestTile.valid)
        lines.push_back(fmt::format("{} tile: {}", label, findingText(r.strongestTile, r, opt)));
    if (r.nonFiniteOneSide > 0)
        lines.push_back(
            fmt::format("{} pixels hold NaN or Inf on one side only (counted as "
                        "differing)",
                        r.nonFiniteOneSide));
    if (r.nonFiniteBoth > 0)
        lines.push_back(
            fmt::format("{} pixels hold NaN or Inf on both sides (not tested)", r.nonFiniteBoth));
    if (r.constantEqual > 0)
        lines.push_back(
            fmt::format("{} pixel tests had no noise and no difference (e.g. black "
                        "background)",
                        r.constantEqual));
    if (r.oneSample && !equivalence && r.rejectedNoisy >= 10 &&
        r.rejectedDarker * 10 >= r.rejectedNoisy * 9)
        lines.push_back(fmt::format(
            "warning: {} of the {} noisy pixels that differ are darker than the reference: the "
            "signature of rare paths (fireflies, caustics) this render has not seen yet, not of a "
            "change; compare against a statistics file of the reference instead (docs/compare.md)",
            r.rejectedDarker, r.rejectedNoisy));
    // Measured (docs/compare.md): 29 of 200 same-scene splits 10 + 11 of Cycles renders alarmed at
    // level 1 %, none of 200 at 21 + 21, none of 40 fixture pairs at 16 + 16.
    if (opt.trimmed && std::min(r.Ma, r.Mb) < 16)
        lines.push_back(fmt::format(
            "warning: Yuen's test on fewer than 16 buffers a side (here {}) can find no spread "
            "where the few kept buffer values cluster: on Cycles renders it alarmed in 14.5 % of "
            "10 + 11 splits of one scene at level 1 % (docs/compare.md); prefer test=welch or "
            "more seeds",
            std::min(r.Ma, r.Mb)));
    if (r.fewBuffers > 0)
        lines.push_back(
            fmt::format("{} pixels not tested: fewer than two non-empty buffers on a "
                        "side ({})",
                        r.fewBuffers,
                        r.adaptive ? "adaptive M gives smooth pixels one buffer"
                                   : "fewer samples than buffers"));
    if (r.tile > 0 && r.adaptive)
        lines.push_back(fmt::format(
            "tiles tested from their pixels' means and variances, pixels' noise taken as "
            "independent{} (a side has adaptive M or is a compact file: buffer indices differ "
            "from pixel to pixel)",
            opt.trimmed ? ", with Welch's t on both sides" : ""));
    return lines;
}

const std::vector<ParamSpec>& compareParams() {
    static const std::vector<ParamSpec> m = [] {
        ParamSpec aovs = textParam("aovs", "",
                                   "AOV channels to test too, each by itself: names or globs, "
                                   "comma-separated (e.g. *_key.*)");
        aovs.list = true;
        return std::vector<ParamSpec>{
            realParam("level", 0.0, 0.5, true, "0.01",
                      "false discovery rate (or error rate, see control) of the verdict"),
            enumParam("test", {"welch", "yuen"}, "welch",
                      "welch: means; yuen: trimmed means, robust to fireflies"),
            realParam("trim", 0.0, 0.45, false, "0.2", "yuen: fraction trimmed from each end"),
            enumParam("control", {"fdr", "fwer", "none"}, "fdr",
                      "fdr: Benjamini-Hochberg; fwer: Holm; none: each test alone"),
            enumParam("channels", {"luminance", "rgb"}, "luminance", "what a pixel is tested on",
                      {{"lum", "luminance"}, {"y", "luminance"}}),
            aovs,
            intParam("tile", 0, 4096, "16", "tile side for the tile tests; 0: pixels only"),
            realParam("tol", 0.0, HUGE_VAL, false, "0", "absolute tolerance (image units)"),
            realParam("reltol", 0.0, HUGE_VAL, false, "0",
                      "relative tolerance (fraction of the pixel's value)"),
            flagParam("equivalence", "0",
                      "1: show agreement within the tolerance (two one-sided tests per tile)"),
            realParam("refspp", 0.0, HUGE_VAL, false, "0",
                      "image reference: its samples per pixel (0: exact)"),
            textParam("layer", "", "image reference: its RGB layer (default: its beauty)"),
            textParam("refvar", "",
                      "image reference: its per-sample variance image (Mitsuba 3's _var.exr)"),
            enumParam("rule", {"mcstat", "mitsuba"}, "mcstat",
                      "mitsuba: Mitsuba 3's render-test rule against refvar (docs/compare.md)"),
            realParam("varfloor", 0.0, HUGE_VAL, false, "1e-4",
                      "rule=mitsuba: floor of the reference's variance"),
            realParam("passfraction", 0.0, 1.0, false, "0.9975",
                      "rule=mitsuba: fraction of channel tests that must pass"),
            realParam("minpower", 0.0, HUGE_VAL, false, "0",
                      "fail (UNDERPOWERED) unless a change of this fraction in one tile (one "
                      "pixel without tiles) would have been found with probability 0.8; 0: "
                      "no limit"),
            enumParam("identical", {"pass", "fail"}, "pass",
                      "fail: two copies of one render (IDENTICAL, which tests nothing) fail, "
                      "for CI"),
            textParam("junit", "", "write the verdict as JUnit XML to this file"),
            textParam("json", "", "write the verdict and its numbers as JSON to this file"),
            textParam("html", "", "write a report page (A, B, heatmap, numbers) into this folder"),
            textParam("name", "", "the test's name in the reports (default: A vs B)"),
        };
    }();
    return m;
}

bool parseCompareOptions(const std::map<std::string, std::string>& kv, CompareOptions& opt,
                         std::string& err, const std::string& context) {
    std::map<std::string, std::string> mods = kv;
    if (!checkModifiers(context, compareParams(), mods, err)) return false;
    Operation compare;  // the registry's parser gives the typed values
    compare.name = "compare";
    compare.params = compareParams();
    ParamValues v;
    if (!parseOperationParams(compare, mods, v, err, context)) return false;
    opt.level = v.at("level").real;
    opt.trimmed = v.at("test").text == "yuen";
    opt.trim = v.at("trim").real;
    const std::string control = v.at("control").text;
    opt.control = control == "fwer"   ? Multiplicity::FWER
                  : control == "none" ? Multiplicity::None
                                      : Multiplicity::FDR;
    opt.rgb = v.at("channels").text == "rgb";
    const std::string& aovs = v.at("aovs").text;
    opt.aovs = aovs.empty() ? std::vector<std::string>() : OIIO::Strutil::splits(aovs, ",");
    opt.tile = int(v.at("tile").integer);
    opt.tol = v.at("tol").real;
    opt.reltol = v.at("reltol").real;
    opt.test = v.at("equivalence").integer ? TwoSampleTest::Equivalence : TwoSampleTest::Difference;
    opt.referenceSpp = v.at("refspp").real;
    opt.rule = v.at("rule").text == "mitsuba" ? CompareOptions::Rule::Mitsuba
                                              : CompareOptions::Rule::Mcstat;
    opt.varianceFloor = v.at("varfloor").real;
    opt.passFraction = v.at("passfraction").real;
    opt.minPower = v.at("minpower").real;
    opt.identicalFails = v.at("identical").text == "fail";
    if (opt.minPower > 0.0 &&
        (opt.test != TwoSampleTest::Difference || opt.rule != CompareOptions::Rule::Mcstat)) {
        err = context +
              ": minpower is for the difference test of mcstat's rule (not with "
              "equivalence=1 or rule=mitsuba, whose verdicts state their own terms)";
        return false;
    }
    return true;
}

}  // namespace mcstat
