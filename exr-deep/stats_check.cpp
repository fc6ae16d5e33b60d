// checkStatsFile: the complete validation behind `mcstat f --check` (FORMAT.md "Validation").
// Everything is read by blocks through the same readers the operations use, so what --check
// accepts, every command can read.
#include <OpenEXR/ImfCheckFile.h>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <exception>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "stats_layout.h"

namespace mcstat {

bool checkStatsFile(const std::string& path, StatsCheckReport& report, std::string& err,
                    const ReadLimits& limits, int nthreads,
                    const std::function<void(double)>& progress) {
    report = StatsCheckReport();
    // 1. Headers and chunk table, checked against the file before anything is allocated.
    StatsFileReader reader;
    if (!reader.open(path, err, limits, nthreads)) return false;
    const StatsHeader& h = reader.header();
    report.header = h;
    report.pixels = int64_t(h.width) * h.height;

    // 2. OpenEXR's own checker (exrcheck's engine: every read path of the library, the Core API's
    //    validation included), in its reduced-memory mode. It runs after step 1, which bounds
    //    what the headers may claim. It returns true when it found a problem.
    try {
        if (Imf::checkOpenEXRFile(path.c_str(), /*reduceMemory=*/true, /*reduceTime=*/true,
                                  /*enableCoreCheck=*/true)) {
            err = path + ": OpenEXR's file checker (exrcheck) reports the file as damaged";
            return false;
        }
    } catch (const std::exception& e) {
        err = fmt::format("{}: OpenEXR's file checker failed ({})", path, libraryMessage(e.what()));
        return false;
    }
    report.openexrChecked = true;

    // 3. Every row of the four parts, by blocks; read() checks each count and, with buffers and
    //    moments both decoded, that the buffer counts sum to the moments count.
    const int extraSteps = (h.hasRecords ? 1 : 0) + (h.hasState() ? 1 : 0);
    const double shareOfParts = 1.0 / double(1 + extraSteps);
    StatsImage block;
    const int rows = reader.blockRows(kStatsAllParts);
    for (int y = 0; y < h.height; y += rows) {
        const int n = std::min(rows, h.height - y);
        if (!reader.read(y, n, kStatsAllParts, block, err)) return false;
        report.subBuffers += int64_t(block.bufferCount.size());
        for (float v : block.bufferMean) report.nonFinite += !std::isfinite(v);
        if (progress) progress(shareOfParts * double(y + n) / double(h.height));
    }

    // 4. The version-4 parts.
    double done = shareOfParts;
    if (h.hasRecords) {
        SampleRecordsReader records;
        if (!records.open(path, err, limits)) return false;
        SampleBlock samples;
        const int recordRows = std::max(1, (1 << 16) / std::max(1, h.width));
        for (int y = 0; y < h.height; y += recordRows) {
            const int n = std::min(recordRows, h.height - y);
            if (!records.read(y, n, samples, err)) return false;
            for (uint32_t c : samples.counts) report.records += int64_t(c);
            if (progress) progress(done + shareOfParts * double(y + n) / double(h.height));
        }
        done += shareOfParts;
    }
    if (h.hasState()) {
        // The parts' shapes and sizes; what they mean their owner checks (its registry entry's
        // OperationState::describe, which `mcstat --check` runs too).
        PixelStateParts state;
        if (!readPixelStateParts(path, state, err, limits)) return false;
        report.state = true;
        if (progress) progress(1.0);
    }
    return true;
}

}  // namespace mcstat
