// An operation's result described on its spec: the source's provenance, the operation and its
// parameters (describeResult, imageops.h).
#include "mcstat/image/imageops.h"
#include "mcstat/image/spec/render_layout.h"

namespace mcstat {

using OIIO::ImageSpec;

void describeResult(ImageSpec& spec, const Operation& op, const ParamValues& values,
                    const StatsHeader& h, std::string* warning) {
    describeSource(spec, h, warning);
    std::string params;
    for (const auto& [k, v] : values) {
        const ParamSpec* ps = op.param(k);
        if (ps && ps->fixed) continue;
        params += (params.empty() ? "" : ",") + k + "=" + v.text;
    }
    const std::string p = kProvenancePrefix;
    spec.attribute(p + "operation", op.name);
    spec.attribute(p + "parameters", params);
}

}  // namespace mcstat
