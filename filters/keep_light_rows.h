// The steps of keep_light.h over bands of rows (internal to mcstat::filters): each reads per-pixel
// arrays that hold only some rows of the image and computes a range of rows of its output, so
// that keepLightStream (keep_light_stream.cpp) holds a few bands whatever the image's height and
// the whole-image functions of keep_light.h are the same steps over every row. Every window is
// clipped to the image, never to the rows held: the caller holds every row a window reaches.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "mcstat/filters/keep_light.h"

namespace mcstat::keeplight {

/// Per-pixel arrays that hold rows [first, first + count) of a width x height image, row `first`
/// at index 0 (null where a step does not read them or the caller has none).
struct HeldRows {
    int width = 0, height = 0;            ///< the whole image
    int first = 0, count = 0;             ///< the rows held
    size_t nc = 0;                        ///< residual channels per pixel
    const double* residual = nullptr;     ///< nc per pixel
    const float* d = nullptr;             ///< the luminance residual
    const float* se = nullptr;            ///< the plain mean's standard error
    const float* robustY = nullptr;       ///< the robust estimate's luminance, or null
    const uint8_t* active = nullptr;      ///< the pixel carries a residual
    const float* guide = nullptr;         ///< the return's guide (albedo luminance), or null
    const float* cluster = nullptr;       ///< the cluster guide, or null
    const uint8_t* scale = nullptr;       ///< index into the radii, from scalesRows
    const double* norm = nullptr;         ///< from normsRows, with a guide
    const double* clusterNorm = nullptr;  ///< from normsRows, with a cluster guide
    const uint8_t* restScale = nullptr;   ///< the rest's radius index (rules 6, 8), or null
    const float* restShare = nullptr;     ///< the share sent at scale (rules 6, 8), or null
    const float* light = nullptr;         ///< the rest's guide (guideRows), or null
    const double* lightNorm = nullptr;    ///< from normsRows: the light guide's at restScale
    const float* biasGuide = nullptr;     ///< rule 7's guide (keepLightBiasGuide), or null
    const double* biasNorm = nullptr;  ///< from normsRows: the bias guide's, radii 2 to biasRadius
    int biasRadius = 0;                ///< the largest radius that takes the bias guide

    /// Every row of a width x height image held (the whole-image functions of keep_light.h).
    static HeldRows whole(int width, int height) {
        HeldRows h;
        h.width = width;
        h.height = height;
        h.count = height;
        return h;
    }
    /// Index of pixel (x, y), y an image row within the rows held.
    size_t at(int x, int y) const { return size_t(y - first) * size_t(width) + size_t(x); }
    /// Whether pixel index p (as at() gives it) carries a finite nonzero residual to send: `active`
    /// where the caller gives it (keepLightStream's callers set it by this very test), else the
    /// residual's channels.
    bool sends(size_t p) const;
    /// The share of p's residual sent at scale[p]: restShare[p], or 1 without rules 6 and 8.
    double share(size_t p) const { return restShare ? double(restShare[p]) : 1.0; }
    /// Whether p sends a rest at radius index restScale[p] (rule 6: a cluster's luck; rule 8:
    /// radius 0, the light its neighbours' means hold, kept in place).
    bool sendsRest(size_t p) const { return restShare && restShare[p] < 1.f && sends(p); }
    /// Whether the windows of radius r take the bias guide (rule 7).
    bool byBias(int r) const { return biasGuide && r >= 2 && r <= biasRadius; }
};

/// The rows beyond [y0, y1) that each step reads: its windows' largest radius (at least 1, the
/// support test's and the cluster guide's 3 x 3).
int haloRows(const KeepLightParams& params);

/// keepLightScales for rows [y0, y1) into scale (rows [y0, y1) only): reads active over [y0, y1),
/// d and se over [y0 - haloRows, y1 + haloRows) and robustY over [y0 - 1, y1 + 1), clipped to the
/// image. The window sums are the same bits whatever rows are held.
void scalesRows(const HeldRows& held, const KeepLightParams& params, int y0, int y1, uint8_t* scale,
                uint8_t* restScale, float* restShare, float* bias, float* level, int nthreads);

/// keepLightBiasGuide over n pixels (rows of one image, any of them).
void biasGuideRows(const float* bias, const float* level, const float* guide, size_t n,
                   double floor, float* out, int nthreads);

/// keepLightClusterGuide into cluster and keepLightLightGuide into light for rows [y0, y1) (rows
/// [y0, y1) only; either may be null): reads robustY (null: 0) and d over [y0 - 1, y1 + 1)
/// clipped to the image. One pass: the cluster guide weighs by the light guide at the same pixel.
void guideRows(const HeldRows& held, int y0, int y1, float* cluster, float* light, int nthreads);

/// The weight sums of each sender's window over rows [y0, y1), at its own radius: norm[p] the
/// guide's tent sum (with a guide), clusterNorm[p] the cluster guide's (radius 1 only),
/// lightNorm[p] the light guide's at the rest's radius (rules 6 and 8: restScale); 0 where p sends
/// nothing or has no such window; biasNorm[p] the bias guide's, for the senders of radius 2 to
/// biasRadius (rule 7). Reads residual, scale, restScale, restShare, guide, cluster, light and
/// biasGuide over [y0 - radius, y1 + radius).
void normsRows(const HeldRows& held, const std::vector<int>& radii, int y0, int y1, double* norm,
               double* clusterNorm, double* lightNorm, double* biasNorm, int nthreads);

/// gatherRows' buffers, kept from one call to the next so that a stream's bands reuse them.
struct GatherScratch {
    std::vector<double> source, rows, plain, guided, clustered, lit, biased;
    std::vector<uint8_t> need, rowNeed, rowHas, rowUsed;
    size_t rowLength = 0;  ///< the source rows' doubles (width x channels) the buffers are for
};

/// The light that rows [y0, y1) receive, add[(y - y0) * width * nc + x * nc + c] (returnResidual's
/// sum over senders, with the guide, cluster, light and bias guides of the receiving pixel
/// applied): reads residual, scale, restScale, restShare, norm, clusterNorm, lightNorm, biasNorm
/// over [y0 - radius, y1 + radius), guide, cluster, light and biasGuide over [y0, y1).
void gatherRows(const HeldRows& held, const std::vector<int>& radii, int y0, int y1, double* add,
                GatherScratch& scratch, int nthreads);

}  // namespace mcstat::keeplight
