// The straightforward implementation of the per-pixel estimators (as they were before the speed
// work on filters/pixel/ranking.cpp and filters/pixel/myriad.cpp), kept unchanged as the oracle for
// the bit-identity tests (test_bit_identity.cpp). Do not optimise or "fix" this code: its only job
// is to be the old behaviour. Namespace mcstat::reference; same signatures as the library.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat::reference {

/// The parameters every estimator took then, in one struct (the library now gives each estimator
/// its own: PixelParams, GmonbParams, TmpeParams, MyriadParams, MeridianParams).
struct EstimatorParams {
    EstimatorMode mode = EstimatorMode::Luminance;
    std::array<double, 3> luma{0.0, 0.0, 0.0};
    double giniThreshold = 0.25;
    double alpha = 0.25;
    double gamma = 0.05;
    double delta = 0.05;
    bool scaleRelative = true;
    /// Issue 38's defaults, written here as plainly as the rest (off: the old behaviour): G-MoN's
    /// Gini of the magnitudes |x| (gini=abs), the M-estimators' range within Hampel's fence
    /// (scale=hampel, which takes precedence over scaleRelative).
    bool giniMagnitudes = false;
    bool scaleHampel = false;
};
using EstimatorFn = void (*)(const PixelBuffers&, const EstimatorParams&, PixelEstimate&,
                             EstimatorScratch&);

double giniSorted(const double* values, size_t n);
double giniMagnitudes(const double* values, size_t n);
int gmonTrim(double G, int M);
int tmpeTrim(double alpha, int M);
int collectValidBuffers(const PixelBuffers& px, std::vector<int>& order, int& excluded);

void estimateMean(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                  EstimatorScratch& s);
void estimateMoN(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                 EstimatorScratch& s);
void estimateGMoN(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                  EstimatorScratch& s);
void estimateGMoNb(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                   EstimatorScratch& s);
void estimateTMPE(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                  EstimatorScratch& s);

double myriadCost(const double* x, const double* w, int K, double gamma, double beta);
double myriadSorted(const double* x, const double* w, int K, double gamma);
double meridianCost(const double* x, const double* w, int K, double delta, double beta);
int meridianSorted(const double* x, const double* w, int K, double delta);
void estimateMyriad(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                    EstimatorScratch& s);
void estimateMeridian(const PixelBuffers& px, const EstimatorParams& p, PixelEstimate& out,
                      EstimatorScratch& s);

}  // namespace mcstat::reference
