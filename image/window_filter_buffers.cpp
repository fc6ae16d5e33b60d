// A window operation over the sub-buffers of a statistics image (Neighbourhood::SubBuffers: the
// 3D filters; windowFilter over a StatsImage, imageops.h), the file's AOVs weighted as every
// (window pixel, sub-buffer) was in the beauty's average.
#include <memory>

#include "mcstat/image/imageops.h"
#include "window_fill.h"

namespace mcstat {

using detail::fillFiltered;
using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;

namespace {

/// An AOV-carrying result: `names` (R, G, B, AOVs) and spec attributes for region `roi`.
ImageSpec aovResultSpec(ROI roi, const StatsHeader& h, const std::string& colorSpace) {
    std::vector<std::string> names = {"R", "G", "B"};
    for (const std::string& n : aovOutputChannels(h)) names.push_back(n);
    ImageSpec spec = floatSpec(roi, names, displayWindowROI(h), colorSpace);
    spec.alpha_channel = aovAlphaChannel(h, 3);
    spec.z_channel = aovDepthChannel(h, 3);
    setAovAttributes(spec, h, 3);
    return spec;
}

}  // namespace

bool windowFilter(ImageBuf& dst, const StatsImage& src, const WindowKernel& kernel, ROI roi,
                  int nthreads) {
    const StatsHeader& h = src.header;
    if (kernel.over != Neighbourhood::SubBuffers) {
        dst.errorfmt("{}: filters an image, not the sub-buffers of a statistics file", kernel.name);
        return false;
    }
    // Fixed or adaptive M: the view hands each pixel's own buffers (StatsImage::pixelBuffers).
    if (std::string why; !src.checkBufferLayout(why)) {
        dst.errorfmt("{}: statistics image has inconsistent buffer arrays ({})", kernel.name, why);
        return false;
    }
    const ROI full = dataWindowROI(h);
    roi = prepareRoi(roi, full);
    const size_t A = h.aovs.size();
    if (A > 0 && src.aov.size() != src.bufferCount.size() * A) {
        dst.errorfmt("{}: statistics image has {} AOV values for {} AOV channels", kernel.name,
                     src.aov.size(), A);
        return false;
    }
    if (A > 0 && kernel.mode != EstimatorMode::Luminance) {
        dst.errorfmt(
            "{}: mode=channel keeps different sub-buffers for R, G and B, so no one weight per "
            "sub-buffer exists for the file's {} AOV channels (they would stop adding up to the "
            "beauty); use mode=lum",
            kernel.name, A);
        return false;
    }
    // Adaptive M: a pixel's M_p buffers hold n / M_p samples each next to one-buffer pixels of n,
    // so every sample votes once (BufferVotes::PerSample); fixed M: one vote per buffer (eq. 5.19).
    const BufferView view{
        h.width, h.height, &src,
        [](const void* ctx, int x, int y) {
            const auto* img = static_cast<const StatsImage*>(ctx);
            return img->pixelBuffers(size_t(y) * size_t(img->header.width) + size_t(x));
        },
        h.adaptiveM ? BufferVotes::PerSample : BufferVotes::PerBuffer};
    std::string err;
    const std::unique_ptr<WindowPass> pass =
        kernel.begin(WindowInput{nullptr, &view}, roi.xbegin - h.originX, roi.ybegin - h.originY,
                     roi.xend - h.originX, roi.yend - h.originY, nthreads, err);
    if (!pass) {
        dst.errorfmt("{}: {}", kernel.name, err);
        return false;
    }
    dst.reset(A > 0 ? aovResultSpec(roi, h, h.colorSpace) : floatSpec(roi, {"R", "G", "B"}, h),
              OIIO::InitializePixels::No);
    // AOVs (docs/aovs.md): every (window pixel, sub-buffer) keeps the weight it had in the
    // beauty's trimmed average.
    const std::vector<AovClass> classes = aovClasses(h.aovs);
    fillFiltered(dst, roi, nthreads, A, classes.data(), *pass, h.originX, h.originY,
                 [&](const WindowScratch& scratch, int list, int buffer) {
                     const auto [xx, yy] = scratch.source[size_t(list)];
                     const size_t k = src.bufferBegin(size_t(yy) * size_t(h.width) + size_t(xx)) +
                                      size_t(buffer);
                     return src.aov.data() + k * A;
                 });
    return true;
}

ImageBuf windowFilter(const StatsImage& src, const WindowKernel& kernel, ROI roi, int nthreads) {
    ImageBuf dst;
    windowFilter(dst, src, kernel, roi, nthreads);
    return dst;
}

}  // namespace mcstat
