// The operation registry: one line per operation, in the order --help lists them (docs/
// architecture.md). Each operation's entry (name, help, parameters, kernel) is in its own file.
#include "mcstat/filters/registry.h"

#include "mcstat/filters/pixel/gmon.h"
#include "mcstat/filters/pixel/gmonb.h"
#include "mcstat/filters/pixel/mean.h"
#include "mcstat/filters/pixel/median.h"
#include "mcstat/filters/pixel/meridian.h"
#include "mcstat/filters/pixel/myriad.h"
#include "mcstat/filters/pixel/tmpe.h"
#include "mcstat/filters/samples/pajot.h"
#include "mcstat/filters/samples/rpf.h"
#include "mcstat/filters/window/filter3d.h"
#include "mcstat/filters/window/mif.h"

namespace mcstat {

const std::vector<Operation>& operationRegistry() {
    // Functions, not namespace-scope constants: this may run during another translation unit's
    // static initialisation (the benchmarks register from it).
    static const std::vector<Operation> registry = {
        // Per pixel, over its sub-buffer means (filters/pixel/).
        meanOperation(),    // Buisine et al. 2021
        monOperation(),     //
        gmonOperation(),    //
        gmonbOperation(),   //
        medianOperation(),  // Jung 2016
        tmpeOperation(),    //
        myriadOperation(),  //
        meridianOperation(),
        // Over a window (filters/window/): Jung 2016, chapter 5.
        mifOperation(), wmifOperation(), filter3dmfOperation(), filter3dwmfOperation(),
        filter3dwtmfOperation(),
        // Over every sample (filters/samples/).
        pajotOperation(),  // Pajot et al. 2011
        rpfOperation(),    // Sen and Darabi 2011
    };
    return registry;
}

const Operation* findOperation(std::string_view name) {
    for (const Operation& op : operationRegistry())
        if (op.name == name) return &op;
    return nullptr;
}

const std::vector<Operation>& estimatorRegistry() {
    static const std::vector<Operation> estimators = [] {
        std::vector<Operation> v;
        for (const Operation& op : operationRegistry())
            if (op.input == InputKind::BufferMeans) v.push_back(op);
        return v;
    }();
    return estimators;
}

const Operation* findEstimator(std::string_view name) {
    for (const Operation& e : estimatorRegistry())
        if (e.name == name) return &e;
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

bool bindPixelKernel(const Operation& op, const std::map<std::string, std::string>& kv,
                     const std::array<double, 3>& luma, PixelKernel& out, std::string& err) {
    if (op.bindPixel == nullptr) {
        err = op.name + " is not a per-pixel estimator";
        return false;
    }
    ParamValues values;
    if (!parseOperationParams(op, kv, values, err)) return false;
    out = op.bindPixel(values, luma);
    return true;
}

}  // namespace mcstat
