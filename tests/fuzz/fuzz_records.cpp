// Fuzz target: the version-4 parts of a statistics file: the per-sample deep part `records`
// (SampleRecordsReader, by blocks of rows, with every channel and with R, G, B, Z alone), Pajot's
// parts `pajot` and `modes`, and the per-sample operations (Pajot, RPF) over what was accepted.
#include "fuzz_support.h"
#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/filters/registry.h"
#include "mcstat/filters/samples/sample_delaying_state.h"

using namespace mcstat;

namespace {

void runSamplesOperations(SampleSource& source) {
    for (const Operation& op : operationRegistry()) {
        if (op.input != InputKind::Samples || op.samples == nullptr) continue;
        std::string err;
        ParamValues values;
        fuzz::require(parseOperationParams(op, {}, values, err), "default parameters", err);
        SamplesRequest req;
        req.path = source.path();
        req.source = &source;
        req.params = &values;
        req.luma = {0.2126, 0.7152, 0.0722};
        req.nthreads = 1;
        OperationImage out;
        if (!op.samples(req, out, err)) {
            fuzz::requireOneLineError(source.path(), err);
            continue;
        }
        const StatsHeader& h = source.header();
        fuzz::require(
            out.width == h.width && out.height == h.height &&
                out.pixels.size() == size_t(out.width) * size_t(out.height) * out.channels.size(),
            "operation image size", op.name);
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const fuzz::InputFile file(data, size);
    const ReadLimits limits = fuzz::fuzzLimits();
    std::string err;

    SampleRecordsReader records;
    if (records.open(file.path(), err, limits)) {
        const StatsHeader& h = records.header();
        SampleBlock block;
        bool ok = true;
        for (int y = 0; ok && y < h.height; y += 2) {
            ok = records.read(y, std::min(2, h.height - y), block, err);
            if (!ok) fuzz::requireOneLineError(file.path(), err);
        }
        if (ok && records.select({}, err)) {
            for (int y = 0; ok && y < h.height; y += 3) {
                ok = records.read(y, std::min(3, h.height - y), block, err);
                if (!ok) fuzz::requireOneLineError(file.path(), err);
            }
        }
    } else {
        fuzz::requireOneLineError(file.path(), err);
    }

    PajotImage pajot;
    if (!readPajotParts(file.path(), pajot, err, limits))
        fuzz::requireOneLineError(file.path(), err);

    const std::unique_ptr<SampleSource> source = openSampleSource(file.path(), err, limits);
    if (!source) {
        fuzz::requireOneLineError(file.path(), err);
        return 0;
    }
    runSamplesOperations(*source);
    return 0;
}
