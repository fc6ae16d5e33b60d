// Private to compare/: the comparison engine's types (docs/compare.md). A Comparison reads both
// sides by the same blocks of rows (comparison.cpp), tests every pixel and tile of a block
// (comparison_tile.cpp), then decides the verdict over every p-value (comparison_decision.cpp) and
// draws its maps (comparison_maps.cpp); what a side holds per pixel is side_values.cpp's.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "mcstat/compare/compare.h"
#include "mcstat/core/float_rounding.h"

namespace mcstat::detail {

inline constexpr float kNaNf = std::numeric_limits<float>::quiet_NaN();

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

// ---- what a side holds per pixel (side_values.cpp)

/// Buffer values of quantity `q` of pixel p (local to the block) of a statistics side.
void gatherBuffers(const Side& s, const Quantity& q, bool sideB, size_t p,
                   const std::array<double, 3>& luma, std::vector<double>& values,
                   std::vector<double>& counts);
/// A compact file's pixel that keeps only its mean (one buffer where the file has M > 1): the
/// summary meanSummary gives on the full file's buffers, from what the compact file kept of them
/// (FORMAT.md "Version 6"): the valid buffers M', the mean and the between-buffer covariance of
/// R, G, B, s^2 = c^T C c for the quantity's weights c, variance s^2 / N, df = M' - 1. Yuen's
/// trimmed mean of such a pixel is its mean (G-MoN trimmed nothing), tested as Welch's.
bool compactSummary(const Side& s, const Quantity& q, size_t p, const std::array<double, 3>& luma,
                    SideSummary& out);
/// The reference image's value of quantity `q` at pixel (x, y) of the block's rows.
double referenceValue(const Side& s, const Quantity& q, int x, int y,
                      const std::array<double, 3>& luma);
/// The reference's per-sample variance of quantity `q` at pixel (x, y): a channel's, or for the
/// luminance sum w_c^2 var_c (the variance image holds no covariances: R, G and B of one pixel are
/// taken as independent, which understates the luminance's variance where they correlate).
double referenceVariance(const Side& s, const Quantity& q, int x, int y,
                         const std::array<double, 3>& luma);
/// A side's R, G, B mean at pixel `local` of the block (x, y in the image): the count-weighted mean
/// of its non-empty buffers, or the reference's values.
void rgbMean(const Side& s, size_t local, int x, int y, float* out);

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

/// One tile's task: what it tests by (whether tiles are tested, which sides are summed per pixel)
/// and its sums per quantity and buffer, with the buffers' values of the pixel at hand.
struct TileWork {
    bool tiles = false;
    /// A side summed from its pixels' summaries (PixelSums) rather than by buffer index.
    bool pixA = false, pixB = false;
    /// Buffers summed by index per side (0 for a reference side or one summed per pixel).
    size_t Ma = 0, Mb = 0;
    std::vector<double> va, ca, vb, cb;  ///< a pixel's (then the tile's) buffer values and counts
    std::vector<double> sumA, cntA, sumB, cntB, refSum, refVarSum;
    std::vector<uint8_t> tileBad;  ///< per quantity: a pixel was not finite on a side
    std::vector<PixelSums> sumsA, sumsB;
};

class Comparison {
  public:
    Comparison(Side& a, Side& b, const CompareOptions& opt, CompareResult& out)
        : a_(a), b_(b), opt_(opt), out_(out) {}

    bool run(std::string& err);

  private:
    bool resolveQuantities(std::string& err);
    bool processBlock(int row0, int rows, std::string& err);
    /// The tests of tile (tx, ty)'s pixels, then of the tile itself (comparison_tile.cpp).
    void testTile(int tx, int ty, int row0, Tally& tally);
    /// Every quantity's test of pixel (x, y) (block row y - row0), its values added to the tile's
    /// sums in `w`.
    void testPixelAt(int x, int y, int row0, TileWork& w, Tally& tally);
    /// Adds quantity qi's summaries `sa`, `sb` of pixel `local` (with b's `nb` samples) to the
    /// tile's sums in `w`.
    void addToTile(size_t qi, size_t local, const SideSummary& sa, const SideSummary& sb, double nb,
                   TileWork& w) const;
    /// The tests of tile `t` of `n` pixels from the sums `w` holds.
    void testTileSums(size_t t, double n, TileWork& w, Tally& tally);
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

}  // namespace mcstat::detail
