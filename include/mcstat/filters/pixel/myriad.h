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

/// Where the scale of the myriad's gamma and the meridian's delta comes from (parameter "scale").
enum class ScaleRule {
    /// factor x the range of the buffers within Hampel's fence |x_j - med| <= 3 x 1.4826 x MAD
    /// (detail::hampelRange): the thesis' 0.05 x range where no buffer is an outlier, and at most
    /// 8.9 x factor x MAD whatever one buffer (any fewer than half of them) holds. The default.
    Hampel,
    /// factor x the whole range max - min of the ranked values: the thesis' form (Jung 2016,
    /// section 4.2, "0.05 times the input range"). One buffer sets it: a buffer X far away gives
    /// gamma ~ 0.05 |X| and drags the myriad by about 4e-4 |X| at M = 7 (docs/estimators.md).
    Range,
    /// factor itself, in the values' units.
    Absolute,
};

struct MyriadParams : PixelParams {
    /// Scale gamma > 0 (eq. 4.7), a factor of the values' spread (ScaleRule) or an absolute value.
    /// The thesis used 0.05 x range (section 4.2).
    double gamma = 0.05;
    ScaleRule scale = ScaleRule::Hampel;
};

/// Myriad (eq. 4.7) with gamma = p.gamma x the spread p.scale names (the range within Hampel's
/// fence by default; the thesis' 0.05 x input range with ScaleRule::Range), or gamma = p.gamma.
/// PerChannel: each channel's myriad. Luminance: beta is the myriad of the buffers' luminances Y_j
/// and the RGB is sum n_j k_j theta_j / sum n_j k_j with the final weights k_j = gamma^2 / (gamma^2
/// + (Y_j - beta)^2): the luminance of that colour is beta (beta is the fixed point of those
/// weights). kept = buffers within gamma of beta (k_j >= 1/2). All values equal: their
/// count-weighted mean.
void estimateMyriad(const PixelBuffers& px, const MyriadParams& p, PixelEstimate& out,
                    EstimatorScratch& s);

/// Parameter "scale" (hampel / rel / abs) of the myriad and the meridian.
ParamSpec scaleParam();
/// ScaleRule from the parsed value of scaleParam.
ScaleRule scaleRule(const ParamValues& values);
/// The registry entry "myriad".
Operation myriadOperation();

}  // namespace mcstat
