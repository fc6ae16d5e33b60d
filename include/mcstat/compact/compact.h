// Compact statistics files (`mcstat --compact`, FORMAT.md "Version 6"): a pixel keeps its M
// sub-buffers only where G-MoN would trim any of them, and otherwise the one mean G-MoN returns
// for it, decided after the samples are in. Pure per-pixel functions, and a block source that
// turns a full file into a compact one a block of rows at a time.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "mcstat/core/pixel_buffers.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

/// Which pixels keep their buffers. The default (margin 0, z 0) keeps exactly those where G-MoN
/// (Buisine et al. 2021, eq. 4 and 6) trims at least one buffer in luminance or channel mode, so
/// G-MoN on the compact file equals G-MoN on the full file bit for bit in both modes.
struct CompactRule {
    /// Luminance weights G-MoN ranks by (the OCIO config's, as everywhere); G-MoN in luminance
    /// mode is exact on the compact file when it uses the same weights.
    std::array<double, 3> luma{0.0, 0.0, 0.0};
    /// Also keep a pixel whose Gini coefficient G (any mode) is within this fraction of G-MoN's
    /// threshold: G * floor(M'/2) >= 1 - margin. 0..1; 1 keeps every pixel with G > 0.
    double margin = 0.0;
    /// Also keep a pixel whose luminance of some buffer lies more than z robust sigmas (1.4826
    /// times the median absolute deviation) from the buffers' median; 0: off.
    double z = 0.0;
};

/// "gmon luma=0.2126,0.7152,0.0722 margin=0 z=0": the rule as stored in mcstat:compact.
std::string compactRuleText(const CompactRule& rule);

/// Checks a rule's values; false with `err` (a phrase) otherwise.
bool checkCompactRule(const CompactRule& rule, std::string& err);

/// Per-thread scratch of compactKeeps.
struct CompactScratch {
    EstimatorScratch estimator;
    /// After compactKeeps: the pixel's valid buffers, as collectValidBuffers gives them.
    std::vector<int> valid;
    std::vector<double> lum, deviation;
};

/// Whether pixel `px` keeps its buffers under `rule`. When it does not, `mean` is the value G-MoN
/// returns for it in both modes (the count-weighted mean of its valid buffers) and, with
/// `weights`, the buffer weights G-MoN gives it in luminance mode (for the AOVs). A pixel with a
/// NaN or infinite buffer always keeps its buffers (every estimator decides what to do with it).
/// Either way scratch.valid lists the pixel's valid buffers afterwards.
bool compactKeeps(const PixelBuffers& px, const CompactRule& rule, CompactScratch& scratch,
                  std::array<float, 3>& mean, std::vector<double>* weights = nullptr);

/// The spread of pixel `px` (StatsImage::spread, kSpreadFloats values) over its valid buffers
/// `valid` (as collectValidBuffers gives them): their number M' and the between-buffer covariance
/// of R, G, B, sum_j n_j (x_j - mx) (y_j - my) / (M' - 1) with mx, my the count-weighted means,
/// accumulated in double; NaN for M' < 2. A compact file stores it for the pixels without buffers
/// and, for the others, M' and zeros (their buffers give the rest).
void bufferSpread(const PixelBuffers& px, const std::vector<int>& valid, float* out);

/// The header of the compact file made from a file with header `full` (named `name` in
/// messages) under `rule`: the adaptive layout, format version 8, the rule's text, no per-sample
/// parts. False with `err` for an adaptive or already compact file, or an invalid rule.
bool compactHeader(const StatsHeader& full, const std::string& name, const CompactRule& rule,
                   StatsHeader& out, std::string& err);

/// A compact file's rows from a fixed-M source, a block at a time (memory follows the blocks).
/// The source must outlive this. Per-sample parts are not passed on (the caller copies them).
class CompactStatsSource final : public StatsBlockSource {
  public:
    /// False with `err` when `src` cannot be compacted (adaptive M, already compact) or the rule
    /// is invalid. `nthreads` decide the pixels of a block (0: all cores).
    bool init(StatsBlockSource& src, const CompactRule& rule, std::string& err, int nthreads = 0);
    const StatsHeader& header() const override { return header_; }
    const std::string& name() const override { return src_->name(); }
    int chunkRows() const override { return src_->chunkRows(); }
    int decodeThreads() const override { return src_->decodeThreads(); }
    int blocksHeld() const override { return src_->blocksHeld() + 1; }
    bool read(int firstRow, int rows, unsigned parts, StatsImage& block, std::string& err) override;

  private:
    StatsBlockSource* src_ = nullptr;
    StatsHeader header_;
    CompactRule rule_;
    int nthreads_ = 0;
    StatsImage full_;
};

/// compacts a whole image in memory (CompactStatsSource over a MemoryStatsSource).
bool compactStats(const StatsImage& full, const CompactRule& rule, StatsImage& out,
                  std::string& err, int nthreads = 0);

}  // namespace mcstat
