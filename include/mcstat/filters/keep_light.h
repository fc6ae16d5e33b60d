// Robust images that keep their light (issue 49, docs/keep-light.md): a robust estimate R removes
// light with the fireflies; the residual r = mean - R (per channel and per AOV) is all of it. This
// module gives every pixel's residual back, all of it, spread by a kernel that sums to 1, at a
// scale the data choose pixel by pixel. Pure functions over planar arrays, no I/O, no OIIO types.
//
// The scale: the residual's expectation is the robust estimator's bias b (the mean is unbiased),
// a smooth field over a surface lit by rare paths (fireflies everywhere: b is small and even) and
// a sharp one where a caustic lies (b large, in a region). Where it goes back should be an
// estimate of b, as local as the evidence allows. That is the adaptive window choice of the
// intersection of confidence intervals (ICI; Goldenshluger and Nemirovski 1997, Katkovnik 1999):
// for windows of radii r_0 < r_1 < ... around p, the window's mean of d (the luminance residual)
// is an estimate of b with standard error sigma_k = sqrt(sum se^2) / n_k (se: the plain mean's
// standard error, filters/removed_light.h, which bounds the residual's: Hausman 1978); the
// intervals [mean_k - gamma sigma_k, mean_k + gamma sigma_k] are intersected from the smallest
// window up, and p's radius is the largest r_k whose intersection is not empty. A lone firefly
// (d = se, its neighbours 0) never contradicts a wider window: its light goes wide, over the
// image's surfaces. A caustic's pixels agree with each other and not with the dark beyond, so the
// intersection empties once the window passes the caustic's edge: its light stays in it.
//
// The return conserves energy exactly (up to float summation): pixel p's residual goes to the
// pixels of its window with the weights of a tent (pyramid) of p's radius, (r + 1 - |dx|)
// (r + 1 - |dy|), divided by the sum of the weights that fall inside the image, so they sum to 1
// (a box would leave its square's edges in the image). The tent is symmetric and separable, so
// the receiving side is a gather of two direct 1D sums (rows, then columns; never a running sum,
// whose subtractions would leave a firefly's rounding in the dark beyond it): identical for any
// thread count. A pixel that no nonzero residual reaches is the robust estimate bit for bit.
//
// ICI alone cannot keep a small caustic close: with n pixels of removed light d each with se = d
// (z = 1, the light in one or two of M = 9 buffers), every window's mean is n d / area with
// standard error sqrt(n) d / area, so all intervals hold 0 while sqrt(n) < gamma and the light
// spreads to the largest radius. The pooled 3 x 3 test (KeepLightParams::supportZ) catches such a
// cluster. Gamma and the radius were chosen on the fixture's firefly scenes and on Blender Cycles
// renders together (docs/keep-light.md, "The scale's two settings"); supportZ on the fixture's
// caustic and default scenes.
//
// One case wants no spread at all. At the edge of a bright surface (an emitter, a lit highlight,
// a defocused one) a pixel that the surface covers in part sees it in a few of its samples, and
// a robust estimator takes them for fireflies: the plain mean is the right value there, and the
// robust one is far too dark. Its neighbours tell: where the median of the 3 x 3 window's robust
// luminance lies nearer the pixel's mean than its robust value, the pixel keeps its light (radius
// 0: it is its plain mean). A firefly's neighbours are its surface's robust values, which lie
// near its own robust value; a firefly beside an emitter's straight edge has the emitter in three
// of its nine, not the median. (In an emitter's inside corner, five of nine, it would keep its
// light: a corner's pixel is rare, and its light stays where the mean put it.)
//
// A supported cluster's light is not all signal. Its 3 x 3 test's statistic Z = sum d /
// sqrt(sum se^2) says how much: of a sum whose noise has variance sum se^2, the share
// 1 - 1 / Z^2 is the Wiener estimate of the signal's. Kept within a pixel, the rest is the
// cluster's luck (at 64 spp a thin caustic's events put twice the reference in one pixel and a
// third of it on the dark rows beside the line). So a pixel that the support test capped at
// radius 1 where ICI's own choice was wider keeps the share 1 - (supportZ / Z)^2 there (0 at the
// test's threshold: the rule is continuous) and sends the rest to ICI's own radius, by the light
// guide: where the plain mean says light is (its luminance), a pixel counting for no more than its
// brightest neighbour's, so that a lone firefly, whose mean is not its surface's light, draws no
// more than its surface, while a caustic's pixels and lines, whose neighbours are as bright, draw
// their own. The rest stays on the caustic where ICI's window is small (a resolved caustic, real
// renders) and spreads over the lit surfaces where it is wide (a caustic of a few sparse events).
//
// A window of a few pixels (radius 2 to KeepLightParams::biasRadius) has seen the bias change
// around it: ICI stopped there because a caustic ends. By the albedo alone its tent reaches past
// the caustic's edge onto the dark beside it. Its light goes instead by the bias guide: each
// receiver's own estimate of the bias (ICI's window mean at its own radius) where a surface was
// hit, plus a floor that follows the surface (the albedo times the largest window's mean
// residual). Wider windows keep the albedo: they saw no edge, and the receivers' estimates at
// their scale are a few events' noise (on real renders, a caustic's focus would draw the light
// of the whole floor around it).
//
// A pixel's neighbours can say that its light is there when its own robust value does not: the
// edge of a defocused light whose pixels along the edge all lost their light (no robust value
// near holds it, so the edge test above cannot tell). Their plain means do hold it. So a pixel
// that no rule keeps close keeps in place part of the gap between the median of its 8
// neighbours' plain means and its robust value (KeepLightParams::neighbourShare: half; the
// median is noisy too), at most its own residual. A lone firefly's neighbours lie at its
// surface's level, its robust value: it keeps nothing, and its light goes wide as before.
//
// Last, a pixel's own light stays in place: a gain (the robust value above the mean: no
// firefly inflated that mean, nothing was removed, and spread it would darken other pixels, below
// 0 beside a light whose edge a mode-seeking estimator filled), and a loss beyond ownZ of the
// pixel's own standard errors (d > ownZ se, 2.5): its own buffers hold that light, whatever an
// estimator made of it. A 3D filter, which estimates a pixel from its neighbours' buffers too,
// leaves one at the edge of a small bright emitter: it takes the emitter's light to the dark
// pixels beside it. A per-pixel estimator leaves one where many of its buffers hold a light's
// samples and its robust value took a dark one (the median of 21 buffers of one sample each, 10
// of them on a light); with M = 9 and a few fireflies its d / se stays under 1.8. So only light
// that was removed moves, and no pixel's luminance ends below the smaller of its robust value's
// and its plain mean's.
#pragma once

