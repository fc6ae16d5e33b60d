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
#include "mcstat/filters/samples/cascade_reweighting_operation.h"
#include "mcstat/filters/samples/rpf.h"
#include "mcstat/filters/samples/sample_delaying.h"
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
        pajotOperation(),     // Pajot et al. 2011
        rpfOperation(),       // Sen and Darabi 2011
        reweightOperation(),  // Zirr, Hanika and Dachsbacher 2018
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
