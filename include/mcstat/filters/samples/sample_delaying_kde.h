// Pajot, Barthe, Paulin, "Sample-Space Bright Spots Removal Using Density Estimation", GI 2011:
// a per-pixel average estimator robust to outliers. Every sample of a pixel, in the order it was
// taken, updates a kernel-density representation of the pixel's log-luminance distribution; a
// sample is splatted when its log-luminance is at most m, the upper bound of the last extended
// mode, and delayed otherwise. Delayed samples are splatted later if m rises (Algorithm 1).
//
// Pure and deterministic: no I/O, no OIIO types, no threads. The renderer (online), `mcstat
// --pajot` (offline, from the per-sample records) and the tests share this one implementation, so
// online and offline results are equal bit for bit when they see the same samples in the same
// order. docs/pajot.md is the long form of every rule below.
//
// Conventions chosen where the paper is silent (each tested in tests/filters/samples/):
// - Luminance Y = luma . rgb in double; a sample is *black* when Y <= 0 (zero, or negative
//   components summing to <= 0). Black samples are always splatted and never enter the
//   distribution (they have no log-luminance, section 3). Others have l = float(log(Y)); l is
//   rounded to float once, so every stored bound is exact in a float32 file.
// - A sample with a non-finite component is refused by add() (the caller counts it); it changes
//   nothing.
// - Acceptance: l <= m splats (section 3: "should not be added ... if its l value is greater than
//   the upper bound of the last extended mode"). With no extended mode, m = -infinity: every
//   non-black sample is delayed until two of them form one.
// - Kernels (Epanechnikov, support |x - x_i| < h_i, eq. 3) of two samples overlap when
//   |x_i - x_j| < h_i + h_j; equal values always share a mode (so zero bandwidths, from all-equal
//   luminances, still build extended modes of equal samples).
// - The estimate is the mean of the splatted samples (a renderer's film normalised by the weights
//   it received); 0 when nothing was splatted. During the learning phase (fewer than N samples)
//   nothing has been classified and the estimate is the plain mean of the samples so far.
// - The dubious list holds at most maxDelayed samples. When a sample must be delayed and the list
//   is full, the one with the largest log-luminance of the list and the newcomer (the newcomer on
//   ties) is discarded for good and counted; the distribution still counts it.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace mcstat {

/// How the modes' kernel bandwidths are chosen.
enum class PajotMethod {
    ADR,     ///< adaptive bandwidths (eq. 4) over the approximate distribution (section 4.2)
    ROT,     ///< rule-of-thumb constant bandwidth (eq. 5), modes above m only (section 4.4)
    Hybrid,  ///< both, ADR's m until T successive |m_rot - m_adr| / |m_adr| <= delta (section 4.6)
};

const char* pajotMethodName(PajotMethod m);
/// "adr", "rot" or "hybrid"; false otherwise.
bool parsePajotMethod(const std::string& text, PajotMethod& out);

struct PajotParams {
    PajotMethod method = PajotMethod::Hybrid;
    int learning = 50;    ///< N, samples of the learning phase (section 4.1; section 5 uses 50)
    int maxDelayed = 64;  ///< bound of the dubious list (section 4.1: "can be bounded")
    int T = 2;            ///< hybrid: successive small distances before ROT alone (section 4.6)
    double delta = 0.0;   ///< hybrid: largest relative distance counted as small
    std::array<double, 3> luma{0.2126, 0.7152, 0.0722};  ///< from the colour config (color.h)
};

/// Range checks of PajotParams; `err` is one line naming the parameter.
bool validatePajotParams(const PajotParams& p, std::string& err);

/// One mode of the approximate distribution (section 4.2): the log-luminances of its lowest and
/// highest samples and how many samples it holds. n = 1 is a single mode (lo = hi), n >= 2 an
/// extended one; its samples are approximated by n regularly spaced values in [lo, hi].
struct PajotMode {
    float lo = 0, hi = 0;
    uint32_t n = 0;
    bool extended() const { return n >= 2; }
};

/// A sample kept as it was taken: during learning, or while delayed (with its log-luminance).
struct PajotSample {
    std::array<float, 3> rgb{0.f, 0.f, 0.f};
    float l = 0;  ///< log-luminance; -infinity for a black sample
    /// The caller's name for the sample (its index in the pixel), so that it can learn which
    /// samples the estimate splatted (PajotPixel::logSplats) and weight their AOVs the same
    /// (docs/aovs.md). Not part of the stored state: -1 for samples read back from a file.
    int64_t tag = -1;
};

/// Where a pixel stands.
enum class PajotPhase : uint8_t {
    Learning = 0,  ///< fewer than N samples stored (section 4.1)
    ADR = 1,       ///< classifying with ADR's m (ADR, or the hybrid before its switch)
    ROT = 2,       ///< classifying with ROT's m (ROT, or the hybrid after its switch)
};

