// Noise-aware comparison of two renders from their sub-buffers (`mcstat --compare`,
// docs/compare.md): are the two the same image, up to their Monte Carlo noise?
//
// Per pixel, and per tile where averaging gains power for diffuse changes, a two-sample test on
// the sub-buffer means of both sides (two_sample.h: Welch's t, or Yuen's trimmed t against
// fireflies), on the luminance by default, on R, G, B or named AOV channels on request; then one
// multiple-testing control over every pixel and tile tested (Benjamini-Hochberg by default). The
// result is a verdict, the evidence behind it and maps (p-values, effects in standard errors and
// in the image's units) for review tools.
//
// Both sides are read by blocks of rows (StatsBlockSource); what grows with the image is one
// p-value per hypothesis and the maps (4 bytes per pixel and channel), never the sub-buffers.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <array>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "mcstat/analysis/two_sample.h"
#include "mcstat/core/params.h"
#include "mcstat/exr-deep/stats_file.h"

namespace mcstat {

struct CompareOptions {
    std::array<double, 3> luma{0.2126, 0.7152, 0.0722};  ///< luminance weights of R, G, B
    /// Yuen's trimmed test (trimmedSummary) instead of Welch's on the means (meanSummary).
    bool trimmed = false;
    double trim = 0.2;  ///< Yuen's trimming fraction per end, [0, 0.5)
    TwoSampleTest test = TwoSampleTest::Difference;
    double level = 0.01;  ///< q: false discovery rate, family-wise error rate or per-test level
    Multiplicity control = Multiplicity::FDR;
    bool rgb = false;  ///< test R, G, B (three hypotheses per pixel) instead of the luminance
    /// AOV channels of both files to test as well, each by itself: exact names or globs
    /// (fnmatch, e.g. "*_key.*"); empty: none.
    std::vector<std::string> aovs;
    int tile = 16;  ///< tile side in pixels for the tile tests; 0: pixels only
    /// Tolerance of the test: delta = max(tol, reltol * |(a + b) / 2|) per hypothesis.
    double tol = 0.0, reltol = 0.0;
    /// One-sample comparison against a reference image: its samples per pixel, when it is a
    /// render itself (its noise is then modelled with the statistics file's per-sample variance);
    /// 0: the reference is taken as exact.
    double referenceSpp = 0.0;
    /// The decision rule. Mcstat: the tests and the multiple-testing control above. Mitsuba:
    /// Mitsuba 3's render-test rule (mitsuba-renderer/mitsuba3, src/render/tests/test_renders.py),
    /// for a statistics file against a reference mean image with its per-sample variance image: per
    /// pixel and channel R, G, B, z = |b - ref| sqrt(N_b / max(var, varianceFloor)) (N_b the file's
    /// samples at the pixel), a two-sided normal p-value, the Sidak level
    /// 1 - (1 - level)^(1 / pixels), and a pass when at least passFraction of the pixels' channel
    /// tests pass; no tiles (docs/compare.md, "Mitsuba 3's references").
    enum class Rule { Mcstat, Mitsuba } rule = Rule::Mcstat;
    double varianceFloor = 1e-4;   ///< Mitsuba: the floor of the reference's variance
    double passFraction = 0.9975;  ///< Mitsuba: the fraction of channel tests that must pass
    /// A difference test (mcstat's rule) that finds nothing fails unless it could have found a
    /// relative change of minPower in one tile (one pixel without tiles) with probability
    /// kComparePower: its median detectable change (CompareResult::power) must be at most this.
    /// 0: any power passes.
    double minPower = 0.0;
    /// IDENTICAL (two copies of one render, which test nothing) fails: for CI, where a test that
    /// compares a file with itself must not pass.
    bool identicalFails = false;
    /// Keep both sides' RGB means (CompareResult::meanA, meanB) for a report's pictures.
    bool keepMeans = false;
    int nthreads = 0;
    std::function<void(double)> progress;  ///< fraction done, or empty
};

/// The comparison's parameters as `mcstat --compare:key=value` and Python's mcstat.compare take
/// them: level, test, trim, control, channels, aovs, tile, tol, reltol, equivalence, refspp, layer,
/// refvar, rule, varfloor, passfraction, and the reports' junit, json, html and name
/// (compare_report.h).
const std::vector<ParamSpec>& compareParams();
/// Parses key=value parameters (compareParams(), defaults for those not given) into `opt`; luma,
/// nthreads and progress are left as they are. False with the one-line error of the one parser
/// (parseParamValue, `context` naming the command) or for an unknown key. `layer` and `refvar`
/// concern an image reference and the reports their files; the caller reads them from `kv`.
bool parseCompareOptions(const std::map<std::string, std::string>& kv, CompareOptions& opt,
                         std::string& err, const std::string& context = "--compare");

/// One hypothesis worth reporting: where, on what, and what was found.
struct CompareFinding {
    bool valid = false;
    bool tile = false;        ///< a tile test (x, y its first pixel; size CompareResult::tile)
    int x = 0, y = 0;         ///< image coordinates (the data window's, origin included)
    std::string quantity;     ///< "luminance", "R", an AOV channel name
    double a = 0.0, b = 0.0;  ///< the two estimates
    TwoSampleResult result;   ///< p, z, difference, se and margin (df is not kept per pixel)
};

/// The probability with which CompareResult::power's changes are found.
constexpr double kComparePower = 0.8;

/// What a difference test could have seen: the smallest change that one tile, or one pixel, alone
/// would have been found with probability kComparePower at the verdict's level and multiple-testing
/// control (the first rejection of Benjamini-Hochberg's and Holm's steps needs p <= q / m, q the
/// family's level, m its tested hypotheses; control=none: p <= q), each hypothesis's from its own
/// standard error and degrees of freedom (two_sample.h: detectableDifference). Medians over the
/// tested hypotheses with noise: relative to side A's value (where it is not 0) and in the image's
/// units. NaN where none was computed: no tile tests, no tested hypothesis with noise, the
/// equivalence test, Mitsuba's rule.
struct ComparePower {
    double tileRelative = std::numeric_limits<double>::quiet_NaN();
    double tileAbsolute = std::numeric_limits<double>::quiet_NaN();
    double pixelRelative = std::numeric_limits<double>::quiet_NaN();
    double pixelAbsolute = std::numeric_limits<double>::quiet_NaN();
};

struct CompareResult {
    /// Difference test: some hypothesis was rejected (they differ). Equivalence test: not every
    /// hypothesis was rejected (equivalence not shown).
    bool fail = false;
    /// Every difference tested was exactly zero with zero variance on both sides: two copies of
    /// one render.
    bool identical = false;
    /// What the test could have seen (difference tests, mcstat's rule).
    ComparePower power;
    /// Nothing differs, but the test could not have found CompareOptions::minPower: it fails.
    bool underpowered = false;
    std::vector<std::string> quantities;  ///< what was tested per pixel, e.g. {"luminance"}
    int width = 0, height = 0, originX = 0, originY = 0;
    int Ma = 0, Mb = 0;  ///< buffers per pixel of each side (Mb only for a reference image: 0)
    bool oneSample = false;
    int tile = 0;  ///< tile side used (0: no tile tests)
    size_t pixels = 0, pixelsTested = 0, pixelsRejected = 0;
    size_t tiles = 0, tilesTested = 0, tilesRejected = 0;
    /// Pixels with NaN / Inf in some buffer of one side only: counted as differing (p = 0), since
    /// a renderer that starts making NaNs has changed. Both sides: left untested.
    size_t nonFiniteOneSide = 0, nonFiniteBoth = 0;
    /// One-sample: of the pixels declared different with a finite z, how many are darker than the
    /// reference (b < a). Nearly all of them is the signature of rare paths the statistics file has
    /// not seen yet, not of a change (docs/compare.md, "Against a reference image").
    size_t rejectedNoisy = 0, rejectedDarker = 0;
    /// Pixels left untested because a side has fewer than two non-empty buffers there (adaptive M
    /// gives smooth pixels one buffer; spp < M leaves buffers empty).
    size_t fewBuffers = 0;
    bool adaptive = false;  ///< a side has adaptive M (Ma, Mb are then the largest m_p)
    /// Pixels constant (zero variance) and equal on both sides: nothing to test, counted as
    /// agreeing.
    size_t constantEqual = 0;
    size_t hypotheses = 0;  ///< p-values tested (pixels and tiles)
    /// The largest rejected p-value of the pixels' and of the tiles' family (-1: none). The two
    /// families are controlled at half the level each (Bonferroni over the two).
    double threshold = -1.0, tileThreshold = -1.0;
    /// Difference test: the rejected hypothesis with the largest |z| (none rejected: the largest
    /// |z| tested). Equivalence test: the hypothesis with the largest p (the least equivalent).
    CompareFinding strongest;
    CompareFinding strongestTile;
    /// Maps over the data window: per quantity suffix s ("" for the luminance, ".R", ".<aov>")
    /// channels p<s>, z<s>, effect<s> (b - a), differs<s> (1 rejected, 0 not, NaN untested), and
    /// with tiles tile.p<s>, tile.z<s>, tile.differs<s> (each pixel its tile's). Differences test:
    /// "differs" means rejected; equivalence test: not shown equivalent.
    OIIO::ImageBuf maps;
    /// With CompareOptions::keepMeans: each side's R, G, B mean over the data window (a reference
    /// image: its values).
    OIIO::ImageBuf meanA, meanB;
    /// Mitsuba's rule: the channel tests that passed and the fraction of them it needs.
    size_t channelTests = 0, channelTestsPassed = 0;
};

/// Compares `b` against `a` (b - a), both statistics sources of one image (same data window; M
/// may differ). False with `err` naming the sources for: different windows, M < 2 on a side (no
/// variance), AOVs asked for that a side lacks, a bad option, a read failure.
bool compareStats(StatsBlockSource& a, StatsBlockSource& b, const CompareOptions& opt,
                  CompareResult& out, std::string& err);

/// One-sample comparison of `b` against a reference image `ref` (R, G, B: its first three
/// channels, pixels paired by their place in each data window, same size), exact or with
/// opt.referenceSpp samples per pixel. With `refVar` (R, G, B per-sample variances of the
/// reference, as Mitsuba 3 stores them; needs opt.referenceSpp > 0) the reference's noise is
/// var / referenceSpp per pixel instead of b's own scaled, and opt.rule may be Mitsuba. AOVs cannot
/// be asked for, nor Yuen's test (a trimmed mean is not the mean a reference holds).
/// Anti-conservative on heavy-tailed pixels: a render that has not yet seen a pixel's rare paths
/// has a lower mean and a smaller spread there than the converged reference (docs/compare.md);
/// prefer compareStats against a stored statistics file.
bool compareStatsToImage(const OIIO::ImageBuf& ref, const std::string& refName, StatsBlockSource& b,
                         const CompareOptions& opt, CompareResult& out, std::string& err,
                         const OIIO::ImageBuf* refVar = nullptr);

/// The verdict in one line, e.g. "DIFFERENT: 9576 of 16384 pixels and 61 of 64 tiles differ in
/// luminance (Welch's t on M = 21 + 21 sub-buffers, false discovery rate 1%)".
std::string compareVerdict(const CompareResult& r, const CompareOptions& opt);
/// What a difference test of mcstat's rule could have seen, in the words SAME and UNDERPOWERED
/// verdicts state it ("it finds a change of 3.9 % in one tile or 41 % in one pixel with
/// probability 0.8 (medians)"); empty for Mitsuba's rule, the equivalence test and IDENTICAL.
std::string comparePowerText(const CompareResult& r, const CompareOptions& opt);
/// The evidence, one line per item (counts, the strongest finding with its place and size, the
/// untested pixels).
std::vector<std::string> compareEvidence(const CompareResult& r, const CompareOptions& opt);

}  // namespace mcstat
