// Myriad (Jung 2016, eq. 4.7) over one pixel's sub-buffer means: an M-estimator of location whose
// scale gamma moves it from the mode (small) to the mean (large).
// Jung, "Rendering of Teeth and Dental Restorations using Robust Statistical Estimation
// Techniques", PhD thesis, University of Minnesota, 2016, section 4.1.3 (M-estimators) and
// section 4.2 (scale 0.05 x input range, luminance-driven selection). Rules: myriad.h. The
// default scale is the range within Hampel's fence, not the whole range (ScaleRule).
#include "mcstat/filters/pixel/myriad.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "distinct_values.h"

namespace mcstat {

using detail::clearlyLess;
using detail::saneScale;

namespace {

/// log1p(t^2) for t = |d| / scale >= 0, without overflow: for huge t it is 2 log t.
double logSquareTerm(double d, double scale) {
    const double ad = std::fabs(d);
    const double t = ad / scale;
    if (t < 1e150) return std::log1p(t * t);
    return 2.0 * (std::log(ad) - std::log(scale));
}

/// Majorise-minimise (fixed-point) iteration for eq. 4.7 from `beta`: log is concave, so
/// log(g^2 + d^2) <= log(a) + (g^2 + d^2 - a) / a, and minimising that quadratic bound gives the
/// weighted mean with weights w_j k_j, k_j = 1 / (1 + (d_j / g)^2); that step never increases the
/// cost. Its convergence is linear, so once the steps are small (< 0.01 gamma) and the cost is
/// convex there (f'' > 0), Newton steps finish quadratically; a Newton step longer than 8 MM steps
/// or leaving [x_0, x_{K-1}] is replaced by the MM step.
///
/// myriadVisit runs that iteration for eight windows at a time (GCC vector extension, 2 x 4
/// doubles): lane l runs exactly the scalar loop (as first written) from its window's sample; each
/// lane's operations are the scalar ones in the same order (the terms, their sums over j in index
/// order, the step choice, the clamp, the stopping tests and the 2000-iteration cap), IEEE
/// operations that round the same in any width (no FMA in either clone). A descent is a chain of
/// dependent additions and divisions, so one descent leaves the CPU mostly waiting; eight
/// interleaved keep its dividers busy (on the benchmark image a pixel runs ~13 descents, ~300
/// steps). A lane that stops hands its result over and takes the next window.
///
/// The results are then used exactly as the scalar visit in myriadSorted used them: in the
/// windows' order, each window's bound tested against the best cost of the windows before it
/// (clearlyLess(bestCost, bound): stop), then its cost and the choice of the best. Descents of
/// windows after that stop were computed ahead and are not used: the scalar visit would not have
/// run them.
__attribute__((target_clones("avx2", "default"))) double myriadVisit(
    const double* x, const double* w, int K, double gamma, const std::pair<double, int>* windows,
    int nw) {
    // Two halves of four lanes: 32-byte vectors are AVX2 registers (SSE2 pairs in the default
    // clone); lane l is half l / 4, element l % 4.
    typedef double V __attribute__((vector_size(32)));
    typedef long long VI __attribute__((vector_size(32)));
    thread_local std::vector<double> result;
    thread_local std::vector<unsigned char> ready;
    result.assign(size_t(nw), 0.0);
    ready.assign(size_t(nw), 0);
    V beta[2] = {};
    VI active[2] = {};
    int win[8] = {}, iters[8] = {};
    int assigned = 0, visited = 0;
    double best = x[0], bestCost = std::numeric_limits<double>::infinity();
    const double lo = x[0], hi = x[K - 1];
    const VI absMask = VI{} + 0x7fffffffffffffffll;  // |v| clears the sign bit
    const double nearStep = 0.01 * gamma, tiny = 1e-10 * gamma;
    const double ulp2 = 2.0 * std::numeric_limits<double>::epsilon();
    for (;;) {
        for (int l = 0; l < 8; ++l)
            if (!active[l / 4][l % 4] && assigned < nw) {
                win[l] = assigned;
                beta[l / 4][l % 4] = x[windows[assigned].second];
                active[l / 4][l % 4] = -1;
                iters[l] = 0;
                ++assigned;
            }
        // One step of every active lane (the body of the scalar loop).
        V grad[2] = {}, mm[2] = {}, curv[2] = {};  // sums of w k t, w k, w (1 - t^2) k^2
        for (int j = 0; j < K; ++j) {
            const double xj = x[j], wj = w[j];
            for (int h = 0; h < 2; ++h) {
                const V t = (xj - beta[h]) / gamma;
                const V k = 1.0 / (1.0 + t * t);  // t = inf gives 0: a far sample has no pull
                grad[h] += wj * k * t;
                mm[h] += wj * k;
                curv[h] += wj * (1.0 - t * t) * k * k;
            }
        }
        VI still[2];
        for (int h = 0; h < 2; ++h) {
            const VI ok = mm[h] > 0.0;  // else the scalar loop stops with beta unchanged
            // Step forms (beta + weighted mean of the offsets): exact at the fixed point.
            const V stepMM = gamma * (grad[h] / mm[h]);
            const V stepNewton = gamma * (grad[h] / curv[h]);
            const V absMM = (V)((VI)stepMM & absMask);
            const VI newton = (absMM < nearStep) & (curv[h] > 0.0) &
                              ((V)((VI)stepNewton & absMask) <= 8.0 * absMM) &
                              (beta[h] + stepNewton >= lo) & (beta[h] + stepNewton <= hi);
            const V step = newton ? stepNewton : stepMM;
            const V moved0 = beta[h] + step;
            const V next =
                moved0 < lo ? V{} + lo : (hi < moved0 ? V{} + hi : moved0);  // std::clamp
            const V moved = (V)((VI)(next - beta[h]) & absMask);
            const VI update = active[h] & ok;
            beta[h] = update ? next : beta[h];
            const VI stop = (moved <= tiny) | (moved <= ulp2 * (V)((VI)next & absMask));
            still[h] = update & ~stop;
        }
        for (int l = 0; l < 8; ++l) {
            if (!active[l / 4][l % 4]) continue;
            if (still[l / 4][l % 4] && ++iters[l] < 2000) continue;
            active[l / 4][l % 4] = 0;  // this descent is over: its result is beta
            result[size_t(win[l])] = beta[l / 4][l % 4];
            ready[size_t(win[l])] = 1;
        }
        // The scalar visit, as far as the results allow.
        while (visited < nw) {
            if (clearlyLess(bestCost, windows[visited].first)) return best;
            if (!ready[size_t(visited)]) break;
            const double b = result[size_t(visited)];
            const double c = myriadCost(x, w, K, gamma, b);
            if (std::isinf(bestCost) || clearlyLess(c, bestCost) ||
                (!clearlyLess(bestCost, c) && b < best)) {
                best = b;
                bestCost = c;
            }
            ++visited;
        }
        if (visited == nw) return best;
    }
}
}  // namespace

double myriadCost(const double* x, const double* w, int K, double gamma, double beta) {
    gamma = saneScale(gamma);
    double c = 0.0;
    for (int j = 0; j < K; ++j) c += w[j] * logSquareTerm(x[j] - beta, gamma);
    return c;
}

double myriadSorted(const double* x, const double* w, int K, double gamma) {
    if (K <= 0) return 0.0;
    if (K == 1) return x[0];
    gamma = saneScale(gamma);
    // Every local minimum lies within gamma of a sample (see the header), so the global one lies in
    // some window W_i = [x_i - gamma, x_i + gamma]. A lower bound of the cost on W_i replaces each
    // |x_j - beta| by its smallest value on W_i. Windows are visited by increasing bound, the
    // descent runs from x_i, and once a bound reaches the best cost found no later window can hold
    // a better minimum: they are skipped (this keeps the cost near one descent per pixel).
    thread_local std::vector<std::pair<double, int>> windows;
    windows.clear();
    // The bound's terms are symmetric in (i, j) (|x_j - x_i| is exactly |x_i - x_j|), and zero
    // (log1p(0), and w * 0 adds nothing to a sum >= +0) within gamma: each log is taken once, for
    // i < j, and the sums still run over j in index order, as before.
    thread_local std::vector<double> term;
    term.assign(size_t(K) * size_t(K), 0.0);
    for (int i = 0; i < K; ++i)
        for (int j = i + 1; j < K; ++j) {
            const double d = std::max(0.0, std::fabs(x[j] - x[i]) - gamma);
            if (d == 0.0) continue;
            const double v = logSquareTerm(d, gamma);
            term[size_t(i) * size_t(K) + size_t(j)] = v;
            term[size_t(j) * size_t(K) + size_t(i)] = v;
        }
    for (int i = 0; i < K; ++i) {
        double bound = 0.0;
        const double* ti = term.data() + size_t(i) * size_t(K);
        for (int j = 0; j < K; ++j) bound += w[j] * ti[j];
        windows.emplace_back(bound, i);
    }
    std::sort(windows.begin(), windows.end());
    return myriadVisit(x, w, K, gamma, windows.data(), int(windows.size()));
}

void estimateMyriad(const PixelBuffers& px, const MyriadParams& p, PixelEstimate& out,
                    EstimatorScratch& s) {
    const bool lum = p.mode == EstimatorMode::Luminance;
    detail::estimateLocation(px, p, p.gamma, out, s, [&](int ch, int K, double gamma) {
        const double beta = myriadSorted(s.sorted.data(), s.weight.data(), K, gamma);
        int kept = 0;
        double sum[3] = {0.0, 0.0, 0.0}, wsum = 0.0;
        for (int j : s.order) {
            // Final fixed-point weights k_j = gamma^2 / (gamma^2 + d^2); all 1 when K == 1.
            const double t = K == 1 ? 0.0 : (s.key[j] - beta) / saneScale(gamma);
            const double k = 1.0 / (1.0 + t * t);
            if (k >= 0.5) ++kept;
            if (lum) {
                const double nk = double(px.count[j]) * k;
                wsum += nk;
                for (int c = 0; c < 3; ++c) sum[c] += nk * double(px.mean[3 * j + c]);
            }
        }
        if (!lum) {
            out.rgb[ch] = float(beta);
            out.kept[ch] = kept;
            return;
        }
        if (wsum > 0.0) {
            for (int c = 0; c < 3; ++c) out.rgb[c] = float(sum[c] / wsum);
        } else {  // every weight underflowed (cannot happen for beta at a sample): nearest buffer
            const int j = s.order[0];
            for (int c = 0; c < 3; ++c) out.rgb[c] = px.mean[3 * j + c];
        }
        if (s.wantWeights) {
            // The final weights n_j k_j / sum n k (or the one buffer used above).
            s.bufferWeight.assign(size_t(px.M), 0.0);
            for (int j : s.order) {
                const double t = K == 1 ? 0.0 : (s.key[j] - beta) / saneScale(gamma);
                const double k = 1.0 / (1.0 + t * t);
                const double nk = double(px.count[j]) * k;
                if (wsum > 0.0) s.bufferWeight[size_t(j)] = nk / wsum;
            }
            if (!(wsum > 0.0)) s.bufferWeight[size_t(s.order[0])] = 1.0;
        }
        out.kept.fill(kept);
    });
}

namespace {

PixelKernel bindMyriad(const ParamValues& values, const std::array<double, 3>& luma) {
    auto p = pixelParamsAs<MyriadParams>(values, luma);
    p.gamma = values.at("gamma").real;
    p.scale = scaleRule(values);
    return pixelKernel(p, &estimateMyriad, /*smallestRobustM=*/2);
}

}  // namespace

ParamSpec scaleParam() {
    return enumParam("scale", {"hampel", "rel", "abs"}, "hampel",
                     "hampel: gamma/delta is a factor of the range of the buffers within Hampel's "
                     "fence |x - median| <= 3 x 1.4826 x MAD (one outlying buffer cannot set it); "
                     "rel: of the whole range max - min (Jung 2016 section 4.2, the thesis' form); "
                     "abs: an absolute value",
                     {{"robust", "hampel"}, {"relative", "rel"}, {"absolute", "abs"}});
}

ScaleRule scaleRule(const ParamValues& values) {
    const std::string& v = values.at("scale").text;
    return v == "rel" ? ScaleRule::Range : v == "abs" ? ScaleRule::Absolute : ScaleRule::Hampel;
}

Operation myriadOperation() {
    return pixelOperation(
        "myriad", "myriad",
        "Myriad (Jung eq. 4.7): argmin sum n_j log(gamma^2 + (x_j - b)^2), global minimum",
        "Jung eq. 4.7",
        {modeParam(),
         realParam("gamma", 0.0, HUGE_VAL, true, "0.05",
                   "scale (small: mode-like, large: the mean)"),
         scaleParam()},
        &bindMyriad);
}

}  // namespace mcstat
