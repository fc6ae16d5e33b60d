// What an operation is: its name, its help, the paper equation it implements, the input it needs
// and its typed parameters, and the function that binds parsed parameter values to its kernel.
// Each operation defines one Operation in its own file (filters/pixel/gmon.cpp...), and the
// registry (registry.h) lists them; the tools find them there by name and never look inside their
// parameters. The few places that name one do so for what it is: the plain mean (the reference of
// residuals and what MIF filters over a statistics file), G-MoN (the default of the plugin and of
// contact sheets), and the renderer's flag of the one operation it runs online. An operation that
// keeps per-pixel state in a statistics file says what the state is through its OperationState
// hooks, so that the format and the tools stay generic (FORMAT.md "State parts with an owner").
// This header and estimate.h name no family of operations: each family (filters/pixel,
// filters/window, filters/samples) reaches only them (tests/architecture/check_arrows.sh).
//
// The kernels, by input kind (docs/architecture.md):
// - BufferMeans: a PixelKernel estimates one pixel from its M sub-buffer means, and on request
//   gives the convex weights of the sub-buffers it combined (applied to every AOV).
// - Neighbourhood: a WindowKernel is a weighted trimmed mean over a window of pixels or of their
//   sub-buffers, with its halo; it prepares a WindowPass over an input, which estimates any
//   output pixel (its parameters stay the window family's own, filters/window/window_kernel.h).
// - Samples: a SamplesFn reads the per-sample records or the stored per-pixel state through an
//   opened SampleSource and makes an image.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "mcstat/core/params.h"
#include "mcstat/core/pixel_buffers.h"
#include "mcstat/filters/estimate.h"

