// Robust images that keep their light (issue 49, docs/keep-light.md): `:keeplight=1` on every
// estimator and 3D filter over a statistics file. The residual (plain mean - result) of the beauty
// and of every AOV but the labels is given back, all of it, at a scale the data choose pixel by
// pixel (filters/keep_light.h): the image's sum per channel is the plain mean's up to float
// summation, a pixel no removed light reaches is the robust estimate bit for bit, and AOVs go
// back by the beauty's kernels, so light groups still sum to the beauty.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <array>
#include <map>
#include <string>
#include <vector>

#include "mcstat/core/params.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/keep_light.h"
#include "mcstat/filters/registry.h"

namespace mcstat {

/// The modifiers: `keeplight` (1: give the removed light back), `keeplightgamma` (the ICI
/// threshold, in standard errors) and `keeplightradius` (the largest window radius, pixels).
std::vector<ParamSpec> keepLightModifiers();
/// Moves the keeplight modifiers (already checked by checkModifiers) out of `mods` into `out`,
/// parsed; nothing when keeplight is absent or 0 (keeplightgamma/keeplightradius without it are
/// an error, one line). False with the line.
bool takeKeepLightModifiers(const std::string& context, std::map<std::string, std::string>& mods,
                            ParamValues& out, std::string& err);
/// Whether `values` (takeKeepLightModifiers merged in) asks for the light back, and with what.
bool keepLightAsked(const ParamValues& values);
/// Why `op` with `values` cannot give its light back (an image filter or a per-sample operation;
/// keeplight with ci, whose interval is the robust estimate's), as one line; empty when it can or
/// keeplight is not asked. The one check of every caller (the seam, applyOperation, the sheet).
std::string keepLightRefusal(const Operation& op, const ParamValues& values);
KeepLightParams keepLightParams(const ParamValues& values);

/// Gives `robust` (an operation's float result over `src`: R, G, B first, then any channels, the
/// file's AOVs under their names; its data window) the light it removed: each returned channel
/// (R, G, B and every AOV but the labels, as appendResidual picks them) becomes robust + the
/// residuals of its neighbourhood, each spread by its pixel's window (filters/keep_light.h), by
/// bands of rows (filters/keep_light_stream.h): beside `robust`, a few bands are held. Other
/// channels are left as they are. Adds mcstat:keeplight:returned (the luminance returned over the
/// plain mean's, the fraction of the light the estimate had removed), :gamma and :maxRadius.
/// Errors on `robust`.
bool keepLight(OIIO::ImageBuf& robust, const StatsImage& src, const std::array<double, 3>& luma,
               const KeepLightParams& params = {}, int nthreads = 0);
bool keepLight(OIIO::ImageBuf& robust, StatsBlockSource& src, const std::array<double, 3>& luma,
               const KeepLightParams& params = {}, int nthreads = 0);

/// A per-pixel estimator's result over the whole data window of `src` with its light given back,
/// computed band by band with keepLight's return: `kernel` (bound from `op`, with removedLight and
/// plainMeanLayers set) gives each band's result and, in the same pass over the buffers, its
/// plain mean and luminance spread, which stay in the band. The same pixels and attributes as
/// estimate() then keepLight(); beside the result, a few bands of rows are held. Errors on dst.
bool keepLightEstimate(OIIO::ImageBuf& dst, const StatsImage& src, const Operation& op,
                       const PixelKernel& kernel, bool diagnostics,
                       const std::array<double, 3>& luma, const KeepLightParams& params,
                       int nthreads = 0);
bool keepLightEstimate(OIIO::ImageBuf& dst, StatsBlockSource& src, const Operation& op,
                       const PixelKernel& kernel, bool diagnostics,
                       const std::array<double, 3>& luma, const KeepLightParams& params,
                       int nthreads = 0);

}  // namespace mcstat
