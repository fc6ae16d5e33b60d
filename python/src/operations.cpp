// Registry operations and the noise-aware comparison for Python, through the dispatcher the CLI
// uses (image/imageops.h, compare/compare.h): equal to `mcstat FILE --OP` bit for bit.
#include "bindings.h"
#include "mcstat/compare/compare.h"
#include "mcstat/compare/report/compare_report.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/temp_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/keep_light_image.h"
#include "mcstat/image/operation_input.h"
#include "mcstat/image/removed_light_layers.h"

namespace mcstat::python {

namespace {

const Operation& operationNamed(const std::string& name) {
    const Operation* op = findOperation(name);
    if (op != nullptr) return *op;
    std::string names;
    for (const Operation& o : operationRegistry()) names += (names.empty() ? "" : ", ") + o.name;
    throw Error("unknown operation '" + name + "' (operations: " + names + ")");
}

py::list operations() {
    py::list out;
    for (const Operation& op : operationRegistry()) {
        py::dict d;
        d["name"] = op.name;
        d["title"] = op.title;
        d["help"] = op.help;
        d["takes_image"] = takesImage(op);
        d["reads_samples"] = readsSamples(op);
        d["has_diagnostics"] = hasDiagnostics(op);
        py::list params;
        for (const ParamSpec& p : op.params) {
            if (p.fixed) continue;
            py::dict q;
            q["name"] = p.name;
            q["default"] = p.defaultValue;
            q["accepts"] = describeParam(p);
            q["help"] = p.help;
            params.append(q);
        }
        d["params"] = params;
        out.append(d);
    }
    return out;
}

/// A statistics source for Python: an image in memory (a handle) or a file streamed by blocks.
struct Source {
    std::shared_ptr<NativeStats> native;
    std::string path;
    std::unique_ptr<StatsBlockSource> stream;
    StatsHeader header;
    std::string name;

