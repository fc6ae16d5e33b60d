// The comparison's key=value parameters (compareParams, parseCompareOptions; compare.h): one
// declaration, parsed by the registry's parser.
#include <OpenImageIO/strutil.h>

#include <cmath>

#include "mcstat/compare/compare.h"
#include "mcstat/filters/registry.h"

namespace mcstat {

const std::vector<ParamSpec>& compareParams() {
    static const std::vector<ParamSpec> m = [] {
        ParamSpec aovs = textParam("aovs", "",
                                   "AOV channels to test too, each by itself: names or globs, "
                                   "comma-separated (e.g. *_key.*)");
        aovs.list = true;
        return std::vector<ParamSpec>{
            realParam("level", 0.0, 0.5, true, "0.01",
                      "false discovery rate (or error rate, see control) of the verdict"),
            enumParam("test", {"welch", "yuen"}, "welch",
                      "welch: means; yuen: trimmed means, robust to fireflies"),
            realParam("trim", 0.0, 0.45, false, "0.2", "yuen: fraction trimmed from each end"),
            enumParam("control", {"fdr", "fwer", "none"}, "fdr",
                      "fdr: Benjamini-Hochberg; fwer: Holm; none: each test alone"),
            enumParam("channels", {"luminance", "rgb"}, "luminance", "what a pixel is tested on",
                      {{"lum", "luminance"}, {"y", "luminance"}}),
            aovs,
            intParam("tile", 0, 4096, "16", "tile side for the tile tests; 0: pixels only"),
            realParam("tol", 0.0, HUGE_VAL, false, "0", "absolute tolerance (image units)"),
            realParam("reltol", 0.0, HUGE_VAL, false, "0",
                      "relative tolerance (fraction of the pixel's value)"),
            flagParam("equivalence", "0",
                      "1: show agreement within the tolerance (two one-sided tests per tile)"),
            realParam("refspp", 0.0, HUGE_VAL, false, "0",
                      "image reference: its samples per pixel (0: exact)"),
            textParam("layer", "", "image reference: its RGB layer (default: its beauty)"),
            textParam("refvar", "",
                      "image reference: its per-sample variance image (Mitsuba 3's _var.exr)"),
            enumParam("rule", {"mcstat", "mitsuba"}, "mcstat",
                      "mitsuba: Mitsuba 3's render-test rule against refvar (docs/compare.md)"),
            realParam("varfloor", 0.0, HUGE_VAL, false, "1e-4",
                      "rule=mitsuba: floor of the reference's variance"),
            realParam("passfraction", 0.0, 1.0, false, "0.9975",
                      "rule=mitsuba: fraction of channel tests that must pass"),
            realParam("minpower", 0.0, HUGE_VAL, false, "0",
                      "fail (UNDERPOWERED) unless a change of this fraction in one tile (one "
                      "pixel without tiles) would have been found with probability 0.8; 0: "
                      "no limit"),
            enumParam("identical", {"pass", "fail"}, "pass",
                      "fail: two copies of one render (IDENTICAL, which tests nothing) fail, "
                      "for CI"),
            textParam("junit", "", "write the verdict as JUnit XML to this file"),
            textParam("json", "", "write the verdict and its numbers as JSON to this file"),
            textParam("html", "", "write a report page (A, B, heatmap, numbers) into this folder"),
            textParam("name", "", "the test's name in the reports (default: A vs B)"),
        };
    }();
    return m;
}

bool parseCompareOptions(const std::map<std::string, std::string>& kv, CompareOptions& opt,
                         std::string& err, const std::string& context) {
    std::map<std::string, std::string> mods = kv;
    if (!checkModifiers(context, compareParams(), mods, err)) return false;
    Operation compare;  // the registry's parser gives the typed values
    compare.name = "compare";
    compare.params = compareParams();
    ParamValues v;
    if (!parseOperationParams(compare, mods, v, err, context)) return false;
    opt.level = v.at("level").real;
    opt.trimmed = v.at("test").text == "yuen";
    opt.trim = v.at("trim").real;
    const std::string control = v.at("control").text;
    opt.control = control == "fwer"   ? Multiplicity::FWER
                  : control == "none" ? Multiplicity::None
                                      : Multiplicity::FDR;
    opt.rgb = v.at("channels").text == "rgb";
    const std::string& aovs = v.at("aovs").text;
    opt.aovs = aovs.empty() ? std::vector<std::string>() : OIIO::Strutil::splits(aovs, ",");
    opt.tile = int(v.at("tile").integer);
    opt.tol = v.at("tol").real;
    opt.reltol = v.at("reltol").real;
    opt.test = v.at("equivalence").integer ? TwoSampleTest::Equivalence : TwoSampleTest::Difference;
    opt.referenceSpp = v.at("refspp").real;
    opt.rule = v.at("rule").text == "mitsuba" ? CompareOptions::Rule::Mitsuba
                                              : CompareOptions::Rule::Mcstat;
    opt.varianceFloor = v.at("varfloor").real;
    opt.passFraction = v.at("passfraction").real;
    opt.minPower = v.at("minpower").real;
    opt.identicalFails = v.at("identical").text == "fail";
    if (opt.minPower > 0.0 &&
        (opt.test != TwoSampleTest::Difference || opt.rule != CompareOptions::Rule::Mcstat)) {
        err = context +
              ": minpower is for the difference test of mcstat's rule (not with "
              "equivalence=1 or rule=mitsuba, whose verdicts state their own terms)";
        return false;
    }
    return true;
}

}  // namespace mcstat
