// A per-sample operation run over the statistics file on disk (runSamplesOperation, imageops.h):
// its SampleSource opened, its OperationImage turned into an ImageBuf.
#include <memory>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/image/imageops.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::TypeDesc;

bool runSamplesOperation(ImageBuf& dst, const std::string& path, const StatsHeader& header,
                         const Operation& op, const ParamValues& values,
                         const std::array<double, 3>& luma, int nthreads,
                         const std::function<void(double)>& progress) {
    if (op.input != InputKind::Samples || op.samples == nullptr) {
        dst.errorfmt("{} is not a per-sample operation", op.name);
        return false;
    }
    std::string openErr;
    const std::unique_ptr<SampleSource> source =
        openSampleSource(path, openErr, ReadLimits(), nthreads);
    if (!source) {
        dst.errorfmt("{}", openErr);
        return false;
    }
    SamplesRequest req;
    req.path = path;
    req.source = source.get();
    req.params = &values;
    req.luma = luma;
    req.nthreads = nthreads;
    req.progress = progress;
    OperationImage out;
    std::string err;
    if (!op.samples(req, out, err)) {
        dst.errorfmt("{}", err);
        return false;
    }
    const size_t nch = out.channels.size();
    if (out.width != header.width || out.height != header.height || nch < 3 ||
        out.pixels.size() != size_t(out.width) * size_t(out.height) * nch) {
        dst.errorfmt(
            "{}: {} returned a {} x {} image of {} channels and {} values; the file is {} "
            "x {}",
            path, op.name, out.width, out.height, nch, out.pixels.size(), header.width,
            header.height);
        return false;
    }
    dst.reset(floatSpec(dataWindowROI(header), out.channels, {}, header.colorSpace));
    return dst.set_pixels(dst.roi(), TypeDesc::FLOAT, out.pixels.data());
}

}  // namespace mcstat
