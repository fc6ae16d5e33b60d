// Private to the image layer: the parallel loop both window passes (window_filter_image.cpp over
// an image, window_filter_buffers.cpp over sub-buffers) fill their result with.
#pragma once

#include <OpenImageIO/imagebufalgo_util.h>

#include <memory>
#include <vector>

#include "mcstat/filters/aov_weights.h"
#include "mcstat/filters/operation.h"

namespace mcstat::detail {

/// Fills `dst` (an RGB float image already reset to `roi`, then `A` AOV channels) in parallel with
/// a window kernel's pass: image pixel (x, y) is the pass's pixel (x - ox, y - oy). Every chunk of
/// work has its own scratch, so threads share nothing. With A > 0 the pass leaves its weighted
/// elements in the scratch (WindowScratch::wantWeights) and `aovOf(scratch, element, buffer)`
/// points at an element's A values, to which those weights are applied (docs/aovs.md).
template <class AovOf>
void fillFiltered(OIIO::ImageBuf& dst, OIIO::ROI roi, int nthreads, size_t A,
                  const AovClass* classes, const WindowPass& pass, int ox, int oy, AovOf aovOf) {
    float* const base = static_cast<float*>(dst.localpixels());
    const size_t nch = 3 + A;
    OIIO::ImageBufAlgo::parallel_image(roi, nthreads, [&](OIIO::ROI r) {
        const std::unique_ptr<WindowScratch> scratch = pass.newScratch();
        scratch->wantWeights = A > 0;
        PixelEstimate e;
        AovScratch as;
        std::vector<double> w;
        std::vector<float> values;
        for (int y = r.ybegin; y < r.yend; ++y)
            for (int x = r.xbegin; x < r.xend; ++x) {
                pass.filterPixel(x - ox, y - oy, e, *scratch);
                float* px =
                    base +
                    (size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin)) * nch;
                px[0] = e.rgb[0];
                px[1] = e.rgb[1];
                px[2] = e.rgb[2];
                if (A == 0) continue;
                w.clear();
                values.clear();
                for (const auto& el : scratch->weights) {
                    w.push_back(el.weight);
                    const float* v = aovOf(*scratch, el.element, el.buffer);
                    values.insert(values.end(), v, v + A);
                }
                applyAovWeights(w.data(), w.size(), values.data(), A, classes, px + 3, as);
            }
    });
}

}  // namespace mcstat::detail