#include <cstdint>
#include <vector>

namespace mcstat {

/// The scale choice's parameters.
struct KeepLightParams {
    double gamma = 4.0;  ///< ICI threshold: the intervals' half width in standard errors
    int maxRadius = 64;  ///< the largest window radius (the radii are 0, 1, 2, 4, ... up to it)
    /// A pixel whose 3 x 3 neighbourhood's removed light is significant together, sum d /
    /// sqrt(sum se^2) >= supportZ (removed_light.h's pooled test), keeps at most radius 1: a
    /// caustic of a few pixels, each of which alone looks like a firefly (z about 1: with M = 9
    /// its light is in one or two buffers), whose intervals ICI cannot tell from fireflies'.
    double supportZ = 2.0;
    /// Rule 7: a window of radius 2 to biasRadius (0: none) sends its light in proportion to
    /// the receivers' bias guide (keepLightBiasGuide) instead of the albedo alone, so that a
    /// caustic's light stays on the caustic and off the dark beside it. Wider windows keep the
    /// albedo: what they saw has no structure at their scale, and the receivers' estimates there
    /// are a few events' noise (docs/keep-light.md, rule 7).
    int biasRadius = 16;
    /// The bias guide's floor: biasFloor x albedo x the mean residual over the largest window,
    /// the share of the light that follows the surface alone where no bias is estimated.
    double biasFloor = 4.0;
    /// Rule 8: a pixel that no other rule keeps close (not supported, not kept by the edge test)
    /// keeps in place min(d, neighbourShare x (L - robust)) of its light, L the median of its 8
    /// neighbours' plain means (neighbourShare 0: the rule is off): light its neighbours' means
    /// say is there (a defocused edge whose neighbours along it lost their light too). A lone
    /// firefly's neighbours lie at its surface's level, which is its robust value: it keeps
    /// nothing. Half the gap because the neighbours' median is noisy too (docs/keep-light.md,
    /// rule 8).
    double neighbourShare = 0.5;
    /// Rule 9: a pixel whose loss alone lies beyond ownZ of its own standard errors, d > ownZ
    /// se, keeps it in place (its buffers hold that light), as every gain (d < 0). 2.5: no G-MoN
    /// or TMPE pixel of the fixture's M = 9 renders reaches 1.8, and a lone firefly's d / se is
    /// about 1 for any M; at 2 the 3D filters' caustic lost 15 % (docs/keep-light.md, rule 9).
    double ownZ = 2.5;
};

/// The window radii the choice considers: 0, 1, 2, 4, ..., each doubling, the last maxRadius.
std::vector<int> keepLightRadii(int maxRadius);

/// ICI's choice per pixel over a width x height image (row-major): scale[p] is the index into
/// keepLightRadii(params.maxRadius) of p's window. `d` is the luminance residual, `se` the plain
/// mean's standard error; non-finite values count as 0. The window sums are direct (no
/// summed-area table): a firefly of 1e38 changes no other window's sum. With `robustY` (the
/// robust estimate's luminance; null: no such test), a pixel whose 3 x 3 window's median of it
/// lies nearer the pixel's mean (robustY + d) than its robust value gets scale 0 (the edge of a
/// bright surface, above; beyond the image the window takes the nearest pixel inside it);
/// non-finite values of robustY take no part in the median, and a pixel whose own robustY or d
/// is not finite is not tested. A pixel whose own d is a gain (d < 0) or lies beyond ownZ of its
/// se (d > ownZ se; se 0: d > 0; both finite) gets scale 0 too: the pixel's own light (rule 9).
/// Only pixels with active[p] != 0 are decided (the others get 0): the rest carry no residual.
/// Deterministic, any thread count.
///
/// With restScale and restShare (both or neither; null: every pixel sends all of its light at
/// scale[p], and rule 8 does not apply), p sends the share restShare[p] of its residual at
/// scale[p] and the rest at restScale[p]:
/// - a supported cluster's pixel (the 3 x 3 test's Z >= supportZ capped its scale at radius 1,
///   where ICI chose a wider one, and the edge test did not keep it): restShare[p] =
///   1 - (supportZ / Z)^2, restScale[p] ICI's own choice (rule 6);
/// - a pixel that neither the support test nor the edge test kept close, with d > 0, whose 8
///   neighbours' median plain mean L (robustY + d; finite values, beyond the image the nearest
///   pixel inside it) lies above its robust value: restShare[p] = 1 - min(d, neighbourShare x
///   (L - robustY)) / d, restScale[p] = 0, the rest kept in place (rule 8);
/// - every other pixel: restShare[p] = 1 and restScale[p] = scale[p].
///
/// With bias and level (both or neither; rule 7's inputs to keepLightBiasGuide), every pixel,
/// active or not, gets bias[p] = max(0, the mean of d over the window ICI chose for it, before
/// the support test and the edge test cap it: its estimate of the bias at its own scale) and
/// level[p] = max(0, the mean of d over its window of the largest radius).
void keepLightScales(const float* d, const float* se, const float* robustY, const uint8_t* active,
                     int width, int height, const KeepLightParams& params, uint8_t* scale,
                     int nthreads = 0, uint8_t* restScale = nullptr, float* restShare = nullptr,
                     float* bias = nullptr, float* level = nullptr);

/// Adds every pixel's residual back with its tent of radius radii[scale[p]]: for each channel c
/// of `nch` interleaved channels, out[q][c] = robust[q][c] + sum over p within that radius of q of
/// residual[p][c] t(q - p) / (sum of t over p's window inside the image), t the tent's weight.
/// Residuals that are not finite are not returned (the pixel keeps the robust value there). A
/// channel of a pixel that no nonzero residual reaches is robust[q][c] bit for bit. `out` may be
/// `robust`. Deterministic, any thread count.
///
/// With `guide` (one value >= 0 per pixel, e.g. the albedo's luminance: irradiance goes back, the
/// surface's texture multiplies it), p's light goes to q in proportion to t(q - p) guide[q], the
/// weights divided by their sum over p's window: light stays off what has no surface (guide 0:
/// the background, black surfaces) and each window still returns all of its pixel's light. A
/// window whose guide is 0 everywhere takes the tent alone.
///
/// With `clusterGuide` (keepLightClusterGuide), a window of radius 1, a supported cluster's
/// (keepLightScales), takes it instead of `guide`: the cluster's light goes where its own light
/// was found, so a thin caustic stays on its line instead of the tent's square around it. A
/// window of radius 1 whose cluster guide is 0 everywhere takes `guide`, then the tent.
///
/// With restScale and restShare (keepLightScales'; null: all at scale), p sends the share
/// restShare[p] of its residual as above and the rest at radius radii[restScale[p]], in
/// proportion to t(q - p) lightGuide[q] (keepLightLightGuide; a window whose light guide is 0
/// everywhere, or no light guide, takes the tent alone).
///
/// With `biasGuide` (keepLightBiasGuide) and biasRadius >= 2 (KeepLightParams::biasRadius), a
/// window of radius 2 to biasRadius takes it instead of `guide` (rule 7); one whose bias guide is
/// 0 everywhere takes `guide`, then the tent.
void returnResidual(const float* robust, const double* residual, const uint8_t* scale,
                    const std::vector<int>& radii, int width, int height, int nch, float* out,
                    int nthreads = 0, const float* guide = nullptr,
                    const float* clusterGuide = nullptr, const uint8_t* restScale = nullptr,
                    const float* restShare = nullptr, const float* lightGuide = nullptr,
                    const float* biasGuide = nullptr, int biasRadius = 0);

/// A channel's value with the light returned to it, as returnResidual writes it and every caller
/// of keepLightStream must: robust + add rounded once to float where add is not 0, robust bit for
/// bit where it is (a pixel no returned light reaches is untouched).
inline float withReturnedLight(float robust, double add) {
    return add != 0.0 ? float(double(robust) + add) : robust;
}

/// The guide of a supported cluster's return: at each pixel c sqrt(m + c), c the 3 x 3 tent's
/// weighted mean (weights 1 2 1 by 1 2 1, divided by their sum inside the image) of the positive
/// luminance residual max(d, 0) (non-finite d counts as 0), m the light guide there
/// (keepLightLightGuide; robustY null counts as 0); at most the largest float. c follows the
/// events the buffers put where they are dense (a caustic's line), and fills the one-pixel gaps
/// between sparse ones (a broad caustic's grain), where d itself would give each event's light
/// back to the event alone. sqrt(m + c) leans it toward the pixels whose mean holds light: at an
/// emitter's partly covered edge, the emitter, not the dark row on the other side, whose c is as
/// large (docs/keep-light.md, rule 3); the root, and c under it, so that a caustic's gaps keep
/// their share.
std::vector<float> keepLightClusterGuide(const float* robustY, const float* d, int width,
                                         int height, int nthreads = 0);

/// The guide of a supported cluster's rest (keepLightScales' restShare): at each pixel, the plain
/// mean's luminance m = robustY + d (0 where it is negative or not finite; robustY null counts as
/// 0), but at most the largest m of its 8 neighbours inside the image (0 for a lone pixel). A lone
/// firefly draws no more light than the brightest pixel beside it; a caustic's pixels, beside
/// pixels as bright, and a line of them draw their own.
std::vector<float> keepLightLightGuide(const float* robustY, const float* d, int width, int height,
                                       int nthreads = 0);

/// The guide of the windows of radius 2 to KeepLightParams::biasRadius (rule 7), per pixel:
/// bias[p] where the surface guide[p] (the albedo's luminance) is above 0, plus
/// floor x guide[p] x level[p] (keepLightScales' bias and level; a guide that is negative or not
/// finite counts as 0). Where a window's pixels estimate a bias (a caustic), its light goes to
/// them in proportion; where they estimate none, by the surface, as rule 4. Nothing goes where no
/// surface was hit.
std::vector<float> keepLightBiasGuide(const float* bias, const float* level, const float* guide,
                                      int width, int height, double floor);

}  // namespace mcstat
