// The dispatcher behind applyOperation (imageops.h): the one code that switches on an operation's
// InputKind, over a statistics image in memory, a streamed one, or an image.
#include "mcstat/filters/removed_light.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/keep_light_image.h"
#include "mcstat/image/removed_light_pass.h"
#include "source_header.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ROI;

using detail::headerOf;

namespace {

/// applyOperation over an image in memory or a streamed source: the same calls, each with its
/// own overloads of estimate() and windowFilter().
template <class Source>
bool runOperationOn(ImageBuf& dst, Source& src, const Operation& op, const ParamValues& values,
                    const std::array<double, 3>& luma, bool diagnostics, bool keepLight, ROI roi,
                    int nthreads) {
    switch (op.input) {
        case InputKind::BufferMeans: {
            PixelKernel kernel = op.bindPixel(values, luma);
            bindConfidence(kernel, values);
            // The removed-light layers in this pass (removedLightInPass): no second read.
            RemovedLightOptions removed;
            kernel.removedLight = removedLightValues(values, removed);
            kernel.removedLuma = luma;
            if (keepLight) {
                // What keeplight reads of the buffers, in this pass too (keep_light_image.h): the
                // plain mean and the removed-light layers' per-pixel step (their luminance
                // spread), band by band with the return.
                kernel.removedLight = true;
                kernel.plainMeanLayers = true;
                return keepLightEstimate(dst, src, op, kernel, diagnostics, luma,
                                         keepLightParams(values), nthreads);
            }
            if (!estimate(dst, src, op, kernel, diagnostics, roi, nthreads)) return false;
            return !kernel.removedLight ||
                   finishRemovedLight(dst, dst.nchannels() - 5, luma, removed, nthreads);
        }
        case InputKind::Neighbourhood: {
            const WindowKernel kernel = op.bindWindow(values, luma);
            if (kernel.over == Neighbourhood::SubBuffers)
                return windowFilter(dst, src, kernel, roi, nthreads);
            if (kernel.over == Neighbourhood::Image) {
                // The plain mean as the "mean" estimator computes it (`mcstat f --mean --mif`)
                // over roi grown by the window's radius (clipped to the data window), then the
                // median filter over roi: each window sees the same pixels as over the whole
                // image, since only the data window's edges clip it.
                const ROI full = dataWindowROI(headerOf(src));
                roi = prepareRoi(roi, full);
                const int rx = kernel.haloX(), ry = kernel.haloY();
                const ROI grown = OIIO::roi_intersection(
                    ROI(roi.xbegin - rx, roi.xend + rx, roi.ybegin - ry, roi.yend + ry), full);
                ImageBuf mean;
                if (!plainMean(mean, src, luma, grown, nthreads)) {
                    dst.errorfmt("{}: {}", op.name, mean.geterror());
                    return false;
                }
                return windowFilter(dst, mean, kernel, roi, nthreads);
            }
            break;
        }
        case InputKind::Samples:
            dst.errorfmt("{} works on the per-sample records of a statistics file on disk",
                         op.name);
            return false;
    }
    dst.errorfmt("{}: the registry entry names no input it can run on", op.name);
    return false;
}

/// The operation, then with keeplight=1 (keep_light_image.h) the light it removed given back.
template <class Source>
bool applyOperationTo(ImageBuf& dst, Source& src, const Operation& op, const ParamValues& values,
                      const std::array<double, 3>& luma, bool diagnostics, ROI roi, int nthreads) {
    const bool keep = keepLightAsked(values);
    if (const std::string why = keepLightRefusal(op, values); !why.empty()) {
        dst.errorfmt("{}", why);
        return false;
    }
    if (keep && roi.defined() && roi != dataWindowROI(headerOf(src))) {
        dst.errorfmt("{}: keeplight needs the whole data window (light moves between pixels)",
                     op.name);
        return false;
    }
    if (RemovedLightOptions r; removedLightValues(values, r) && !removedLightInPass(op, keep)) {
        dst.errorfmt(
            "{}: removed=1 is computed in the operation's pass only for a per-pixel estimator "
            "without keeplight; append the layers afterwards (appendRemovedLight)",
            op.name);
        return false;
    }
    if (!runOperationOn(dst, src, op, values, luma, diagnostics, keep, roi, nthreads)) return false;
    // A per-pixel estimator gave its light back band by band in its own pass.
    return !keep || op.input == InputKind::BufferMeans ||
           keepLight(dst, src, luma, keepLightParams(values), nthreads);
}

}  // namespace

bool applyOperation(ImageBuf& dst, const StatsImage& src, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma, bool diagnostics,
                    ROI roi, int nthreads) {
    return applyOperationTo(dst, src, op, values, luma, diagnostics, roi, nthreads);
}

bool applyOperation(ImageBuf& dst, StatsBlockSource& src, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma, bool diagnostics,
                    ROI roi, int nthreads) {
    return applyOperationTo(dst, src, op, values, luma, diagnostics, roi, nthreads);
}

bool applyOperation(ImageBuf& dst, const ImageBuf& src, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma, ROI roi,
                    int nthreads) {
    if (!takesImage(op)) {
        dst.errorfmt("{} works on a statistics file, not on an image", op.name);
        return false;
    }
    return windowFilter(dst, src, op.bindWindow(values, luma), roi, nthreads);
}

}  // namespace mcstat