    explicit Source(const py::object& obj) {
        if (py::isinstance<NativeStats>(obj)) {
            native = obj.cast<std::shared_ptr<NativeStats>>();
            header = native->img->header;
            name = native->name;
        } else {
            path = obj.cast<std::string>();
            name = path;
            std::string err;
            py::gil_scoped_release release;
            if (!checkStatsPath(path, err) || !readStatsHeader(path, header, err)) throw Error(err);
        }
    }
    /// The block source (opened on first use, GIL released by the caller).
    StatsBlockSource& blocks() {
        if (!stream) {
            if (native) {
                stream = std::make_unique<MemoryStatsSource>(native->img, name);
            } else {
                auto reader = std::make_unique<StatsFileReader>();
                std::string err;
                if (!reader->open(path, err)) throw Error(err);
                stream = std::move(reader);
            }
        }
        return *stream;
    }
};

/// An operation's modifiers as `mcstat --OP:key=value` reads them (diag, residual and removed
/// among them): checked, then split into the layers asked for and the operation's parameters.
struct EstimateRequest {
    bool diag = false, residual = false, removed = false;
    RemovedLightOptions removedOpt;
    ParamValues values;  ///< the operation's parameters with ci, ciaovs and keeplight
};

EstimateRequest estimateRequest(const Operation& op, const std::string& cmd,
                                const std::map<std::string, std::string>& params, bool diag,
                                bool residual) {
    std::map<std::string, std::string> mods = params;
    if (diag) mods["diag"] = "1";
    if (residual) mods["residual"] = "1";
    std::string err;
    const std::vector<ParamSpec> specs = operationModifiers(op);
    const std::map<std::string, std::string> given = mods;  // before the defaults are filled in
    if (!checkModifiers(cmd, specs, mods, err)) throw Error(err);
    EstimateRequest q;
    q.diag = diag;
    q.residual = residual;
    // removed=True (removedradius, removedz): the removed-light layers, as the command's.
    q.removed = modifierValue(specs, mods, "removed").integer != 0;
    if (std::string why = removedModifiersRefusal(cmd, q.removed, given); !why.empty())
        throw Error(why);
    if (q.removed) {
        q.removedOpt.radius = int(modifierValue(specs, mods, "removedradius").integer);
        q.removedOpt.zLimit = modifierValue(specs, mods, "removedz").real;
    }
    for (const char* k : {"diag", "residual", "removed", "removedradius", "removedz"})
        mods.erase(k);
    ParamValues ci;  // ci, ciaovs: the interval layers (docs/confidence.md)
    if (!takeConfidenceModifiers(cmd, mods, ci, err)) throw Error(err);
    ParamValues keep;  // keeplight: the removed light given back (docs/keep-light.md)
    if (!takeKeepLightModifiers(cmd, mods, keep, err)) throw Error(err);
    if (!parseOperationParams(op, mods, q.values, err, cmd)) throw Error(err);
    q.values.insert(ci.begin(), ci.end());
    q.values.insert(keep.begin(), keep.end());
    return q;
}

py::tuple estimate(const py::object& src, const std::string& name,
                   const std::map<std::string, std::string>& params, bool diag, bool residual) {
    const Operation& op = operationNamed(name);
    const std::string cmd = "--" + op.name;
    Source in(src);
    const EstimateRequest q = estimateRequest(op, cmd, params, diag, residual);
    const std::array<double, 3> luma = lumaOf(in.header.colorSpace, in.name);
    // Python's own advice for a computed image (the seam's names the CLI's way).
    if (readsSamples(op) && in.path.empty())
        throw Error(cmd + " reads the per-sample records of a statistics file on disk; " + in.name +
                    " was computed (write it with mcstat.write and pass the path)");
    // A per-pixel estimator computes the removed light in its own pass (removed_light_pass.h),
    // as the CLI does; otherwise a file is streamed once more for it, and once more for the
    // residual.
    const bool removedInPass = q.removed && removedLightInPass(op, keepLightAsked(q.values));
    ParamValues runValues = q.values;
    if (removedInPass) setRemovedLightValues(runValues, q.removedOpt);
    // What Python holds, described once (image/operation_input.h), as the CLI and the plugin do:
    // the seam takes what the operation's kind needs.
    OperationInput input;
    input.name = in.name;
    input.path = in.path;
    input.header = &in.header;
    if (in.native)
        input.stats = in.native->img.get();
    else
        input.stream = [&in](std::string&) -> StatsBlockSource* { return &in.blocks(); };
    std::unique_ptr<Source> again, againRemoved;
    if (q.residual && !in.native) again = std::make_unique<Source>(src);
    if (q.removed && !removedInPass && !in.native) againRemoved = std::make_unique<Source>(src);
    OIIO::ImageBuf img;
    {
        py::gil_scoped_release release;
        bool ok = applyOperation(img, input, op, runValues, luma, q.diag);
        if (!ok) throw Error(cmd + ": " + img.geterror());
        if (q.removed && !removedInPass) {
            ok = in.native ? appendRemovedLight(img, *in.native->img, luma, q.removedOpt)
                           : appendRemovedLight(img, againRemoved->blocks(), luma, q.removedOpt);
            if (!ok) throw Error(cmd + ": " + img.geterror());
        }
        if (q.residual) {
            ok = in.native ? appendResidual(img, *in.native->img, luma)
                           : appendResidual(img, again->blocks(), luma);
            if (!ok) throw Error(cmd + ": " + img.geterror());
        }
    }
    return imageArrays(img);
}

py::dict findingDict(const CompareFinding& f) {
    py::dict d;
    if (!f.valid) return d;
    d["tile"] = f.tile;
    d["x"] = f.x;
    d["y"] = f.y;
    d["quantity"] = f.quantity;
    d["a"] = f.a;
    d["b"] = f.b;
    d["p"] = f.result.p;
    d["z"] = f.result.z;
    d["difference"] = f.result.difference;
    d["se"] = f.result.se;
    return d;
}

/// Writes the maps to `path` (an EXR, through a temporary file renamed onto it).
void writeMaps(const OIIO::ImageBuf& maps, const std::string& path) {
    std::string err;
    if (!checkOutputTarget(path, err)) throw Error("--compare: " + err);
    TemporaryFile tmp(path, ".exr");
    if (!maps.write(tmp.path(), OIIO::TypeFloat, "openexr"))
        throw Error("--compare: " + path + ": " + libraryMessage(maps.geterror()));
    if (!tmp.commit(err)) throw Error("--compare: " + err);
}

py::dict compare(const py::object& a, const py::object& b,
                 const std::map<std::string, std::string>& params, const std::string& mapsPath) {
    Source sa(a), sb(b);
    CompareOptions opt;
    std::string err;
    if (!parseCompareOptions(params, opt, err, "--compare")) throw Error(err);
    if (modifierValue(compareParams(), params, "refspp").real != 0.0)
        throw Error("--compare: refspp is for an image reference; " + sa.name + " and " + sb.name +
                    " are statistics files");
    if (sa.header.colorSpace != sb.header.colorSpace)
        throw Error("--compare: " + sa.name + " is in " + sa.header.colorSpace + " but " + sb.name +
                    " is in " + sb.header.colorSpace);
    opt.luma = lumaOf(sa.header.colorSpace, sa.name);
    CompareReportRequest report = compareReportRequest(params);
    report.a.name = sa.name;
    report.b.name = sb.name;
    for (CompareReportSide* s : {&report.a, &report.b})
        if (py::isinstance<py::str>(s == &report.a ? a : b)) s->files.push_back(s->name);
    opt.keepMeans = report.needsMeans();
    CompareResult r;
    {
        py::gil_scoped_release release;
        const auto start = std::chrono::steady_clock::now();
        if (!compareStats(sa.blocks(), sb.blocks(), opt, r, err)) throw Error("--compare: " + err);
        report.seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        if (report.any() && !writeCompareReports(r, opt, report, err, opt.nthreads))
            throw Error("--compare: " + err);
        if (!mapsPath.empty()) writeMaps(r.maps, mapsPath);
    }
    py::dict d;
    d["verdict"] = compareVerdict(r, opt);
    d["evidence"] = py::cast(compareEvidence(r, opt));
    d["fail"] = r.fail;
    d["identical"] = r.identical;
    d["underpowered"] = r.underpowered;
    py::dict power;
    auto num = [](double v) -> py::object {
        return std::isfinite(v) ? py::object(py::float_(v)) : py::object(py::none());
    };
    power["probability"] = kComparePower;
    power["tile_relative"] = num(r.power.tileRelative);
    power["tile_absolute"] = num(r.power.tileAbsolute);
    power["pixel_relative"] = num(r.power.pixelRelative);
    power["pixel_absolute"] = num(r.power.pixelAbsolute);
    d["power"] = power;
    d["quantities"] = py::cast(r.quantities);
    d["Ma"] = r.Ma;
    d["Mb"] = r.Mb;
    d["tile"] = r.tile;
    d["pixels"] = r.pixels;
    d["pixels_tested"] = r.pixelsTested;
    d["pixels_differing"] = r.pixelsRejected;
    d["tiles"] = r.tiles;
    d["tiles_tested"] = r.tilesTested;
    d["tiles_differing"] = r.tilesRejected;
    d["non_finite_one_side"] = r.nonFiniteOneSide;
    d["non_finite_both"] = r.nonFiniteBoth;
    d["few_buffers"] = r.fewBuffers;
    d["constant_equal"] = r.constantEqual;
    d["hypotheses"] = r.hypotheses;
    d["threshold"] = r.threshold;
    d["tile_threshold"] = r.tileThreshold;
    d["strongest"] = findingDict(r.strongest);
    d["strongest_tile"] = findingDict(r.strongestTile);
    d["maps"] = imageArrays(r.maps);
    return d;
}

}  // namespace

void bindOperations(py::module_& m) {
    m.def("_operations", &operations);
    m.def("_estimate", &estimate, py::arg("src"), py::arg("name"), py::arg("params"),
          py::arg("diag"), py::arg("residual"));
    m.def("_compare", &compare, py::arg("a"), py::arg("b"), py::arg("params"),
          py::arg("maps") = std::string());
}

}  // namespace mcstat::python
