// Fuzz target: the streamed reader (StatsFileReader) by blocks of rows, fixed and adaptive M (the
// deep part vbuffers), every part and each part alone, then a streamed estimator over it.
#include <OpenImageIO/imagebuf.h>

#include "fuzz_support.h"
#include "mcstat/image/imageops.h"

using namespace mcstat;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const fuzz::InputFile file(data, size);
    std::string err;
    StatsFileReader reader;
    if (!reader.open(file.path(), err, fuzz::fuzzLimits(), /*nthreads=*/1)) {
        fuzz::requireOneLineError(file.path(), err);
        return 0;
    }
    const StatsHeader& h = reader.header();
    fuzz::require(h.width > 0 && h.height > 0, "opened without a size", file.path());
    StatsImage block;
    for (unsigned parts : {unsigned(kStatsAllParts), unsigned(kStatsPartBuffers),
                           unsigned(kStatsPartMoments | kStatsPartFeatures)}) {
        const int rows = reader.blockRows(parts, 4096);
        fuzz::require(rows >= 1 && rows <= h.height, "block height", std::to_string(rows));
        for (int y = 0; y < h.height; y += rows) {
            if (!reader.read(y, std::min(rows, h.height - y), parts, block, err)) {
                fuzz::requireOneLineError(file.path(), err);
                return 0;
            }
            std::string verr;
            fuzz::require(validateStats(block, parts, file.path(), verr),
                          "accepted block does not validate", verr);
        }
    }
    const Operation* gmon = findOperation("gmon");
    ParamValues values;
    fuzz::require(gmon != nullptr && parseOperationParams(*gmon, {}, values, err), "gmon", err);
    OIIO::ImageBuf out;
    applyOperation(out, reader, *gmon, values, {0.2126, 0.7152, 0.0722}, true, {}, 1);
    return 0;
}
