// The one seam between every input kind and every operation (operation_input.h): the caller says
// what it holds, this takes what the operation needs.
#include "mcstat/image/operation_input.h"

#include "mcstat/image/keep_light_image.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ROI;

bool applyOperation(ImageBuf& dst, const OperationInput& in, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma, bool diagnostics,
                    ROI roi, int nthreads) {
    const bool statistics = in.stats != nullptr || bool(in.stream) || in.header != nullptr;
    // The per-sample and image paths below never reach applyOperation's own check.
    if (const std::string why = keepLightRefusal(op, values); !why.empty()) {
        dst.errorfmt("{}", why);
        return false;
    }
    if (readsSamples(op)) {
        // Per-sample operations read the file's records or stored state from disk themselves.
        if (in.path.empty() || in.header == nullptr) {
            if (statistics)
                dst.errorfmt(
                    "{} reads the per-sample records of a statistics file on disk; {} was "
                    "computed (write it and read it back)",
                    op.name, in.name);
            else
                dst.errorfmt("{} reads the per-sample records of a statistics file; {} is an image",
                             op.name, in.name);
            return false;
        }
        return runSamplesOperation(dst, in.path, *in.header, op, values, luma, nthreads,
                                   in.progress);
    }
    if (in.image != nullptr) return applyOperation(dst, *in.image, op, values, luma, roi, nthreads);
    if (takesImage(op) && !in.imageOperationsFilterTheMean) {
        dst.errorfmt("{} is a statistics file; {} filters an image: apply an estimator first",
                     in.name, op.name);
        return false;
    }
    if (in.stats != nullptr)
        return applyOperation(dst, *in.stats, op, values, luma, diagnostics, roi, nthreads);
    if (in.stream) {
        std::string err;
        StatsBlockSource* source = in.stream(err);
        if (source == nullptr) {
            dst.errorfmt("{}", err);
            return false;
        }
        return applyOperation(dst, *source, op, values, luma, diagnostics, roi, nthreads);
    }
    dst.errorfmt("{}: {} holds no image and no statistics", op.name, in.name);
    return false;
}

ImageBuf applyOperation(const OperationInput& in, const Operation& op, const ParamValues& values,
                        const std::array<double, 3>& luma, bool diagnostics, ROI roi,
                        int nthreads) {
    ImageBuf dst;
    applyOperation(dst, in, op, values, luma, diagnostics, roi, nthreads);
    return dst;
}

}  // namespace mcstat