namespace mcstat {

/// The input an operation needs, which decides where it can run.
enum class InputKind {
    BufferMeans,    ///< per pixel, over its M sub-buffer means (PixelKernel)
    Neighbourhood,  ///< a window of pixels (WindowKernel)
    Samples,        ///< per-sample records / the renderer's online state (SamplesFn)
};

/// What a Neighbourhood operation's window holds.
enum class Neighbourhood {
    None,
    SubBuffers,  ///< the sub-buffers of the window's pixels in a statistics file (3D filters)
    Image,       ///< the pixels of an RGB image (MIF/WMIF): in `mcstat` the top image, in the
                 ///< plugin the plain mean of the sub-buffers (as `--mean` computes it)
};

/// A BufferMeans operation with its parameters bound.
struct PixelKernel {
    /// One pixel's estimate; with scratch.wantWeights also its buffer weights (pixel_estimate.h).
    std::function<void(const PixelBuffers&, PixelEstimate&, EstimatorScratch&)> estimate;
    /// Luminance: the buffer weights exist (AOVs can follow) and the diagnostics are one channel
    /// each; PerChannel: R, G, B ranked apart, diagnostics per channel, no weights.
    EstimatorMode mode = EstimatorMode::Luminance;
    /// The smallest number of sub-buffers at which the estimate can differ from the plain mean
    /// (1: at every M). Below it the CLI and the plugin say that the result is the mean.
    int smallestRobustM = 1;
    /// The confidence interval of what `estimate` estimates (filters/pixel/confidence.h), over one
    /// channel's values in the pixel's m valid buffers (`values` may be reordered; `counts` the
    /// buffers' sample counts) at `level` in (0, 1); null: the estimator has none.
    std::function<ValueInterval(double* values, const double* counts, int m, double level)>
        interval;
    /// `interval` for R, G and B of one pixel at once, over its m valid buffers `valid`
    /// (collectValidBuffers' indices): the same values (confidence.h), with one sort or one pass
    /// for the three channels. Null: `interval` is called per channel.
    std::function<void(const PixelBuffers& px, const int* valid, int m, double level,
                       ValueInterval rgb[3])>
        pixelInterval;
    /// `pixelInterval` over n pixels whose buffers are all valid (pixel i's valid buffers 0 to
    /// px[i].M - 1), rgb[3 i + c] of px[i]'s channel c: the same values, with several pixels at
    /// once. Null: `pixelInterval` per pixel.
    std::function<void(const PixelBuffers* px, int n, double level, ValueInterval* rgb)>
        runIntervals;
    /// `estimate` (without weights) and `pixelInterval` of n pixels from one pass over each
    /// pixel's buffers, e[i] and rgb[3 i + c] with the same bits as the two calls (the mean: its
    /// sums are its interval's first pass, and two pixels go side by side). Null: the two calls.
    std::function<void(const PixelBuffers* px, int n, double level, PixelEstimate* e,
                       ValueInterval* rgb)>
        estimatesWithIntervals;
    /// `estimate` (without weights) of n pixels at once, e[i] of px[i]: the same values, where
    /// several pixels go faster together than one by one. Null: `estimate` per pixel.
    std::function<void(const PixelBuffers* px, int n, PixelEstimate* e)> estimates;
    /// What the interval covers, in words (the file's mcstat:ciTarget): the expected value for
    /// the mean's, the median of the buffer means for MoN's, ... (docs/confidence.md).
    std::string intervalTarget;
    /// Set by the caller (the image layer, from the modifiers ci and ciaovs): the level of the
    /// interval layers ci_low / ci_high to add (0: none), and whether the AOVs get them too.
    double ciLevel = 0.0;
    bool ciAovs = false;
    /// citarget=expected: the interval is the expected value's (the pixel's true value), with the
    /// per-sample variance pooled over a (2 ciPool + 1)^2 window (image/expected_interval.h)
    /// instead of `interval`'s.
    bool ciExpected = false;
    int ciPool = 0;
    /// Set by the caller (the image layer, from the modifier removed): the removed-light layers'
    /// per-pixel step in the estimate's pass, while each pixel's buffers are at hand
    /// (image/removed_light_pass.h), with the working space's luminance weights.
    bool removedLight = false;
    std::array<double, 3> removedLuma{};
    /// Set by the caller (the image layer, for keeplight): the plain mean of the pixel's R, G, B
    /// and AOVs, the "mean" estimator's values bit for bit, appended after every other layer as
    /// kPlainMeanPrefix + name, from this pass while the pixel's buffers are at hand (keeplight
    /// takes them and removes them: one read of a file's buffers instead of two).
    bool plainMeanLayers = false;
};

/// The prefix of the layers PixelKernel::plainMeanLayers appends ("keeplight.mean.R", ...).
inline constexpr const char* kPlainMeanPrefix = "keeplight.mean.";
/// Binds parsed values (every parameter of the operation, defaults applied) and the luminance
/// weights (from the colour config) to the operation's own parameter struct and kernel.
using BindPixelFn = PixelKernel (*)(const ParamValues& values, const std::array<double, 3>& luma);

/// What a Neighbourhood operation's pass reads: the pixels of an RGB image (Neighbourhood::Image)
/// or the sub-buffers of a grid of pixels (SubBuffers). Pixel coordinates start at 0 at the
/// input's first pixel; windows are clipped to [0, width) x [0, height).
struct WindowInput {
    const RGBImageView* image = nullptr;  ///< Image
    const BufferView* buffers = nullptr;  ///< SubBuffers
};

/// One run of a window kernel over one input, prepared for a rectangle of output pixels (the 3D
/// filters sort each pixel's buffers there once, Jung eq. 5.24); then any thread asks it for any
/// pixel of the rectangle, each thread with its own scratch. Every output pixel depends on the
/// input alone, so results do not depend on the thread count.
class WindowPass {
  public:
    virtual ~WindowPass() = default;
    /// A scratch for one thread; its wantWeights asks filterPixel for the AOV weights.
    virtual std::unique_ptr<WindowScratch> newScratch() const = 0;
    /// The estimate of output pixel (x, y) of the input (inside the prepared rectangle).
    virtual void filterPixel(int x, int y, PixelEstimate& out, WindowScratch& s) const = 0;
};

/// A Neighbourhood operation with its parameters bound: a weighted trimmed mean over the window.
/// The family's parameters live in the closure of `begin` (filters/window/window_kernel.h).
struct WindowKernel {
    Neighbourhood over = Neighbourhood::None;
    /// What error messages call it ("3D filter", "median image filter").
    std::string name;
    /// Luminance: one weight per window element exists, so AOVs can follow the beauty.
    EstimatorMode mode = EstimatorMode::Luminance;
    /// Pixels the window reaches beyond the output pixel, each side: what a tile or a block of
    /// rows must read around itself.
    int halo[2] = {0, 0};
    int haloX() const { return halo[0]; }
    int haloY() const { return halo[1]; }
    /// Prepares a pass over `in` for the output pixels [x0, x1) x [y0, y1) of `in`, on nthreads
    /// threads (0: all); null with a one-line `err` for parameters out of range or an input of
    /// the wrong kind.
    std::function<std::unique_ptr<WindowPass>(const WindowInput& in, int x0, int y0, int x1, int y1,
                                              int nthreads, std::string& err)>
        begin;
    /// Checks the parameters without an input (begin checks them again): a streamed pass calls
    /// it before it reads the first block. False with a one-line `err`; empty: nothing to check.
    std::function<bool(std::string& err)> check;
};
using BindWindowFn = WindowKernel (*)(const ParamValues& values, const std::array<double, 3>& luma);

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

struct PixelStateParts;  // sample_records.h: an operation's state as a statistics file stores it

/// A renderer's online run of an operation that keeps per-pixel state (OperationState::start):
/// every sample goes to its pixel, in the order taken.
class OnlineRun {
  public:
    virtual ~OnlineRun() = default;
    /// Sample `rgb` (float32 radiance) of pixel `p`. Pixels are independent: threads may feed
    /// different pixels at once. Non-finite samples are refused (the renderer counts those).
    virtual void add(size_t p, const float rgb[3]) = 0;
    /// The state as its parts store it (owner, part names, parameter text), once, at the end of
    /// the run (it may move the state out); false with one line when a value does not fit.
    virtual bool encode(PixelStateParts& out, std::string& err) = 0;
    /// The run's parameters, the text its parts carry (parseParamText's grammar).
    virtual std::string paramText() const = 0;
    /// The smallest number of samples a pixel needs before the run is more than a plain mean,
    /// for the renderer's warning (0: none).
    virtual int64_t learningSamples() const = 0;
};

/// The hooks of an operation that keeps per-pixel state in a statistics file: the format stores
/// "state parts with an owner" (the operation's registry name) and knows nothing else of them.
struct OperationState {
    std::string flatPart, deepPart;  ///< the parts' names on disk, the operation's own
    /// For --info and --check: lines ("  NAME ...\n") describing state `parts` of an image
    /// `width` pixels wide, every value checked; false with one line (no file name) when bad.
    bool (*describe)(const PixelStateParts& parts, int width, std::string& text,
                     std::string& err) = nullptr;
    /// Starts an online run over `pixels` pixels with `values` (parseOperationParams) and the
    /// luminance weights `luma`, continuing `resume` when not null (a resumed render: its own
    /// parameters, which `values` must equal unless they ask for the stored ones). Null with one
    /// line in `err`.
    std::unique_ptr<OnlineRun> (*start)(const ParamValues& values,
                                        const std::array<double, 3>& luma, int width, size_t pixels,
                                        const PixelStateParts* resume, std::string& err) = nullptr;
};

struct Operation {
    std::string name;      ///< command name without dashes, e.g. "gmon"
    std::string title;     ///< e.g. "G-MoN"
    std::string help;      ///< one line for --help
    std::string equation;  ///< the paper equation(s) it implements, e.g. "Buisine et al. eq. 4, 6"
    InputKind input = InputKind::BufferMeans;
    std::vector<ParamSpec> params;
    BindPixelFn bindPixel = nullptr;           ///< BufferMeans
    BindWindowFn bindWindow = nullptr;         ///< Neighbourhood
    Neighbourhood over = Neighbourhood::None;  ///< Neighbourhood: what bindWindow's kernel reads
    SamplesFn samples = nullptr;               ///< Samples
    OperationState state;  ///< an operation that keeps state in the file: its hooks (else empty)

