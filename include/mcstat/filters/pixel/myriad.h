// The myriad (Jung eq. 4.7) over a pixel's M sub-buffer means: an M-estimator of location. Pure
// functions, no I/O. Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical
// Estimation Techniques", PhD thesis, University of Minnesota, 2016, sections 4.1.3 and 4.2.
// docs/estimators.md has the long form.
//
// Shared rules (pixel_estimate.h) hold: only valid buffers enter; no valid buffer gives black;
// counts are weights. Here a buffer's count n_j is a *sample weight* in the cost: the myriad
// minimises sum_j n_j log(gamma^2 + (x_j - beta)^2), i.e. a buffer of n_j samples counts as n_j
// copies of its mean (equal counts give the thesis' formulas).
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

// ---- one-dimensional building blocks (values sorted ascending and distinct, weights > 0) --------

/// Myriad cost in the form used for comparisons: sum_j w_j log1p(((x_j - beta) / gamma)^2), which
/// is eq. 4.7 minus the constant sum_j w_j log(gamma^2). Terms whose ratio would overflow are
/// computed as 2 (log|x_j - beta| - log gamma), so the cost is finite for any gamma > 0.
double myriadCost(const double* x, const double* w, int K, double gamma, double beta);

/// Global minimiser of eq. 4.7 over [x_0, x_{K-1}] for gamma > 0.
/// Method: every local minimum lies within gamma of a sample (where all |x_j - beta| > gamma the
/// cost is a sum of concave terms), so the global one lies in a window [x_i - gamma, x_i + gamma].
/// Windows are visited by increasing lower bound of the cost on them; from each sample x_i the
/// fixed-point (majorise-minimise) iteration beta <- sum w_j k_j x_j / sum w_j k_j, k_j = 1 / (1 +
/// ((x_j - beta)/gamma)^2), which never increases the cost, runs until a step is below 1e-10 gamma
/// (or 2 ulp of beta), at most 2000 steps; windows whose bound is not below the best cost found are
/// skipped. Costs within 1e-12 (relative) are a tie and the smaller beta wins. K = 1 returns x_0.
/// gamma -> 0 gives the most-weighted sample (the mode), gamma -> inf the mean.
double myriadSorted(const double* x, const double* w, int K, double gamma);

// ---- the estimator ------------------------------------------------------------------------------

struct MyriadParams : PixelParams {
    /// Scale gamma > 0 (eq. 4.7). With scaleRelative a factor of the pixel's input range (max - min
    /// of the valid values the estimator ranks): the thesis used 0.05 x range (section 4.2).
    /// Otherwise an absolute value.
    double gamma = 0.05;
    bool scaleRelative = true;
};

/// Myriad (eq. 4.7) with gamma = p.gamma x (max - min) of the ranked values when p.scaleRelative
/// (the thesis' 0.05 x input range), else gamma = p.gamma.
/// PerChannel: each channel's myriad. Luminance: beta is the myriad of the buffers' luminances Y_j
/// and the RGB is sum n_j k_j theta_j / sum n_j k_j with the final weights k_j = gamma^2 / (gamma^2
/// + (Y_j - beta)^2): the luminance of that colour is beta (beta is the fixed point of those
/// weights). kept = buffers within gamma of beta (k_j >= 1/2). All values equal: their
/// count-weighted mean.
void estimateMyriad(const PixelBuffers& px, const MyriadParams& p, PixelEstimate& out,
                    EstimatorScratch& s);

/// Parameter "scale" (rel / abs) of the myriad and the meridian.
ParamSpec scaleParam();
/// The registry entry "myriad".
Operation myriadOperation();

}  // namespace mcstat
