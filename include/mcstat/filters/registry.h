// The one registry of operations: everything an image can be made with. Each operation is
// registered once, with the input it needs (InputKind) and its typed parameters (ParamSpec: name,
// type, range, default, help). The `mcstat` commands and their --help, the OIIO plugin's
// `mcstat:estimator` / `?estimator=` choices and the benchmarks are all generated from it, and
// parseParamValue is the one checked parser of parameter and modifier values.
//
// Adding an operation: one file pair (filters/<method>.cpp, include/mcstat/<method>.h) with the
// function, one entry in filters/registry.cpp, and tests (docs/estimators.md, "Adding an
// operation").
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "mcstat/core/params.h"
#include "mcstat/filters/pixel/ranking.h"
#include "mcstat/filters/window/window_rank.h"

namespace mcstat {

// ---- operations ---------------------------------------------------------------------------------

/// The input an operation needs, which decides where it can run.
enum class InputKind {
    BufferMeans,    ///< per pixel, over its M sub-buffer means (EstimatorFn)
    Neighbourhood,  ///< a window of pixels (Neighbourhood says of what)
    Samples,        ///< per-sample records / the renderer's online state (SamplesFn)
};

/// What a Neighbourhood operation's window holds.
enum class Neighbourhood {
    None,
    SubBuffers,  ///< the sub-buffers of the window's pixels in a statistics file (3D filters)
    Image,       ///< the pixels of an RGB image (MIF/WMIF): in `mcstat` the top image, in the
                 ///< plugin the plain mean of the sub-buffers (as `--mean` computes it)
};

using EstimatorFn = void (*)(const PixelBuffers&, const EstimatorParams&, PixelEstimate&,
                             EstimatorScratch&);

/// The image a Samples operation makes: the file's data window, scanline order, R, G, B first.
struct OperationImage {
    int width = 0, height = 0;
    std::vector<std::string> channels{"R", "G", "B"};
    std::vector<float> pixels;  ///< width * height * channels.size()
};

/// What a Samples operation is given: the statistics file's path (it streams the file by blocks
/// itself; it reads whatever parts it needs), its parsed parameters and the environment.
class SampleSource;  // sample_records.h

struct SamplesRequest {
    std::string path;
    /// The file, opened by the caller (exr-deep's openSampleSource): the operation reads its parts
    /// through it, by blocks of rows, and never opens files itself.
    SampleSource* source = nullptr;
    const ParamValues* params = nullptr;  ///< every parameter, defaults applied
    std::array<double, 3> luma{0.0, 0.0, 0.0};
    int nthreads = 0;  ///< 0: all cores
    /// Long operations report their progress (0..1) here when set (the CLI sets it on a
    /// terminal only).
    std::function<void(double)> progress;
};

/// A Samples operation: false with a one-line `err` (naming the file) when the file cannot
/// provide its input (e.g. no per-sample part) or is bad.
using SamplesFn = bool (*)(const SamplesRequest&, OperationImage& out, std::string& err);

struct Operation {
    std::string name;      ///< command name without dashes, e.g. "gmon"
    std::string title;     ///< e.g. "G-MoN"
    std::string help;      ///< one line for --help
    std::string equation;  ///< the paper equation(s) it implements, e.g. "Buisine et al. eq. 4, 6"
    InputKind input = InputKind::BufferMeans;
    EstimatorFn fn = nullptr;  ///< BufferMeans
    std::vector<ParamSpec> params;
    Neighbourhood over = Neighbourhood::None;  ///< Neighbourhood
    SamplesFn samples = nullptr;               ///< Samples

    /// Parameters a user may set (params without the fixed ones).
    std::vector<const ParamSpec*> settable() const;
    const ParamSpec* param(std::string_view key) const;
};

// Former names, still used by the estimator code.
using EstimatorInfo = Operation;
using EstimatorParamInfo = ParamSpec;

/// Every operation, in a stable order: the per-pixel estimators, then the neighbourhood filters,
/// then the per-sample operations.
const std::vector<Operation>& operationRegistry();
/// nullptr when unknown.
const Operation* findOperation(std::string_view name);

/// The BufferMeans operations (the estimators over sub-buffer means), in registry order.
const std::vector<EstimatorInfo>& estimatorRegistry();
/// A BufferMeans operation; nullptr when unknown or of another kind.
const EstimatorInfo* findEstimator(std::string_view name);

/// Parses key=value parameters of `op` into `out`: every parameter, defaults (and fixed values)
/// applied first. An unknown key or a bad value is a one-line error: the unknown key is named with
/// the accepted ones; a bad value as parseParamValue says, with `context` (default: op.name).
bool parseOperationParams(const Operation& op, const std::map<std::string, std::string>& kv,
                          ParamValues& out, std::string& err, const std::string& context = "");

/// The smallest number of sub-buffers M at which the BufferMeans operation `op` with parameters
/// `p` can return something other than the plain mean: MoN and the median average the two middle
/// means of M = 2 (3); G-MoN trims c = floor(k G) <= floor((M - 1) / 2) with k = floor(M / 2), and
/// for M = 3 the Gini coefficient of three values stays below 1 (4); G-MoN_b uses MoN (3); TMPE
/// the first M with tmpeTrim(alpha, M) >= 1; myriad and meridian 2. 1 for the mean and anything
/// else (no warning is due).
int smallestRobustM(const Operation& op, const EstimatorParams& p);

/// The estimator's parameters from parsed values (keys the estimator does not have are left as
/// `out` holds them; the caller sets out.luma).
void applyEstimatorParams(const ParamValues& values, EstimatorParams& out);
/// parseOperationParams + applyEstimatorParams.
bool parseEstimatorParams(const EstimatorInfo& info, const std::map<std::string, std::string>& kv,
                          EstimatorParams& out, std::string& err);

/// A Neighbourhood operation's SpatialParams (size, w, alpha, mode) from parsed values, with
/// `luma`.
SpatialParams spatialParams(const ParamValues& values, const std::array<double, 3>& luma);

}  // namespace mcstat
