// Fuzz target: ingest of an untrusted renderer EXR (ingest/ingest.cpp, docs/aovs.md). The bytes
// are one render (M = 1): every layer and part kept as AOVs with their classes, then every
// per-pixel and neighbourhood operation with its weights applied to the AOVs, and the render's
// metadata carried to a result. Rejections must be one line naming the file; an accepted render
// must give a statistics image that validates, results with every AOV, and metadata that reads
// back.
#include <OpenImageIO/imagebuf.h>

#include <algorithm>

#include "fuzz_support.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/ingest/ingest.h"

using namespace mcstat;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const fuzz::InputFile file(data, size);
    IngestOptions opt;
    opt.limits = fuzz::fuzzLimits();
    opt.spp = size % 2 ? 4 : 0;  // half the inputs must say their samples per pixel themselves
    StatsImage img;
    IngestReport report;
    std::string err;
    if (!ingestRenders({file.path()}, opt, img, report, err)) {
        // Ingest's messages name the file first ("<path>: ...") or say what was asked.
        fuzz::require(!err.empty() && err.find('\n') == std::string::npos,
                      "ingest error empty or of more than one line", oneLine(err));
        fuzz::requirePrintable(err, "ingest error holds a control byte or invalid UTF-8");
        fuzz::require(
            err.find(file.path()) != std::string::npos || err.find("spp") != std::string::npos ||
                err.find("samples") != std::string::npos || err.find("limit") != std::string::npos,
            "ingest error does not name the file", err);
        return 0;
    }
    std::string verr;
    fuzz::require(validateStats(img, file.path(), verr), "ingested image does not validate", verr);
    const StatsHeader& h = img.header;
    // What --info and -v would print of it, and the warnings, hold no control byte.
    fuzz::requirePrintableDescription(h);
    for (const std::string& w : report.warnings)
        fuzz::requirePrintable(w, "ingest warning holds a control byte or invalid UTF-8");
    fuzz::requirePrintable(printable(report.beauty.layer) + printable(report.beauty.rule),
                           "-v beauty line");
    fuzz::require(img.aov.size() == img.pixelCount() * size_t(h.M) * h.aovs.size(),
                  "AOV array size", file.path());
    const std::array<double, 3> luma{0.2126, 0.7152, 0.0722};
    // The operations run over a corner of at most 40x40 pixels: every code path (the window
    // filters' halo at the image edge included) for a bounded cost. Over a whole 1M-pixel render
    // under ASan, 20 operations took 15 s for one input, which libFuzzer reports as a slow unit.
    const OIIO::ROI corner(h.originX, h.originX + std::min(h.width, 40), h.originY,
                           h.originY + std::min(h.height, 40));
    for (const Operation& op : operationRegistry()) {
        if (op.input == InputKind::Samples) continue;
        ParamValues values;
        fuzz::require(parseOperationParams(op, {}, values, err), "default parameters", err);
        OIIO::ImageBuf out;
        if (!applyOperation(out, img, op, values, luma, false, corner, 1)) continue;
        fuzz::require(size_t(out.nchannels()) == 3 + h.aovs.size(), "result lacks AOVs", op.name);
        describeResult(out.specmod(), op, values, h);
    }
    // The metadata ingest stored reads back as the attributes it came from.
    OIIO::ImageSpec spec;
    fuzz::require(applySourceMetadata(spec, h.sourceMetadata, err), "own metadata JSON", err);
    return 0;
}