    /// Parameters a user may set (params without the fixed ones).
    std::vector<const ParamSpec*> settable() const;
    const ParamSpec* param(std::string_view key) const;
};

/// A BufferMeans operation's entry (input, title, help, equation, parameters, bind).
Operation pixelOperation(const std::string& name, const std::string& title, const std::string& help,
                         const std::string& equation, std::vector<ParamSpec> params,
                         BindPixelFn bind);
/// A Samples operation's entry.
Operation samplesOperation(const std::string& name, const std::string& title,
                           const std::string& help, const std::string& equation,
                           std::vector<ParamSpec> params, SamplesFn fn);
/// A Neighbourhood operation's entry.
Operation windowOperation(const std::string& name, const std::string& title,
                          const std::string& help, const std::string& equation, Neighbourhood over,
                          std::vector<ParamSpec> params, BindWindowFn bind);

/// Parses key=value parameters of `op` into `out` (modifiers, or a state part's parameter text
/// split by parseParamText): every parameter, defaults (and fixed values) applied first. An
/// unknown key or a bad value is a one-line error: the unknown key is named with the accepted
/// ones; a bad value as parseParamValue says, with `context` (default: op.name).
bool parseOperationParams(const Operation& op, const std::map<std::string, std::string>& kv,
                          ParamValues& out, std::string& err, const std::string& context = "");

/// Parameter "mode" of every operation that ranks colours (lum / channel), with the per-pixel
/// estimators' help unless given another.
ParamSpec modeParam(const std::string& help = "");

}  // namespace mcstat
