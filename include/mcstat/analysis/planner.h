// Jung's analytic error rates (thesis chapters 4 and 5,
// Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical Estimation
// Techniques", PhD thesis, University of Minnesota, 2016): the probability that a sample of
// probability p reaches the final pixel through MPE(m), MIF(n), MPE(m)+MIF(n) and 3DMF(m x n), and
// the design questions built on them. Pure functions, no I/O; docs/planner.md has the long form.
//
// Every probability is carried as a pair of natural logarithms: log P (the sample reaches the
// pixel) and log (1 - P) (it does not), each computed *directly* as its own binomial tail sum in
// log space (lgamma + log-sum-exp), never as 1 - (the other). So both stay accurate from 1 down to
// 1e-300 and below (the logs stay finite where the values underflow), for m up to 101 and windows
// of any size.
#pragma once

#include <string>

namespace mcstat::planner {

/// log P and log(1 - P) of one event. -inf stands for probability 0.
struct LogProb {
    double lnP = 0.0;      ///< log P
    double lnNot = 0.0;    ///< log (1 - P)
    double value() const;  ///< P (0 when it underflows)
    double log10() const;  ///< log10 P (-inf for 0)
};

/// The event q with log q and log(1 - q) from q itself (0 <= q <= 1).
LogProb fromProbability(double q);
/// The event with log q given (log q <= 0); log(1 - q) by log1p / expm1, without cancellation.
LogProb fromLog(double logq);

/// Pr(X >= k) and, as lnNot, Pr(X < k) for X ~ Binomial(n, q), both summed directly in log space
/// (eq. 4.12 is this with k = ceil(n/2)).
LogProb binomialTail(int n, int k, const LogProb& q);

enum class Method {
    MPE,     ///< median pixel estimate over m buffers, eq. 4.13 / 5.3
    MIF,     ///< median image filter over n pixels, eq. 5.9 with p_pixel = N p (eq. 5.10)
    MPEMIF,  ///< MPE(m) then MIF(n), eq. 5.16
    DMF3,    ///< 3D median filter over m x n buffer means, eq. 5.22
};

struct Design {
    Method method = Method::MPE;
    int m = 1;  ///< pixel buffers (ignored by MIF)
    int n = 1;  ///< filter window in pixels, k x l (ignored by MPE)
};

/// "MPE(7)", "MIF(3x3)", "MPE(7)+MIF(3x3)", "3DMF(7x3x3)" (a square window is written k x k; a
/// window that is not a square is written as its pixel count).
const char* methodName(Method m);
std::string designName(const Design& d);

/// The probability that one buffer (MPE, MPE+MIF, 3DMF) or one pixel (MIF) holds the sample, from
/// the normalised probability x = N p with the thesis' linearisation (eq. 4.10): q = x / m, and q =
/// x for MIF (eq. 5.10); capped at 1.
LogProb unitProbabilityLinear(const Design& d, double np);
/// The same without the linearisation: q = 1 - (1 - p)^(N/m) (eq. 4.10 first line), N/m samples per
/// buffer (N per pixel for MIF); computed as -expm1((N/m) log1p(-p)).
LogProb unitProbabilityExact(const Design& d, double p, double spp);

/// The probability that the sample reaches the final pixel, given the unit probability q
/// (eq. 5.3 / 5.9 / 5.16 / 5.22: binomial tails at ceil(m/2), ceil(n/2), ceil(mn/2)).
LogProb reachProbability(const Design& d, const LogProb& q);
/// reachProbability at N p = np with the linearisation (the thesis' curves, Figures 4.1 and 5.1).
LogProb errorRate(const Design& d, double np);

/// Smallest odd m <= maxM with errorRate(MPE(m), np) < 1 / pixels: fewer than one overestimated
/// pixel expected in an image of `pixels` pixels (section 4.1.4). 0 when none. Even m are skipped:
/// with ceil(m/2) = m/2 an even m is always worse than m - 1 (e.g. 16 buffers: 1.9e-6 >
/// 15: 1.6e-6).
int smallestBuffers(double np, double pixels, int maxM = 101);
/// Smallest odd square window k x k (k <= maxK) with errorRate({method, m, k*k}, np) < 1 / pixels,
/// for MPEMIF, DMF3 or MIF. 0 when none.
int smallestWindow(Method method, int m, double np, double pixels, int maxK = 31);

/// Section 5.3.1: the minimum sample count N so that a sample of probability p reaches the final
/// pixel with probability >= certainty (the miss probability 1 - P <= 1 - certainty).
struct SppPlan {
    double np = 0.0;        ///< smallest N p meeting the certainty (linearised model)
    double sppLinear = 0;   ///< ceil(np / p): the thesis' reading of its curves
    double sppExact = 0;    ///< smallest N with the exact unit probability 1 - (1 - p)^(N/m)
    bool feasible = false;  ///< false when no N can reach the certainty (or p <= 0)
};
SppPlan minimumSpp(const Design& d, double p, double certainty);

}  // namespace mcstat::planner
