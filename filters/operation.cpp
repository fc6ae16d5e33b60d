// What an operation is (operation.h): the entries' common constructors and parameters.
#include "mcstat/filters/operation.h"

namespace mcstat {

Operation pixelOperation(const std::string& name, const std::string& title, const std::string& help,
                         const std::string& equation, std::vector<ParamSpec> params,
                         BindPixelFn bind) {
    Operation op;
    op.name = name;
    op.title = title;
    op.help = help;
    op.equation = equation;
    op.input = InputKind::BufferMeans;
    op.params = std::move(params);
    op.bindPixel = bind;
    return op;
}

Operation windowOperation(const std::string& name, const std::string& title,
                          const std::string& help, const std::string& equation, Neighbourhood over,
                          std::vector<ParamSpec> params, BindWindowFn bind) {
    Operation op;
    op.name = name;
    op.title = title;
    op.help = help;
    op.equation = equation;
    op.input = InputKind::Neighbourhood;
    op.over = over;
    op.params = std::move(params);
    op.bindWindow = bind;
    return op;
}

ParamSpec modeParam() {
    return enumParam("mode", {"lum", "channel"}, "lum",
                     "lum: rank buffers by luminance and return the chosen buffers' RGB, their "
                     "weights applied to every AOV; channel: R, G, B independently, refused with "
                     "AOVs (no one weight per buffer keeps them summing to the beauty)",
                     {{"luminance", "lum"}, {"rgb", "channel"}});
}

PixelParams pixelParams(const ParamValues& values, const std::array<double, 3>& luma) {
    PixelParams p;
    p.luma = luma;
    const auto mode = values.find("mode");
    if (mode != values.end() && mode->second.text == "channel") p.mode = EstimatorMode::PerChannel;
    return p;
}

std::vector<const ParamSpec*> Operation::settable() const {
    std::vector<const ParamSpec*> v;
    for (const ParamSpec& p : params)
        if (!p.fixed) v.push_back(&p);
    return v;
}

const ParamSpec* Operation::param(std::string_view key) const {
    for (const ParamSpec& p : params)
        if (p.name == key) return &p;
    return nullptr;
}

}  // namespace mcstat
