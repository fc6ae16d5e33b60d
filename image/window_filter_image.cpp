// A window operation over an image (Neighbourhood::Image: MIF, WMIF; windowFilter over an ImageBuf,
// imageops.h), with the AOVs an estimator's result carries weighted as the beauty's window pixels.
#include <OpenImageIO/strutil.h>

#include <memory>

#include "mcstat/image/imageops.h"
#include "window_fill.h"

namespace mcstat {

using detail::fillFiltered;
using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;
using OIIO::TypeDesc;

namespace {

/// The AOV channels an image carries (setAovAttributes), or false when it carries none.
bool imageAovs(const ImageSpec& spec, int& first, std::vector<AovClass>& classes) {
    first = spec.get_int_attribute(kAttrFirstAov, -1);
    const std::string text = spec.get_string_attribute(kAttrAovClasses);
    classes.clear();
    for (const std::string& t : OIIO::Strutil::splits(text, ",")) {
        AovClass c;
        if (!parseAovClass(t, c)) return false;
        classes.push_back(c);
    }
    return first >= 3 && !classes.empty() &&
           size_t(first) + classes.size() == size_t(spec.nchannels);
}

/// Float RGB destination for `roi` with the full (display) window `full`.
ImageSpec rgbSpec(ROI roi, ROI full, const std::string& colorSpace) {
    return floatSpec(roi, {"R", "G", "B"}, full, colorSpace);
}

}  // namespace

bool windowFilter(ImageBuf& dst, const ImageBuf& src, const WindowKernel& kernel, ROI roi,
                  int nthreads) {
    if (kernel.over != Neighbourhood::Image) {
        dst.errorfmt("{}: filters the sub-buffers of a statistics file, not an image", kernel.name);
        return false;
    }
    if (src.nchannels() < 3) {
        dst.errorfmt("{} needs R, G, B channels; the image has {}", kernel.name, src.nchannels());
        return false;
    }
    const ROI full = src.roi();  // the data window: what the filter window is clipped to
    roi = prepareRoi(roi, full);
    std::vector<float> in(size_t(full.width()) * size_t(full.height()) * 3);
    if (!src.get_pixels(ROI(full.xbegin, full.xend, full.ybegin, full.yend, 0, 1, 0, 3),
                        TypeDesc::FLOAT, in.data())) {
        dst.errorfmt("{}: {}", kernel.name, src.geterror());
        return false;
    }
    const RGBImageView view{in.data(), full.width(), full.height()};
    std::string err;
    const std::unique_ptr<WindowPass> pass = kernel.begin(
        WindowInput{&view, nullptr}, roi.xbegin - full.xbegin, roi.ybegin - full.ybegin,
        roi.xend - full.xbegin, roi.yend - full.ybegin, nthreads, err);
    if (!pass) {
        dst.errorfmt("{}: {}", kernel.name, err);
        return false;
    }
    std::string colorSpace = src.spec().get_string_attribute("oiio:ColorSpace", "lin_rec709");
    int firstAov = 0;
    std::vector<AovClass> classes;
    if (!imageAovs(src.spec(), firstAov, classes)) {
        dst.reset(rgbSpec(roi, src.roi_full(), colorSpace), OIIO::InitializePixels::No);
        static const float kNoAov = 0.f;  // never read: no AOV channel
        fillFiltered(dst, roi, nthreads, 0, nullptr, *pass, full.xbegin, full.ybegin,
                     [](const WindowScratch&, int, int) { return &kNoAov; });
        return true;
    }
    // AOVs (docs/aovs.md): the window pixels' weights, from the beauty, applied to each.
    if (kernel.mode != EstimatorMode::Luminance) {
        dst.errorfmt(
            "{}: mode=channel keeps different pixels for R, G and B, so no one weight per pixel "
            "exists for the image's {} AOV channels; use mode=lum",
            kernel.name, classes.size());
        return false;
    }
    const size_t A = classes.size(), nch = size_t(src.nchannels());
    std::vector<float> all(size_t(full.width()) * size_t(full.height()) * nch);
    if (!src.get_pixels(full, TypeDesc::FLOAT, all.data())) {
        dst.errorfmt("{}: {}", kernel.name, src.geterror());
        return false;
    }
    ImageSpec spec = rgbSpec(roi, src.roi_full(), colorSpace);
    spec.nchannels = int(3 + A);
    spec.channelnames.resize(3);
    spec.channelformats.clear();
    for (size_t a = 0; a < A; ++a)
        spec.channelnames.push_back(src.spec().channelnames[size_t(firstAov) + a]);
    spec.alpha_channel = -1;
    for (size_t a = 0; a < A; ++a)
        if (classes[a] == AovClass::Alpha) spec.alpha_channel = int(3 + a);
    spec.z_channel = -1;
    spec.attribute(kAttrFirstAov, 3);
    spec.attribute(kAttrAovClasses, src.spec().get_string_attribute(kAttrAovClasses));
    dst.reset(spec, OIIO::InitializePixels::No);
    fillFiltered(dst, roi, nthreads, A, classes.data(), *pass, full.xbegin, full.ybegin,
                 [&](const WindowScratch& scratch, int element, int) {
                     const auto [xx, yy] = scratch.source[size_t(element)];
                     return all.data() + (size_t(yy) * size_t(full.width()) + size_t(xx)) * nch +
                            size_t(firstAov);
                 });
    return true;
}

ImageBuf windowFilter(const ImageBuf& src, const WindowKernel& kernel, ROI roi, int nthreads) {
    ImageBuf dst;
    windowFilter(dst, src, kernel, roi, nthreads);
    return dst;
}

}  // namespace mcstat
