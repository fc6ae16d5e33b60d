// The relative width of the confidence interval per pixel (intervalWidthImage, imageops.h), the
// channel --heatmap:channel=ciwidth draws.
#include <cmath>

#include "mcstat/image/imageops.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ImageSpec;

bool intervalWidthImage(ImageBuf& dst, const ImageBuf& src) {
    const ImageSpec& in = src.spec();
    int lo[3], hi[3], est[3];
    for (int c = 0; c < 3; ++c) {
        const std::string n(1, "RGB"[c]);
        est[c] = in.channelindex(n);
        lo[c] = in.channelindex(kCiLowPrefix + n);
        hi[c] = in.channelindex(kCiHighPrefix + n);
        if (est[c] < 0 || lo[c] < 0 || hi[c] < 0) {
            dst.errorfmt("the image has no channel {}{} (an estimator's result with :ci=LEVEL)",
                         est[c] < 0  ? ""
                         : lo[c] < 0 ? kCiLowPrefix
                                     : kCiHighPrefix,
                         n);
            return false;
        }
    }
    ImageSpec spec = floatSpec(src.roi(), {kCiWidthChannel}, src.roi_full());
    spec.extra_attribs = in.extra_attribs;  // provenance: the heatmap's caption
    dst.reset(spec);
    std::vector<float> px(size_t(in.nchannels));
    for (OIIO::ImageBuf::Iterator<float> it(dst); !it.done(); ++it) {
        src.getpixel(it.x(), it.y(), px.data(), in.nchannels);
        double width = 0.0, value = 0.0;
        for (int c = 0; c < 3; ++c) {
            width += double(px[size_t(hi[c])]) - double(px[size_t(lo[c])]);
            value += std::fabs(double(px[size_t(est[c])]));
        }
        it[0] = float(width == 0.0 ? 0.0 : value > 0.0 ? width / value : HUGE_VAL);
        if (std::isnan(width)) it[0] = NAN;
    }
    return true;
}

}  // namespace mcstat
