// Two images' RGB compared in scene-linear and display-encoded values (diffImages, display.h;
// the measures are analysis/metrics.h's).
#include <OpenImageIO/strutil.h>

#include <vector>

#include "mcstat/color/color.h"
#include "mcstat/review/display.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ROI;
using OIIO::TypeDesc;

bool diffImages(const ImageBuf& img, const ImageBuf& ref, const DiffOptions& opt, DiffMetrics& out,
                std::string& err) {
    const ROI a = img.roi(), b = ref.roi();
    if (a.width() != b.width() || a.height() != b.height()) {
        err = OIIO::Strutil::fmt::format("image is {}x{} but the reference is {}x{}", a.width(),
                                         a.height(), b.width(), b.height());
        return false;
    }
    if (img.nchannels() < 3 || ref.nchannels() < 3) {
        err = "both images need R, G, B channels";
        return false;
    }
    const int w = a.width(), h = a.height();
    std::vector<float> lin(size_t(w) * h * 3), rlin(lin.size());
    img.get_pixels(ROI(a.xbegin, a.xend, a.ybegin, a.yend, 0, 1, 0, 3), TypeDesc::FLOAT,
                   lin.data());
    ref.get_pixels(ROI(b.xbegin, b.xend, b.ybegin, b.yend, 0, 1, 0, 3), TypeDesc::FLOAT,
                   rlin.data());
    std::vector<float> disp = lin, rdisp = rlin;
    if (!applyDisplayTransform(disp.data(), long(w) * h, err, "", "", opt.space) ||
        !applyDisplayTransform(rdisp.data(), long(w) * h, err, "", "", opt.space))
        return false;
    out = compareImages(lin.data(), rlin.data(), disp.data(), rdisp.data(), w, h, opt);
    return true;
}

}  // namespace mcstat
