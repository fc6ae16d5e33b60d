// The removed light given back by bands of rows (issue 49, docs/keep-light.md): keep_light.h's
// scale choice, cluster and light guides and return over an image that the caller hands over a band
// of rows at a time and takes back a band at a time, holding a few bands of rows whatever the
// image's height. Every step's windows reach at most the largest radius R beyond their rows, so the
// stream holds the rows from R above the first row it has not yet returned to the last row it was
// given: about a band and 3 R rows. Pure functions, no I/O, no OIIO types.
//
// Each row's scale, cluster guide and window weight sums are computed once, in the band in which
// they become computable, so that every sender's weights sum to 1 across the bands that receive
// its light: the image's sum per channel is the plain mean's up to float summation. The bands'
// boundaries depend on the band height and the radius only, never on the thread count: the same
// bits for any thread count. With one band (bandRows at least the height) the result is the
// whole-image functions' of keep_light.h bit for bit; with more, the sums' order differs in the
// last bits.
#pragma once

#include <cstdint>
#include <functional>

#include "mcstat/filters/keep_light.h"

namespace mcstat {

/// Where the caller writes the inputs of rows [y0, y1): each array holds those rows only, row y0
/// first (pixel (x, y) at (y - y0) * width + x, times nch for the residual).
struct KeepLightBandIn {
    double* residual;  ///< the residual per channel, nch per pixel (mean - robust)
    float* d;          ///< the luminance residual
    float* se;         ///< the plain mean's standard error (0 where the pixel carries nothing)
    float* robustY;    ///< the robust estimate's luminance (keepLightScales' edge test)
    uint8_t* active;   ///< 1 where the pixel carries a finite nonzero residual
    float* guide;      ///< the return's guide (>= 0), or null when the stream has none
};

/// Fills rows [y0, y1) (called in order, each row once); false stops the stream.
using KeepLightFill = std::function<bool(int y0, int y1, const KeepLightBandIn& in)>;
/// Takes the light returned to rows [y0, y1) (in order, each row once): add[(y - y0) * width *
/// nch + x * nch + c], to be added to the robust value where it is not 0 (withReturnedLight,
/// keep_light.h); false stops the stream.
using KeepLightTake = std::function<bool(int y0, int y1, const double* add)>;

/// The rows of a band when the caller names none: 2 R, at least 64, so that the halos' repeated
/// work is at most the band's own. Smaller bands hold less and repeat more (1920 x 1080, M = 21,
/// `--gmon:keeplight=1` from a file: bands of 32, 64 and 128 rows peak at 277, 338 and 390 MB,
/// `--gmon` alone at 266 MB, and take 2.99, 2.93 and 2.83 s, docs/keep-light.md).
int keepLightBandRows(const KeepLightParams& params);

/// keepLightScales with its rest (rules 6 and 8), keepLightClusterGuide, keepLightLightGuide and
/// returnResidual (with the guide when `guided`, and then rule 7's keepLightBiasGuide too, and
/// the cluster and light guides) over a width x height image of nch residual channels, by bands
/// of bandRows rows (0: keepLightBandRows). Fill is never more than a band and 2 R + 1 rows ahead
/// of take (2 R + min(biasRadius, R) when rule 7 applies: its guide comes with the scales). False
/// when fill or take returned false.
bool keepLightStream(int width, int height, int nch, bool guided, const KeepLightParams& params,
                     const KeepLightFill& fill, const KeepLightTake& take, int nthreads = 0,
                     int bandRows = 0);

}  // namespace mcstat
