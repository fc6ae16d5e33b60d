// Ingest of renderer output (include/mcstat/ingest/ingest.h, docs/ingest.md): many renders of one
// image, one per seed, become one statistics file with one sub-buffer per file. The work is in four
// rooms (ingest_plan.h); this file holds the whole-image call and the parameters.
#include "mcstat/ingest/ingest.h"

#include <OpenImageIO/strutil.h>
#include <fmt/format.h>

#include <string>
#include <vector>

#include "ingest_plan.h"
#include "mcstat/core/color_space.h"
#include "mcstat/core/params.h"
#include "mcstat/core/untrusted_text.h"

namespace mcstat {

using namespace ingest_detail;
using OIIO::ImageInput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

bool ingestRenders(const std::vector<std::string>& paths, const IngestOptions& opt, StatsImage& out,
                   IngestReport& report, std::string& err) {
    report = IngestReport();
    IngestSource src;
    if (!src.init(paths, opt, err)) {
        report = src.report();
        return false;
    }
    StatsImage img;
    const bool ok = readAll(src, img, err);
    report = src.report();
    if (!ok) return false;
    out = std::move(img);
    return true;
}

const std::vector<ParamSpec>& ingestParams() {
    static const std::vector<ParamSpec> params = [] {
        std::vector<ParamSpec> m = {
            textParam("layer", "",
                      "the beauty layer, e.g. ViewLayer.Combined; default: plain R,G,B, else "
                      "Blender's <ViewLayer>.Combined, else an AOV named RGBA/beauty/Ci/C"),
            intParam("spp", 1, double(1 << 24), "",
                     "samples per file; default: the files' metadata (mcstat:spp, samplesPerPixel, "
                     "cycles.<ViewLayer>.samples)"),
            textParam("colorspace", "",
                      "the working space of untagged renders (no colorInteropID, chromaticities or "
                      "oiio:ColorSpace): lin_rec709 (default), ACEScg, ACES2065-1, lin_p3d65, "
                      "lin_rec2020 or their colorInteropID (docs/color.md)"),
            textParam("seed", "",
                      "PATTERN: each file's seed from its name, {seed} standing for the seed's "
                      "digits (e.g. seed_{seed}.exr; * and ? as in a glob); files also give it in "
                      "a Note stamp 'seed=N' (Blender, mcstat-blender); two files of one seed are "
                      "refused (docs/ingest.md, \"Seeds\")"),
            flagParam("aovs", "1",
                      "1 keeps alpha, light groups, passes, data and ID mattes per sub-buffer "
                      "(docs/aovs.md); 0 leaves out every channel but the beauty's R,G,B"),
        };
        for (const char* cls : {"alpha", "light", "data", "id"})
            m.push_back(
                textParam(cls, "",
                          std::string("GLOB,...: the matching channels or layers are of class ") +
                              cls + ", overriding the naming rules"));
        return m;
    }();
    return params;
}

bool parseIngestOptions(const std::map<std::string, std::string>& kv, IngestOptions& opt,
                        std::string& err, const std::string& context) {
    std::map<std::string, std::string> mods = kv;
    if (!checkModifiers(context, ingestParams(), mods, err)) return false;
    for (const auto& [k, v] : mods) {
        ParamValue value;  // checked above; parsed again for its typed value
        for (const ParamSpec& p : ingestParams())
            if (p.name == k && !parseParamValue(context, p, v, value, err)) return false;
        if (k == "layer") {
            opt.layer = v;
        } else if (k == "spp") {
            opt.spp = v.empty() ? 0 : value.integer;
        } else if (k == "seed") {
            std::string problem;
            if (!v.empty() && !checkSeedPattern(v, problem)) {
                err = context + ": " + problem;
                return false;
            }
            opt.seedPattern = v;
        } else if (k == "aovs") {
            opt.aovs = value.integer != 0;
        } else if (k == "colorspace" && !v.empty()) {
            const WorkingSpace* ws = findWorkingSpace(v);
            if (!ws) {
                err = fmt::format("{}: colorspace '{}' is unknown (known: {})", context,
                                  printable(v), knownWorkingSpaceNames());
                return false;
            }
            opt.colorSpace = ws->name;
        } else if (AovClass cls; parseAovClass(k, cls)) {
            // :id=GLOB,GLOB  :data=...  :light=...  :alpha=...  (docs/aovs.md, "Classes")
            for (const std::string& g : OIIO::Strutil::splits(v, ","))
                if (!g.empty()) opt.classOverrides.emplace_back(g, cls);
        }
    }
    return true;
}

}  // namespace mcstat
