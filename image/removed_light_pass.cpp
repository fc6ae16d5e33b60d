// The removed-light layers in two steps (removed_light_pass.h): the per-pixel values and the
// image-wide finish, shared by the estimate's pass and appendRemovedLight.
#include "mcstat/image/removed_light_pass.h"

#include <cmath>

#include "mcstat/core/color_space.h"
#include "mcstat/core/pixel_buffers.h"
#include "mcstat/filters/operation.h"
#include "mcstat/filters/removed_light.h"

namespace mcstat {

using OIIO::ImageBuf;
using OIIO::ImageSpec;

std::vector<std::string> removedLightChannels() {
    std::vector<std::string> names;
    for (const char* c : {"Y", "se", "z", "zlocal", "significant"})
        names.push_back(kRemovedPrefix + std::string(c));
    return names;
}

namespace {

/// How many pixels ahead finishRemovedLight's passes ask for the pixels they read: its two loops
/// run on one thread (their sums in pixel order), and without asking they waited on memory for
/// most of their time (perf: 60 % of their samples on two loads, a 1080p G-MoN's :removed).
constexpr size_t kFinishAhead = 64;

/// Asks for `count` channels from `at` (a channel of pixel 0) of pixel p + kFinishAhead, where
/// the image's n pixels of nch channels have one: the channels a pass reads of each pixel.
[[gnu::always_inline]] inline void prefetchFinish(const float* at, size_t p, size_t n, size_t nch,
                                                  size_t count) {
    if (p + kFinishAhead < n) prefetchLines(at + (p + kFinishAhead) * nch, count * sizeof(float));
}

}  // namespace

void removedLightPixel(const float* rgb, float spreadMean, float spreadSe,
                       const std::array<double, 3>& luma, float out[5]) {
    const double dp = double(spreadMean) - luminance(luma, rgb);
    out[0] = std::isfinite(dp) ? float(dp) : 0.f;
    out[1] = spreadSe;
    out[2] = float(removedZ(out[0], out[1]));
    out[3] = spreadMean;
    out[4] = 0.f;
}

bool finishRemovedLight(ImageBuf& img, int first, const std::array<double, 3>& luma,
                        const RemovedLightOptions& opt, int nthreads) {
    if (opt.radius < 0 || !(opt.zLimit > 0.0) || !std::isfinite(opt.zLimit)) {
        img.errorfmt("removed light: radius {} and z limit {}: need radius >= 0, z > 0", opt.radius,
                     opt.zLimit);
        return false;
    }
    const ImageSpec& spec = img.spec();
    if (first < 3 || first + 5 > spec.nchannels || spec.format != OIIO::TypeDesc::FLOAT ||
        !img.localpixels()) {
        img.errorfmt("removed light: the image has no removed-light channels at {}", first);
        return false;
    }
    const size_t n = size_t(spec.width) * size_t(spec.height), nch = size_t(spec.nchannels);
    float* px = static_cast<float*>(img.localpixels());
    // The image's sums in pixel order (the same for any thread count).
    double removed = 0.0, total = 0.0, variance = 0.0;
    for (size_t p = 0; p < n; ++p) {
        prefetchFinish(px, p, n, nch, 3);          // R, G, B
        prefetchFinish(px + first, p, n, nch, 5);  // the removed-light channels
        const float* q = px + p * nch;
        const float* r = q + first;
        const double dp = double(r[3]) - luminance(luma, q);
        if (std::isfinite(dp) && std::isfinite(r[1])) {
            removed += dp;
            variance += double(r[1]) * double(r[1]);
        }
        if (std::isfinite(r[3])) total += double(r[3]);
    }
    // zlocal from the image's d and se into the fourth channel, whose luminance mean the sums
    // above were its last reader.
    float* d = px + first;
    localRemovedZ(d, d + 1, nch, spec.width, spec.height, opt.radius, d + 3, nch, nthreads);
    // The significant light's sum in pixel order, and the flags in the same pass.
    double significant = 0.0;
    for (size_t p = 0; p < n; ++p) {
        prefetchFinish(d, p, n, nch, 5);  // only the removed-light channels: R, G, B are not read
        float* r = d + p * nch;
        const bool flagged = r[3] > opt.zLimit;
        if (flagged) significant += double(r[0]);
        r[4] = flagged ? 1.f : 0.f;
    }
    ImageSpec& s = img.specmod();
    s.attribute("mcstat:removed:energyFraction", float(total != 0.0 ? removed / total : 0.0));
    s.attribute("mcstat:removed:significantFraction",
                float(removed != 0.0 ? significant / removed : 0.0));
    // The whole image as one window: light spread thin over many pixels (fireflies everywhere)
    // is no region's, yet real in sum.
    s.attribute("mcstat:removed:zImage", float(removedZ(removed, std::sqrt(variance))));
    s.attribute("mcstat:removed:radius", opt.radius);
    s.attribute("mcstat:removed:zLimit", float(opt.zLimit));
    return true;
}

void setRemovedLightValues(ParamValues& values, const RemovedLightOptions& opt) {
    ParamValue on;
    on.type = ParamType::Flag;
    on.integer = 1;
    on.real = 1.0;
    on.text = "1";
    values["removed"] = on;
    ParamValue radius;
    radius.type = ParamType::Int;
    radius.integer = opt.radius;
    radius.real = opt.radius;
    radius.text = std::to_string(opt.radius);
    values["removedradius"] = radius;
    ParamValue z;
    z.type = ParamType::Real;
    z.real = opt.zLimit;
    z.text = std::to_string(opt.zLimit);
    values["removedz"] = z;
}

bool removedLightValues(const ParamValues& values, RemovedLightOptions& opt) {
    const auto on = values.find("removed");
    if (on == values.end() || on->second.integer == 0) return false;
    opt = RemovedLightOptions{};
    if (const auto r = values.find("removedradius"); r != values.end())
        opt.radius = int(r->second.integer);
    if (const auto z = values.find("removedz"); z != values.end()) opt.zLimit = z->second.real;
    return true;
}

bool removedLightInPass(const Operation& op, bool keepLight) {
    return op.input == InputKind::BufferMeans && !keepLight;
}

}  // namespace mcstat
