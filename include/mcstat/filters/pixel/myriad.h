// M-estimators of Jung's thesis over a pixel's M sub-buffer means: the myriad (eq. 4.7) and the
// meridian (eq. 4.8). Pure functions, no I/O. TMPE (eq. 5.1) and MPE (eq. 4.6 / 5.2) are rank
// estimators and live with the others in estimators.h.
//
// Thesis: Jung, "Robust statistical pixel estimation", 2016, chapters 4 and 5
// (Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical Estimation
// Techniques", PhD thesis, University of Minnesota, 2016). docs/estimators.md has the long form.
//
// Shared rules (estimators.h) hold: only valid buffers enter; no valid buffer gives black; counts
// are weights. Here a buffer's count n_j is a *sample weight* in the cost: the myriad minimises
// sum_j n_j log(gamma^2 + (x_j - beta)^2) and the meridian sum_j n_j log(delta + |x_j - beta|),
// i.e. a buffer of n_j samples counts as n_j copies of its mean (equal counts give the thesis'
// formulas).
#pragma once

#include "mcstat/filters/pixel/ranking.h"

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

/// Meridian cost: sum_j w_j log1p(|x_j - beta| / delta), eq. 4.8 minus sum_j w_j log(delta).
double meridianCost(const double* x, const double* w, int K, double delta, double beta);

/// Index of the sample minimising eq. 4.8 (the cost is concave between samples, so the minimum over
/// the real line is at a sample). Ties (relative 1e-12) go to the lowest index (the smallest
/// value).
int meridianSorted(const double* x, const double* w, int K, double delta);

// ---- the estimators -----------------------------------------------------------------------------

/// Myriad (eq. 4.7) with gamma = p.gamma x (max - min) of the ranked values when p.scaleRelative
/// (the thesis' 0.05 x input range), else gamma = p.gamma.
/// PerChannel: each channel's myriad. Luminance: beta is the myriad of the buffers' luminances Y_j
/// and the RGB is sum n_j k_j theta_j / sum n_j k_j with the final weights k_j = gamma^2 / (gamma^2
/// + (Y_j - beta)^2): the luminance of that colour is beta (beta is the fixed point of those
/// weights). kept = buffers within gamma of beta (k_j >= 1/2). All values equal: their
/// count-weighted mean.
void estimateMyriad(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                    EstimatorScratch& s);

/// Meridian (eq. 4.8), a selection estimator, with delta = p.delta x range (relative) or p.delta.
/// PerChannel: the selected value per channel. Luminance: the RGB of the selected buffer (among
/// buffers of equal luminance, the lowest buffer index). kept = 1 (buffers holding the value, per
/// channel).
void estimateMeridian(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                      EstimatorScratch& s);

}  // namespace mcstat
