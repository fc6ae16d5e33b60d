// The meridian (Jung eq. 4.8) over a pixel's M sub-buffer means: a selection M-estimator. Pure
// functions, no I/O. Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical
// Estimation Techniques", PhD thesis, University of Minnesota, 2016, sections 4.1.3 and 4.2.
// docs/estimators.md has the long form.
//
// Shared rules (pixel_estimate.h) hold: only valid buffers enter; no valid buffer gives black;
// counts are weights. A buffer's count n_j is a *sample weight* in the cost: the meridian
// minimises sum_j n_j log(delta + |x_j - beta|), i.e. a buffer of n_j samples counts as n_j copies
// of its mean (equal counts give the thesis' formula).
#pragma once

#include "mcstat/filters/operation.h"
#include "mcstat/filters/pixel/myriad.h"  // scaleParam
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

// ---- one-dimensional building blocks (values sorted ascending and distinct, weights > 0) --------

/// Meridian cost: sum_j w_j log1p(|x_j - beta| / delta), eq. 4.8 minus sum_j w_j log(delta).
double meridianCost(const double* x, const double* w, int K, double delta, double beta);

/// Index of the sample minimising eq. 4.8 (the cost is concave between samples, so the minimum over
/// the real line is at a sample). Ties (relative 1e-12) go to the lowest index (the smallest
/// value).
int meridianSorted(const double* x, const double* w, int K, double delta);

// ---- the estimator ------------------------------------------------------------------------------

struct MeridianParams : PixelParams {
    /// Scale delta > 0 (eq. 4.8), a factor of the values' spread (ScaleRule, myriad.h) or an
    /// absolute value, as the myriad's gamma.
    double delta = 0.05;
    ScaleRule scale = ScaleRule::Hampel;
};

/// Meridian (eq. 4.8), a selection estimator, with delta = p.delta x the spread p.scale names
/// (ScaleRule) or p.delta.
/// PerChannel: the selected value per channel. Luminance: the RGB of the selected buffer (among
/// buffers of equal luminance, the lowest buffer index). kept = 1 (buffers holding the value, per
/// channel).
void estimateMeridian(const PixelBuffers& px, const MeridianParams& p, PixelEstimate& out,
                      EstimatorScratch& s);

/// The registry entry "meridian".
Operation meridianOperation();

}  // namespace mcstat
