// OpenImageIO-facing image operations over statistics files, in OIIO's two forms:
//   ImageBuf op(const Src&, ..., ROI roi = {}, int nthreads = 0)
//   bool     op(ImageBuf& dst, const Src&, ..., ROI roi = {}, int nthreads = 0)
// Errors are recorded on the returned / destination ImageBuf (has_error(), geterror()); nothing
// throws. One theme per source file of image/: estimate.cpp, window_filter_image.cpp,
// window_filter_buffers.cpp, apply_operation.cpp (the dispatcher), imageops_stream.cpp (the same,
// streamed), residual.cpp, plain_mean.cpp, operation_modifiers.cpp, confidence_modifiers.cpp,
// interval_width.cpp, samples_operation.cpp, describe_result.cpp. The display transform and the
// image differences of review tools are review/'s (mcstat/review/display.h).
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <map>
#include <string>

#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/spec/image_spec.h"

namespace mcstat {

/// The channels estimate() gives: R, G, B, and with `diagnostics` "gini", "kept", "excluded"
/// (luminance mode) or "gini.R/G/B", "kept.R/G/B", "excluded" (channel mode). With AOVs in the
/// statistics image, aovOutputChannels(header) follow.
std::vector<std::string> estimatorChannels(EstimatorMode mode, bool diagnostics);

/// Describes an operation's result on its spec: describeSource (render_layout.h: the source's
/// metadata, mcstat.M, mcstat.spp, mcstat.sources, mcstat.renderer), then mcstat.operation (e.g.
/// "gmon") and mcstat.parameters ("mode=lum", the settable ones).
void describeResult(OIIO::ImageSpec& spec, const Operation& op, const ParamValues& values,
                    const StatsHeader& h, std::string* warning = nullptr);

/// Runs estimator `est` on every pixel of `src` within `roi` (default: the whole data window).
/// The result has channels R, G, B and, when `diagnostics` is set, the Gini coefficient, the number
/// of buffers kept and the number excluded for NaN/Inf: "gini", "kept", "excluded" in luminance
/// mode; "gini.R/G/B", "kept.R/G/B", "excluded" per channel. When `src` holds AOVs (version 5)
/// every AOV channel follows, under its input name: the estimator's buffer weights, computed from
/// the beauty, applied to each (applyAovWeights), so AOVs that summed to the beauty in every
/// buffer still sum to the result; the AOV of class alpha is the spec's alpha channel. AOVs need
/// luminance mode (channel mode is refused: it has no one weight per buffer). The display window
/// is the header's.
bool estimate(OIIO::ImageBuf& dst, const StatsImage& src, const Operation& est,
              const PixelKernel& kernel, bool diagnostics = false, OIIO::ROI roi = {},
              int nthreads = 0);
OIIO::ImageBuf estimate(const StatsImage& src, const Operation& est, const PixelKernel& kernel,
                        bool diagnostics = false, OIIO::ROI roi = {}, int nthreads = 0);

/// A window operation (Neighbourhood::Image: Jung's (weighted) median image filter WMIF / MIF,
/// eq. 5.6-5.8, centre weight eq. 5.28) with its kernel bound (`op.bindWindow(values, luma)`, or
/// windowKernel in filters/window/window_kernel.h) over the R, G, B channels (the first three) of
/// `src`, within `roi` (default: src's data window). The window is clipped to src's data window,
/// never to `roi`, so a tile's result equals the same pixels of the whole image. The result has
/// channels R, G, B, and when `src` carries AOVs (kAttrFirstAov, an estimator's result over a file
/// with AOVs) those AOVs too, each with the window pixels' weights from the beauty (luminance mode
/// only). Every output pixel depends on the input alone: identical for any `nthreads`.
bool windowFilter(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const WindowKernel& kernel,
                  OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf windowFilter(const OIIO::ImageBuf& src, const WindowKernel& kernel,
                            OIIO::ROI roi = {}, int nthreads = 0);

/// A window operation over sub-buffers (Neighbourhood::SubBuffers: Jung's 3D filters 3DWTMF /
/// 3DWMF / 3DMF, eq. 5.19-5.21) over the sub-buffers of `src`, within `roi` (default: the data
/// window; the window is clipped to the data window). Buffers vote once each
/// (BufferVotes::PerBuffer) in a fixed-M image and with their sample counts (PerSample) when
/// src.header.adaptiveM. The result has channels R, G, B, then the file's AOVs, each with the
/// weight every (window pixel, sub-buffer) had in the beauty's average (luminance mode only;
/// channel mode is refused with AOVs). Identical for any `nthreads`.
bool windowFilter(OIIO::ImageBuf& dst, const StatsImage& src, const WindowKernel& kernel,
                  OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf windowFilter(const StatsImage& src, const WindowKernel& kernel, OIIO::ROI roi = {},
                            int nthreads = 0);

/// Runs registry operation `op` with parsed `values` (parseOperationParams) over the statistics
/// image `src`, whatever its input kind: BufferMeans through estimate() (with `diagnostics`, its
/// gini/kept/excluded channels follow R, G, B), Neighbourhood through windowFilter (over an Image:
/// applied to the plain mean of the sub-buffers, the "mean" estimator, as `mcstat f --mean --mif`
/// does). Samples operations need the file itself (runSamplesOperation). `luma` as
/// lumaCoefficients() gives it.
bool applyOperation(OIIO::ImageBuf& dst, const StatsImage& src, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma,
                    bool diagnostics = false, OIIO::ROI roi = {}, int nthreads = 0);
/// `op` over an image instead of a statistics file: the operations that filter an image (MIF,
/// WMIF) filter R, G, B of `src` (and the AOVs an estimator's result over a file with AOVs
/// carries, kAttrFirstAov). Any other operation is an error on dst.
bool applyOperation(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma,
                    OIIO::ROI roi = {}, int nthreads = 0);

/// What the dispatcher asks of an operation, so that its callers (the CLI, the plugin, the review
/// commands) need not look at its kind:
/// - takesImage: applyOperation over an image is its natural form (over a statistics file it
///   filters the plain mean);
bool takesImage(const Operation& op);
/// - readsSamples: it reads the per-sample records or stored state of a file on disk
///   (runSamplesOperation), not sub-buffers in memory;
bool readsSamples(const Operation& op);
/// - hasDiagnostics: applyOperation's `diagnostics` adds channels (gini, kept, excluded);
bool hasDiagnostics(const Operation& op);
/// - operationModifiers: the modifiers of `mcstat --OP` (and of Python's mcstat.estimate): its
///   settable parameters, then `diag` when hasDiagnostics, `residual` unless it takes an image or
///   reads samples (checkModifiers in core/params.h checks them);
std::vector<ParamSpec> operationModifiers(const Operation& op);
/// The one-line refusal of removedradius or removedz given without removed=1 (they would be
/// ignored), as ciaovs without ci is refused; empty when the modifiers agree. `removed`: whether
/// removed=1 was given.
std::string removedModifiersRefusal(const std::string& context, bool removed,
                                    const std::map<std::string, std::string>& mods);
/// - hasIntervals: it is a per-pixel estimator with a confidence interval (PixelKernel::interval,
///   filters/pixel/confidence.h), so operationModifiers lists `ci` and `ciaovs`;
bool hasIntervals(const Operation& op);
/// - smallestIntervalM: with values' `ci`, the smallest number of valid buffers at which the
///   interval reaches that level (below it the interval is the buffers' range, or [-inf, inf] for
///   one buffer); 0 when no interval is asked for.
int smallestIntervalM(const Operation& op, const ParamValues& values);
/// - smallestRobustM: the smallest M at which its result can differ from the plain mean (1: at
///   any M, and for operations that are not per-pixel estimators).
int smallestRobustM(const Operation& op, const ParamValues& values);

// ---- the same operations, streamed
// --------------------------------------------------------------- Over a StatsBlockSource
// (stats_file.h: a file, a merge, an image in memory) the operations read blocks of rows of about
// kStreamBlockBytes of decoded sub-buffers (the 3D filters 4x that, plus their window's halo rows)
// and only the rows `roi` needs; the result equals the in-memory operation's over the whole image,
// pixel for pixel. From a file only the sub-buffer part is decoded: each block's counts are
// checked, but the cross-part check that they sum to the moments count is left to readStatsFile.

/// The channels applyOperation gives for `op` with `values`: estimatorChannels for an estimator
/// over buffer means, R, G, B for a neighbourhood operation, nothing for a Samples operation
/// (known once it ran).
/// With `header` (the statistics file's), the AOV channels the operation carries follow.
std::vector<std::string> operationChannels(const Operation& op, const ParamValues& values,
                                           bool diagnostics, const StatsHeader* header = nullptr);

/// Decoded bytes per block of a streamed operation.
inline constexpr size_t kStreamBlockBytes = size_t(64) << 20;

bool estimate(OIIO::ImageBuf& dst, StatsBlockSource& src, const Operation& est,
              const PixelKernel& kernel, bool diagnostics = false, OIIO::ROI roi = {},
              int nthreads = 0);
OIIO::ImageBuf estimate(StatsBlockSource& src, const Operation& est, const PixelKernel& kernel,
                        bool diagnostics = false, OIIO::ROI roi = {}, int nthreads = 0);
bool windowFilter(OIIO::ImageBuf& dst, StatsBlockSource& src, const WindowKernel& kernel,
                  OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf windowFilter(StatsBlockSource& src, const WindowKernel& kernel, OIIO::ROI roi = {},
                            int nthreads = 0);
bool applyOperation(OIIO::ImageBuf& dst, StatsBlockSource& src, const Operation& op,
                    const ParamValues& values, const std::array<double, 3>& luma,
                    bool diagnostics = false, OIIO::ROI roi = {}, int nthreads = 0);

/// The confidence-interval modifiers of an estimator with intervals (issue 37, docs/confidence.md):
/// `ci` a level in (0, 1) (unset: no interval layers) and `ciaovs` (1: the AOVs get intervals too).
std::vector<ParamSpec> confidenceModifiers();
/// Moves `ci` and `ciaovs` (already checked by checkModifiers) out of `mods` into `out`, parsed, so
/// that the rest are the operation's own parameters (parseOperationParams); applyOperation reads
/// them from its `values` (merge `out` into them). False with parseParamValue's line.
bool takeConfidenceModifiers(const std::string& context, std::map<std::string, std::string>& mods,
                             ParamValues& out, std::string& err);
/// Sets kernel.ciLevel and kernel.ciAovs from `values` (its `ci` and `ciaovs`, when present).
void bindConfidence(PixelKernel& kernel, const ParamValues& values);
/// Prefixes of the interval layers: ci_low.R, ci_low.G, ci_low.B, ci_high.R, ci_high.G, ci_high.B,
/// then with ciAovs ci_low.<aov>, ci_high.<aov> for every AOV but the labels (class id); they come
/// after the diagnostics and before the AOVs.
inline constexpr const char* kCiLowPrefix = "ci_low.";
inline constexpr const char* kCiHighPrefix = "ci_high.";
/// The name of intervalWidthImage's channel, which --heatmap:channel=ciwidth draws.
inline constexpr const char* kCiWidthChannel = "ciwidth";
/// One channel "ciwidth", the interval's relative width per pixel, sum_c (ci_high.c - ci_low.c) /
/// sum_c |c| over R, G, B (the width of the channels' average over its value): 0 where the
/// interval has zero width, +inf where it is wider than a zero estimate or unbounded (one buffer),
/// NaN where there is none. False (an error on `dst`) when `src` has no ci_low.R ... ci_high.B.
bool intervalWidthImage(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src);
/// The interval channels `kernel` (bound with bindConfidence) adds over a file with header `h`.
std::vector<std::string> intervalChannels(const PixelKernel& kernel, const StatsHeader& h);

/// Prefix of the residual channels appendResidual adds.
inline constexpr const char* kResidualPrefix = "residual.";
/// Appends to `robust`, an operation's result over `src` (R, G, B first; same data window), the
/// residual of the beauty and of every AOV but the labels (class id): "residual.<channel>" =
/// plain mean - robust, the mean as the "mean" estimator computes it over `src`. So robust +
/// residual = mean up to one float rounding: a compositor adds back, where it judges the light
/// real, what the estimator removed (docs/aovs.md). Errors on `robust`.
bool appendResidual(OIIO::ImageBuf& robust, const StatsImage& src,
                    const std::array<double, 3>& luma, int nthreads = 0);
bool appendResidual(OIIO::ImageBuf& robust, StatsBlockSource& src,
                    const std::array<double, 3>& luma, int nthreads = 0);

/// The plain mean of the sub-buffers over `roi` (the registry's "mean" with its defaults; R, G, B,
/// then the AOVs): what MIF filters when given a statistics file, and the reference of the
/// residuals (appendResidual, keepLight). Errors on dst.
bool plainMean(OIIO::ImageBuf& dst, const StatsImage& src, const std::array<double, 3>& luma,
               OIIO::ROI roi = {}, int nthreads = 0);
bool plainMean(OIIO::ImageBuf& dst, StatsBlockSource& src, const std::array<double, 3>& luma,
               OIIO::ROI roi = {}, int nthreads = 0);

/// The channels of `robust` (an operation's result over a file with header `h`) that hold light
/// of their own, with a residual against the plain mean `mean`: R, G, B and every AOV of the file
/// but the labels (class id: a label's "residual" is no light), found in `mean` by name. Their
/// indices in `robust`; `meanIndex` gets each one's index in `mean`.
std::vector<int> residualChannels(const OIIO::ImageSpec& robust, const OIIO::ImageSpec& mean,
                                  const StatsHeader& h, std::vector<int>& meanIndex);

/// Runs a Samples operation on the statistics file `path` (op.samples streams it) and turns its
/// OperationImage into an ImageBuf with the data window of `header` (the file's). False with the
/// message on dst. `progress` (0..1), when set, hears from long operations.
bool runSamplesOperation(OIIO::ImageBuf& dst, const std::string& path, const StatsHeader& header,
                         const Operation& op, const ParamValues& values,
                         const std::array<double, 3>& luma, int nthreads = 0,
                         const std::function<void(double)>& progress = {});

/// The beauty part (plain mean) of a statistics file as an RGB float image.
OIIO::ImageBuf beautyImage(const StatsImage& src);

}  // namespace mcstat
