// Random parameter filtering (Sen and Darabi, "Implementation of Random Parameter Filtering",
// technical report, 2011; docs/rpf.md). Every sample carries its colour c, screen position p, the
// random parameters r it drew and scene features f (normals, world positions, texture values of the
// first and second hit). Per pixel, a neighbourhood of samples is drawn around it (Algorithm 2),
// the statistical dependency of colour and features on r and p is measured with mutual information
// (Algorithm 3, eq. 1-12), and the pixel's samples are filtered with a cross-bilateral filter whose
// colour and feature weights shrink with that dependency (Algorithm 4, eq. 15-20). Four passes with
// boxes 55, 35, 17, 7 (Algorithm 1).
//
// Pure functions over in-memory sample windows: no I/O and no OIIO types, so the offline command,
// the plugin and the tests share them. Deterministic: every random choice comes from a generator
// seeded by (seed, pass, pixel), so results do not depend on the thread count or on how the image
// is cut into blocks of rows.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace mcstat {

struct RpfParams {
    /// Box sizes of the passes (section 3.2): 55, 35, 17, 7 at 8 spp.
    std::vector<int> boxes{55, 35, 17, 7};
    /// Algorithm 1 line 8: at most M = b^2 * s * samplesFactor samples per neighbourhood (1/2).
    double samplesFactor = 0.5;
    /// ... and never more than this (the rule is the report's for 8 spp, where pass 1 draws
    /// 12,100; the cost of a pixel is its samples x |N|, so without a bound it would grow with
    /// the square of spp).
    int64_t maxNeighbourhood = 16384;
    /// Drawing stops once N holds this many draws (the pixel's samples included); 0: no bound.
    /// The draws are independent, so the first maxKept kept are a uniform random subset of what
    /// all M draws would keep: the report's own acceleration (its section 4.1 draws a random
    /// subset of the box for the same reason), applied where N is large. 1,536 halves the time
    /// of 256 x 256 at 8 spp for 1-3 % more relMSE (docs/rpf.md, "Speed and memory").
    int64_t maxKept = 1536;
    /// sigma_8^2 of section 6: the bilateral variance at 8 spp, sigma^2 = 8 sigma_8^2 / s.
    /// The report uses 0.002, and 0.02 for noisy indoor path-traced scenes.
    double sigma8sq = 0.002;
    /// Clustering (section 4.2): a neighbour is dropped when a feature lies more than
    /// featureSigmas (world positions: positionSigmas) pixel standard deviations from the
    /// pixel's mean, and either that distance exceeds `floor` or the deviation does.
    double featureSigmas = 3, positionSigmas = 30, floor = 0.1;
    /// Section 6.1: after each pass, a sample above its pixel's mean by more than the pixel's
    /// standard deviation (per channel) is set to the mean. Off by default: the report applies it
    /// only to path-traced scenes with small bright lights, and it removes the energy of pixels
    /// partly covering a bright edge (docs/rpf.md, "HDR spikes").
    bool spikes = false;
    /// epsilon of eq. 9 and 10.
    double epsilon = 1e-10;
    uint64_t seed = 0;
};

/// What one sample holds, by role; `RpfLayout::dims()` floats per sample in RpfWindow::x, in the
/// order colour (3), screen position (2), random parameters, features.
struct RpfLayout {
    int randoms = 0;   ///< n of Table I
    int features = 0;  ///< m of Table I
    /// Per feature: true for world positions (the 30-sigma clustering test of section 4.2).
    std::vector<bool> isPosition;
    int dims() const { return 5 + randoms + features; }
};

/// Rows [y0, y0 + rows) of an image `width` x `height`, every sample of every pixel: pixel
/// p = (y - y0) * width + x holds samples [offset[p], offset[p+1]).
struct RpfWindow {
    int width = 0, height = 0, y0 = 0, rows = 0;
    RpfLayout layout;
    std::vector<uint64_t> offset;  ///< pixels + 1 entries
    std::vector<float> x;          ///< samples * layout.dims(): c, p, r, f
    /// Per-sample AOVs (docs/aovs.md): `aovs` values per sample, samples * aovs. Every pass gives
    /// a sample's AOVs the weights w_ij its colour gets (a non-finite value is left out of its
    /// channel, the others renormalised); a spike (section 6.1) replaced in colour channel c
    /// replaces the AOVs that follow channel c (aovFollows, 0..2) by their mean over the pixel's
    /// samples too, so AOVs that sum to the colour keep summing. AOVs in aovFixed (labels) are
    /// never averaged: a pixel's result is its first sample's.
    size_t aovs = 0;
    std::vector<float> aov;
    std::vector<int> aovFollows;  ///< per AOV: the colour channel its spikes follow, or -1
    std::vector<bool> aovFixed;   ///< per AOV: a label, never averaged
    size_t samples() const { return offset.empty() ? 0 : size_t(offset.back()); }
    const float* sample(size_t i) const { return x.data() + i * size_t(layout.dims()); }
};

