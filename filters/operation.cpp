// What an operation is (operation.h): the entries' common constructors and parameters.
#include "mcstat/filters/operation.h"

namespace mcstat {

namespace {

Operation entry(const std::string& name, const std::string& title, const std::string& help,
                const std::string& equation, InputKind input, std::vector<ParamSpec> params) {
    Operation op;
    op.name = name;
    op.title = title;
    op.help = help;
    op.equation = equation;
    op.input = input;
    op.params = std::move(params);
    return op;
}

}  // namespace

Operation pixelOperation(const std::string& name, const std::string& title, const std::string& help,
                         const std::string& equation, std::vector<ParamSpec> params,
                         BindPixelFn bind) {
    Operation op = entry(name, title, help, equation, InputKind::BufferMeans, std::move(params));
    op.bindPixel = bind;
    return op;
}

Operation windowOperation(const std::string& name, const std::string& title,
                          const std::string& help, const std::string& equation, Neighbourhood over,
                          std::vector<ParamSpec> params, BindWindowFn bind) {
    Operation op = entry(name, title, help, equation, InputKind::Neighbourhood, std::move(params));
    op.over = over;
    op.bindWindow = bind;
    return op;
}

Operation samplesOperation(const std::string& name, const std::string& title,
                           const std::string& help, const std::string& equation,
                           std::vector<ParamSpec> params, SamplesFn fn) {
    Operation op = entry(name, title, help, equation, InputKind::Samples, std::move(params));
    op.samples = fn;
    return op;
}

ParamSpec modeParam(const std::string& help) {
    return enumParam(
        "mode", {"lum", "channel"}, "lum",
        !help.empty() ? help
                      : "lum: rank buffers by luminance and return the chosen buffers' RGB, their "
                        "weights applied to every AOV; channel: R, G, B independently, refused "
                        "with AOVs (no one weight per buffer keeps them summing to the beauty)",
        {{"luminance", "lum"}, {"rgb", "channel"}});
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

bool parseOperationParams(const Operation& op, const std::map<std::string, std::string>& kv,
                          ParamValues& out, std::string& err, const std::string& context) {
    const std::string ctx = context.empty() ? op.name : context;
    out.clear();
    // Defaults first, so every parameter is set the same way whether given or not.
    for (const ParamSpec& p : op.params)
        if (!parseParamValue(ctx, p, p.defaultValue, out[p.name], err)) return false;
    for (const auto& [key, value] : kv) {
        const ParamSpec* p = op.param(key);
        if (p == nullptr || p->fixed) {
            const std::vector<const ParamSpec*> keys = op.settable();
            std::string accepted = keys.empty() ? "it takes no parameters" : "accepted: ";
            for (size_t i = 0; i < keys.size(); ++i) accepted += (i ? ", " : "") + keys[i]->name;
            err = "estimator '" + op.name + "' has no parameter '" + key + "' (" + accepted + ")";
            return false;
        }
        if (!parseParamValue(ctx, *p, value, out[key], err)) return false;
    }
    return true;
}

}  // namespace mcstat
