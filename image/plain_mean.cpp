// The plain mean of a statistics image: the "mean" estimator's result (plainMean, what MIF filters
// over a statistics file and what the residuals are taken against) and the stored beauty part
// (beautyImage).
#include "mcstat/image/imageops.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ROI;
using OIIO::TypeDesc;

namespace {

template <class Source>
bool plainMeanOf(ImageBuf& dst, Source& src, const std::array<double, 3>& luma, ROI roi,
                 int nthreads) {
    const Operation& mean = *findOperation("mean");
    return estimate(dst, src, mean, mean.bindPixel(ParamValues(), luma), false, roi, nthreads);
}

}  // namespace

bool plainMean(ImageBuf& dst, const StatsImage& src, const std::array<double, 3>& luma, ROI roi,
               int nthreads) {
    return plainMeanOf(dst, src, luma, roi, nthreads);
}

bool plainMean(ImageBuf& dst, StatsBlockSource& src, const std::array<double, 3>& luma, ROI roi,
               int nthreads) {
    return plainMeanOf(dst, src, luma, roi, nthreads);
}

ImageBuf beautyImage(const StatsImage& src) {
    const StatsHeader& h = src.header;
    ImageBuf dst(floatSpec(dataWindowROI(h), {"R", "G", "B"}, {}, h.colorSpace));
    if (src.beauty.size() == src.pixelCount() * 3)
        dst.set_pixels(dst.roi(), TypeDesc::FLOAT, src.beauty.data());
    else
        dst.errorfmt("statistics image has no beauty part");
    return dst;
}

}  // namespace mcstat
