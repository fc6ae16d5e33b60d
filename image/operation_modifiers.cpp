// What the dispatcher asks of an operation (takesImage, readsSamples, hasDiagnostics,
// smallestRobustM) and the modifiers of `mcstat --OP` that follow from it (operationModifiers,
// removedModifiersRefusal; imageops.h).
#include "mcstat/filters/keep_light.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/keep_light_image.h"

namespace mcstat {

bool takesImage(const Operation& op) {
    return op.input == InputKind::Neighbourhood && op.over == Neighbourhood::Image;
}

bool readsSamples(const Operation& op) { return op.input == InputKind::Samples; }

bool hasDiagnostics(const Operation& op) { return op.input == InputKind::BufferMeans; }

std::vector<ParamSpec> operationModifiers(const Operation& op) {
    std::vector<ParamSpec> m;
    for (const ParamSpec* p : op.settable()) m.push_back(*p);
    if (hasDiagnostics(op))
        m.push_back(flagParam("diag", "0", "1 appends channels gini, kept, excluded"));
    if (hasIntervals(op))
        for (const ParamSpec& p : confidenceModifiers()) m.push_back(p);
    if (!takesImage(op) && !readsSamples(op)) {
        m.push_back(
            flagParam("residual", "0",
                      "1 appends residual.<channel> = mean - result for the beauty and every AOV"));
        m.push_back(flagParam(
            "removed", "0",
            "1 appends removed.Y, .se, .z, .zlocal, .significant: the light taken, its standard "
            "error, and where the buffers support it (docs/removed-light.md)"));
        m.push_back(intParam("removedradius", 0, 16, "2",
                             "with removed=1: radius of the window of removed.zlocal"));
        m.push_back(realParam("removedz", 0.0, 1e6, true, "3",
                              "with removed=1: removed.significant where removed.zlocal > this"));
        for (const ParamSpec& p : keepLightModifiers()) m.push_back(p);
    }
    return m;
}

std::string removedModifiersRefusal(const std::string& context, bool removed,
                                    const std::map<std::string, std::string>& mods) {
    if (removed) return {};
    for (const char* k : {"removedradius", "removedz"})
        if (mods.count(k)) return context + ": " + k + " needs removed=1";
    return {};
}

int smallestRobustM(const Operation& op, const ParamValues& values) {
    if (op.input != InputKind::BufferMeans) return 1;
    return op.bindPixel(values, {0.0, 0.0, 0.0}).smallestRobustM;
}

}  // namespace mcstat
