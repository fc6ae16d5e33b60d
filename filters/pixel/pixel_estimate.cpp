// The per-pixel family's shared parameters (pixel_estimate.h).
#include "mcstat/filters/pixel/pixel_estimate.h"

namespace mcstat {

PixelParams pixelParams(const ParamValues& values, const std::array<double, 3>& luma) {
    PixelParams p;
    p.luma = luma;
    const auto mode = values.find("mode");
    if (mode != values.end() && mode->second.text == "channel") p.mode = EstimatorMode::PerChannel;
    return p;
}

}  // namespace mcstat
