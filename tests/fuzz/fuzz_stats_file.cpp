// Fuzz target: the whole-file statistics reader (readStatsHeader, readStatsFile) and, on every file
// it accepts, each per-pixel estimator of the registry and a 3D filter. Accepted files must
// validate; rejections must be one line naming the file (fuzz_support.h).
#include <OpenImageIO/imagebuf.h>

#include "fuzz_support.h"
#include "mcstat/image/imageops.h"

using namespace mcstat;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const fuzz::InputFile file(data, size);
    const ReadLimits limits = fuzz::fuzzLimits();
    std::string err;
    StatsHeader hdr;
    if (!readStatsHeader(file.path(), hdr, err, limits))
        fuzz::requireOneLineError(file.path(), err);
    else
        fuzz::requirePrintableDescription(hdr);  // what --info prints of it

    StatsImage img;
    if (!readStatsFile(file.path(), img, err, limits)) {
        fuzz::requireOneLineError(file.path(), err);
        return 0;
    }
    std::string verr;
    fuzz::require(validateStats(img, file.path(), verr), "accepted file does not validate", verr);

    // Every value a file can hold reaches the estimators: NaN, Inf, denormals, 1e38, zero counts.
    const std::array<double, 3> luma{0.2126, 0.7152, 0.0722};
    for (const Operation& op : operationRegistry()) {
        if (op.input == InputKind::Samples) continue;
        ParamValues values;
        fuzz::require(parseOperationParams(op, {}, values, err), "default parameters", err);
        OIIO::ImageBuf out;
        applyOperation(out, img, op, values, luma, /*diagnostics=*/true, {}, /*nthreads=*/1);
    }
    return 0;
}
