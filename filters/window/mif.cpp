// Jung's (weighted) median image filter MIF / WMIF (thesis eq. 5.6-5.8, weights eq. 5.28) over an
// RGB image, and its registry entries `mif` and `wmif` (mif.h).
#include "mcstat/filters/window/mif.h"

#include <algorithm>
#include <cmath>

#include "mcstat/filters/window/window_kernel.h"

namespace mcstat {

void wmifPixel(const RGBImageView& img, int x, int y, const SpatialParams& p, PixelEstimate& out,
               SpatialScratch& s) {
    // Window clipped to the image (the thesis does not treat borders).
    const int rx = p.windowWidth / 2, ry = p.windowHeight / 2;
    const int x0 = std::max(0, x - rx), x1 = std::min(img.width - 1, x + rx);
    const int y0 = std::max(0, y - ry), y1 = std::min(img.height - 1, y + ry);
    s.elems.clear();
    s.source.clear();
    out.excluded = 0;
    for (int yy = y0; yy <= y1; ++yy)
        for (int xx = x0; xx <= x1; ++xx) {
            const float* v = img.rgb + (size_t(yy) * size_t(img.width) + size_t(xx)) * 3;
            if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2])) {
                ++out.excluded;
                continue;
            }
            // eq. 5.28: w_c at the centre, 1 elsewhere
            s.elems.push_back({v, 1.0, (xx == x && yy == y) ? p.centreWeight : int64_t(1)});
            if (s.wantWeights) s.source.emplace_back(xx, yy);
        }
    weightedTrimmedMean(s.elems.data(), int(s.elems.size()), p, out, s);
}

void wmifImage(const RGBImageView& img, const SpatialParams& p, float* out) {
    SpatialScratch s;
    PixelEstimate e;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            wmifPixel(img, x, y, p, e, s);
            float* o = out + (size_t(y) * size_t(img.width) + size_t(x)) * 3;
            o[0] = e.rgb[0];
            o[1] = e.rgb[1];
            o[2] = e.rgb[2];
        }
}

namespace {

WindowKernel bindImageWindow(const ParamValues& values, const std::array<double, 3>& luma) {
    return windowKernel(Neighbourhood::Image, spatialParams(values, luma));
}

}  // namespace

Operation mifOperation() {
    return windowOperation("mif", "MIF",
                           "Median image filter MIF(k x l) of the top image (Jung eq. 5.8); after "
                           "--median: MPE+MIF (eq. 5.15)",
                           "Jung eq. 5.8", Neighbourhood::Image,
                           {windowSizeParam(), centreWeightParam("1", true),
                            breakdownParam("0.5", true), windowModeParam()},
                           &bindImageWindow);
}

Operation wmifOperation() {
    return windowOperation("wmif", "WMIF",
                           "Weighted median image filter WMIF(w, k x l) of the top image, centre "
                           "weight w (eq. 5.6, 5.28); after --tmpe: TMPE+WMIF (eq. 5.14)",
                           "Jung eq. 5.6, 5.28", Neighbourhood::Image,
                           {windowSizeParam(), centreWeightParam("3", false),
                            breakdownParam("0.5", true), windowModeParam()},
                           &bindImageWindow);
}

}  // namespace mcstat
