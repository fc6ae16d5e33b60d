// Test pixels: a pixel's sub-buffers built from RGB means and counts, shared by the estimator
// tests.
#pragma once

#include <array>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "mcstat/filters/pixel/ranking.h"
#include "mcstat/filters/registry.h"

namespace mcstat::testing {

inline const std::array<double, 3> kLuma{0.2126, 0.7152, 0.0722};
inline const float kNaN = std::numeric_limits<float>::quiet_NaN();
inline const float kInf = std::numeric_limits<float>::infinity();

/// A pixel built from per-buffer RGB means and counts.
struct Pixel {
    std::vector<float> mean, count;
    Pixel(std::vector<std::array<float, 3>> rgb, std::vector<float> n) : count(std::move(n)) {
        for (auto& c : rgb) mean.insert(mean.end(), c.begin(), c.end());
    }
    PixelBuffers view() const { return {mean.data(), count.data(), int(count.size())}; }
};

/// Grey buffers: the same value on R, G, B; counts 1 unless given.
inline Pixel grey(std::vector<float> v, std::vector<float> n = {}) {
    if (n.empty()) n.assign(v.size(), 1.f);
    std::vector<std::array<float, 3>> rgb;
    for (float x : v) rgb.push_back({x, x, x});
    return Pixel(rgb, n);
}

/// Operation `name`'s kernel as the registry binds it: parameters `kv` over the defaults, "mode"
/// from `mode` (for operations that rank colours), luminance weights kLuma.
inline PixelKernel kernelOf(const std::string& name, EstimatorMode mode = EstimatorMode::Luminance,
                            std::map<std::string, std::string> kv = {}) {
    const Operation* op = findOperation(name);
    if (op == nullptr || op->bindPixel == nullptr)
        throw std::invalid_argument(name + " is not a per-pixel operation");
    if (op->param("mode")) kv["mode"] = mode == EstimatorMode::Luminance ? "lum" : "channel";
    ParamValues values;
    std::string err;
    if (!parseOperationParams(*op, kv, values, err)) throw std::invalid_argument(err);
    return op->bindPixel(values, kLuma);
}

/// One pixel through kernelOf(name, mode, kv).
inline PixelEstimate runKernel(const std::string& name, const Pixel& px,
                               EstimatorMode mode = EstimatorMode::PerChannel,
                               std::map<std::string, std::string> kv = {}) {
    const PixelKernel k = kernelOf(name, mode, std::move(kv));
    EstimatorScratch s;
    PixelEstimate e;
    k.estimate(px.view(), e, s);
    return e;
}

}  // namespace mcstat::testing