/// Per-pixel intermediate values of one pass (report Fig. 6), for pictures and tests.
struct RpfPixelReport {
    int neighbours = 0;                   ///< |N| after clustering
    std::array<double, 3> alpha{};        ///< eq. 15
    std::vector<double> beta;             ///< eq. 16, per feature
    double colorOnRandom = 0;             ///< W_c^r, eq. 11
    std::vector<double> featureOnRandom;  ///< W_f,k^r, eq. 9, per feature
};

// ---- building blocks (exposed for hand-worked tests) -------------------------------------------

/// Mutual information (eq. 1, natural log) of two equally long vectors already normalised to
/// standard deviation 1 (or any scale: values are binned by rounding after subtracting the
/// minimum, section 5.1). Bins are capped at `maxBins` per variable (values beyond go to the last
/// bin). Non-finite values must not be passed.
double mutualInformation(const float* a, const float* b, size_t n, int maxBins = 1024);

/// Eq. 9/10: the fraction of a dependency due to the random parameters.
inline double randomFraction(double dr, double dp, double epsilon) {
    return dr / (dr + dp + epsilon);
}

/// The weights of one neighbourhood (Algorithm 3): `xs` holds |N| samples (RpfLayout order,
/// already normalised, section 4.3); returns alpha (eq. 15), beta (eq. 16) and W_c^r (eq. 11).
struct RpfWeights {
    std::array<double, 3> alpha{};
    std::vector<double> beta;
    double colorOnRandom = 0;                      ///< W_c^r
    std::array<double, 3> colorChannelOnRandom{};  ///< W_c,k^r
    std::vector<double> featureOnRandom;           ///< W_f,k^r
    std::vector<double> colorOnFeature;            ///< W_c^f,k
};
RpfWeights rpfFeatureWeights(const RpfLayout& layout, const float* xs, size_t n, int pass,
                             double epsilon = 1e-10);

// ---- the filter ---------------------------------------------------------------------------------

/// One pass over the pixels of window rows [rowBegin, rowEnd) (absolute image rows): reads the
/// current colours `cIn` (3 per sample of the window) of the samples within the box and writes the
/// filtered colours of the pixels' own samples into `cOut` (same indexing). The window must hold
/// every image row within box/2 of the rows filtered. `report`, when given, receives one entry
/// per pixel of the rows (in scanline order).
/// `aIn` / `aOut`, when given, are the samples' AOVs (w.aovs per sample), filtered alike.
void rpfPass(const RpfWindow& w, const RpfParams& params, int pass, const std::vector<float>& cIn,
             std::vector<float>& cOut, int rowBegin, int rowEnd, int nthreads,
             std::vector<RpfPixelReport>* report = nullptr,
             const std::function<void(int)>& rowDone = {}, const std::vector<float>* aIn = nullptr,
             std::vector<float>* aOut = nullptr);

/// Rows of halo every side of a block of output rows: sum of box/2 over the passes (55 for the
/// report's boxes: 27 + 17 + 8 + 3).
int rpfHalo(const RpfParams& params);

/// Every pass over the window (which must hold rows [outBegin - halo, outEnd + halo] clipped to
/// the image), then the box filter of Algorithm 1 line 19: the mean of each pixel's filtered
/// samples for rows [outBegin, outEnd), RGB interleaved. A pixel without samples is 0.
/// `rowDone` is called (serialised) after each row of each pass.
/// `firstPass`, when given, receives pass 0's RpfPixelReport of the output rows' pixels (the
/// dependency maps of the report's Fig. 6).
/// With w.aovs > 0 and `aovOut`, the pixels' AOVs likewise (w.aovs per pixel).
void rpfFilterRows(const RpfWindow& w, const RpfParams& params, int outBegin, int outEnd,
                   std::vector<float>& rgb, int nthreads,
                   const std::function<void(int)>& rowDone = {},
                   std::vector<RpfPixelReport>* firstPass = nullptr,
                   std::vector<float>* aovOut = nullptr);

/// Checks parameters; false with a one-line `err`.
bool validateRpfParams(const RpfParams& p, std::string& err);

}  // namespace mcstat
