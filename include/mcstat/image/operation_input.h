// The one seam between the input kinds and the operations: an image, a statistics file in memory
// or streamed by blocks of rows, or the file on disk that per-sample operations read themselves.
// The command-line tool and the OIIO plugin describe what they hold in one OperationInput and call
// one applyOperation, which picks the form the operation's kind needs (docs/architecture.md, "A
// new input kind"); neither branches on the kind.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <array>
#include <functional>
#include <string>

#include "mcstat/image/imageops.h"

namespace mcstat {

/// What an operation may run on. Fill in what you hold; applyOperation takes what it needs.
struct OperationInput {
    std::string name;                       ///< what the input is, for messages ("scene.mcstat")
    const OIIO::ImageBuf* image = nullptr;  ///< an image (MIF/WMIF filter R, G, B and its AOVs)
    const StatsImage* stats = nullptr;      ///< a statistics file in memory
    /// A statistics source by blocks of rows (a file, a merge, a compact or ingest source), opened
    /// only when an operation needs it: null with `err` when it cannot be.
    std::function<StatsBlockSource*(std::string& err)> stream;
    std::string path;                      ///< the statistics file on disk, when it is one
    const StatsHeader* header = nullptr;   ///< its header (with `path`, or of `stats`/`stream`)
    std::function<void(double)> progress;  ///< long per-sample operations report 0..1 here
    /// An image operation (MIF) over a statistics file filters its plain mean (the plugin's
    /// choice); false: refused, the caller asking for the estimator to be named first (mcstat's).
    bool imageOperationsFilterTheMean = true;
};

/// Runs registry operation `op` with parsed `values` over `in`: a per-sample operation on the file
/// on disk (runSamplesOperation, progress reported), any other on the image when there is one,
/// else on the statistics in memory or streamed (with `diagnostics`, an estimator's gini, kept and
/// excluded channels follow R, G, B). Errors on dst, naming `in.name`, when `in` lacks what the
/// operation needs.
bool applyOperation(OIIO::ImageBuf& dst, const OperationInput& in, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma,
                    bool diagnostics = false, OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf applyOperation(const OperationInput& in, const Operation& op,
                              const ParamValues& values, const std::array<double, 3>& luma,
                              bool diagnostics = false, OIIO::ROI roi = {}, int nthreads = 0);

}  // namespace mcstat