/// The complete state of one pixel: what the statistics file's parts `pajot` and `modes` store,
/// so that a render resumed from the file continues exactly (exr-deep/FORMAT.md, version 4).
struct PajotState {
    PajotPhase phase = PajotPhase::Learning;
    // Splatted samples (the estimate's numerator and denominator), accumulated in double.
    std::array<double, 3> sum{0.0, 0.0, 0.0};
    int64_t splatted = 0;
    int64_t discarded = 0;  ///< delayed samples dropped because the dubious list was full
    int64_t taken = 0;      ///< samples given to add() and accepted (finite)
    std::vector<PajotSample> learning;  ///< the first N samples, until the learning ends
    std::vector<PajotSample> delayed;   ///< the dubious list L, in the order delayed
    // ADR (section 4.2); released when the hybrid switches to ROT.
    std::vector<PajotMode> modes;  ///< sorted by lo, disjoint
    float mAdr = 0;                ///< ADR's m (-inf: no extended mode)
    // ROT (section 4.4): Welford statistics of every non-black l, m, and the single modes above m.
    int64_t rotN = 0;
    double rotMean = 0, rotM2 = 0;
    float mRot = 0;
    std::vector<float> rotSingles;  ///< sorted ascending, every value > mRot
    int run = 0;                    ///< hybrid: successive distances <= delta so far
};

/// Diagnostics of one pixel for benchmarks and `--info`.
struct PajotCounts {
    int64_t singleModes = 0, extendedModes = 0;
    int64_t delayed = 0;
    int64_t bytes = 0;  ///< memory of the representation (modes, ROT singles, dubious list)
};

/// The per-pixel online estimator: Algorithm 1 with the learning phase of section 4.1.
class PajotPixel {
  public:
    PajotPixel() = default;
    explicit PajotPixel(PajotState s) : s_(std::move(s)) {}

    /// Adds the next sample of the pixel. Returns false, changing nothing, when a component is
    /// not finite.
    bool add(const float rgb[3], const PajotParams& p, int64_t tag = -1);
    /// From now on, appends the tag of every sample splatted to `log` (null: stop). With the
    /// learning samples (while learning, the estimate is their plain mean) this names exactly the
    /// samples the estimate averages: splatTags.
    void logSplats(std::vector<int64_t>* log) { splatLog_ = log; }
    /// The tags of the samples estimate() averages, each with the same weight: while learning
    /// every learning sample, after it the splatted ones logged (logSplats from the first add).
    std::vector<int64_t> splatTags(const std::vector<int64_t>& log) const;
    /// The estimate so far (see the file comment).
    std::array<float, 3> estimate() const;
    /// The current acceptance value m (-inf with no extended mode; learning: -inf).
    float acceptance() const;
    PajotCounts counts() const;
    const PajotState& state() const { return s_; }
    PajotState& state() { return s_; }

  private:
    void finishLearning(const PajotParams& p);
    void offer(const PajotSample& smp, const PajotParams& p);  ///< splat or delay
    void splat(const PajotSample& smp);
    void delay(const PajotSample& smp, const PajotParams& p);
    void retest();  ///< splats delayed samples at or below the current m (m rose)
    PajotState s_;
    std::vector<int64_t>* splatLog_ = nullptr;
};

/// log-luminance of a sample as the estimator computes it (-inf when black), for tests and tools.
float pajotLogLuminance(const float rgb[3], const std::array<double, 3>& luma);

// ---- building blocks, exposed for the hand-worked tests -----------------------------------------

/// Mean nearest-neighbour distance of the approximate distribution `modes` (section 4.2: each mode
/// of n samples stands for n regularly spaced values in [lo, hi]); 0 with fewer than two values.
double adrNearestNeighbour(const std::vector<PajotMode>& modes);
/// Eq. 3 with the same bandwidth h > 0 for every value of the approximate distribution: the
/// estimated density at x (the pilot density of eq. 4 when h = nn).
double adrDensity(const std::vector<PajotMode>& modes, double x, double h);
/// Eq. 5: (25 n)^(-1/5) sigma.
double rotBandwidth(int64_t n, double sigma);
/// Modes of sorted values `l` with per-value bandwidths `h` by aggregation (section 4.2 "initial
/// learning"): consecutive values whose kernels overlap, or that are equal, share a mode.
std::vector<PajotMode> aggregateModes(const std::vector<float>& l, const std::vector<double>& h);
/// Eq. 4 over the exact values `l` (sorted): nn, the pilot density with bandwidth nn, and h_i.
std::vector<double> adaptiveBandwidths(const std::vector<float>& l);
/// What one ADR update computed when the value started a new mode (for the tests that pin the
/// arithmetic bit for bit): nn, eq. 4's G, and the bandwidths at the new value and at the extreme
/// samples of the modes below and above it (0 where there is none).
struct AdrUpdateTrace {
    bool inserted = false;  ///< false: the value fell inside a mode, nothing was computed
    double nn = 0, g = 0, h = 0, hBelow = 0, hAbove = 0;
    bool below = false, above = false;  ///< the merges decided (from the exact values)
    /// What the bounds of G alone decided: 1 merge, 0 not, -1 unsettled (exact G needed).
    int certBelow = -1, certAbove = -1;
    /// The bounds of G last formed (one pair per mode, or per point when those did not settle;
    /// 0 when none were formed).
    double gLo = 0, gHi = 0;
};
/// ADR's incremental update (section 4.2) of sorted, disjoint `modes` by a non-black value l, as
/// PajotPixel::add makes it. Without a trace the merges come from bounds of eq. 4's G when those
/// settle them (the same decisions as the exact G's, by construction); with one, always from the
/// exact values, which it records.
void adrUpdate(std::vector<PajotMode>& modes, float l, AdrUpdateTrace* trace = nullptr);
/// Updates on this thread (without a trace) whose merges the bounds settled: for the tests.
uint64_t adrCertifiedUpdates();
/// m of a mode list: the hi of the last extended mode, -inf when none.
float lastExtendedUpperBound(const std::vector<PajotMode>& modes);

}  // namespace mcstat
