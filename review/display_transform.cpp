// The display transform of review pictures (displayTransform, display.h): R, G, B through the
// active OCIO config's default display and view, in the pixels' own working space.
#include <OpenImageIO/imagebufalgo.h>

#include "mcstat/color/color.h"
#include "mcstat/image/spec/image_spec.h"
#include "mcstat/review/display.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ROI;
using OIIO::TypeDesc;

bool displayTransform(ImageBuf& dst, const ImageBuf& src, ROI roi, int nthreads) {
    if (!roi.defined()) roi = src.roi();
    if (src.nchannels() < 3) {
        dst.errorfmt("display transform needs R, G, B channels; the image has {}", src.nchannels());
        return false;
    }
    ImageBuf out(floatSpec(roi, {"R", "G", "B"}));
    if (!OIIO::ImageBufAlgo::copy(out, src, TypeDesc::FLOAT,
                                  ROI(roi.xbegin, roi.xend, roi.ybegin, roi.yend, 0, 1, 0, 3),
                                  nthreads)) {
        dst.errorfmt("{}", out.geterror());
        return false;
    }
    std::string err;
    auto* pixels = static_cast<float*>(out.localpixels());
    // The pixels' working space (docs/color.md): an ACEScg result is not shown as Rec.709.
    const std::string space = src.spec().get_string_attribute("oiio:ColorSpace");
    if (!applyDisplayTransform(pixels, long(roi.npixels()), err, "", "", space)) {
        dst.errorfmt("{}", err);
        return false;
    }
    dst = std::move(out);
    return true;
}

ImageBuf displayTransform(const ImageBuf& src, ROI roi, int nthreads) {
    ImageBuf dst;
    displayTransform(dst, src, roi, nthreads);
    return dst;
}

}  // namespace mcstat
