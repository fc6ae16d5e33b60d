// `mcstat --plan`: Jung's design questions answered from the analytic error rates (thesis eq. 4.13,
// 5.3, 5.9, 5.16, 5.22 and section 5.3.1) by the pure planner (include/mcstat/analysis/planner.h).
// It needs nothing on the stack and prints a table, or JSON with :json=1. docs/planner.md describes
// it.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "cli.h"
#include "mcstat/analysis/planner.h"

namespace mcstat::cli {

const std::vector<ParamSpec>& planParams() {
    static const std::vector<ParamSpec> params = [] {
        auto real = [](const std::string& name, double hi, const std::string& def,
                       const std::string& help) {
            ParamSpec s;
            s.name = name;
            s.type = ParamType::Real;
            s.min = 0.0;
            s.minOpen = true;
            s.max = hi;
            s.defaultValue = def;
            s.help = help;
            return s;
        };
        auto oddInt = [](const std::string& name, const std::string& def, const std::string& help) {
            ParamSpec s;
            s.name = name;
            s.type = ParamType::Int;
            s.min = 1;
            s.max = 101;
            s.odd = true;
            s.defaultValue = def;
            s.help = help;
            return s;
        };
        ParamSpec json;
        json.name = "json";
        json.type = ParamType::Flag;
        json.defaultValue = "0";
        json.help = "1 prints JSON instead of tables";
        return std::vector<ParamSpec>{
            real("np", 1e6, "1", "overestimated pixels tolerated per image"),
            real("width", 1e9, "1920", "image width in pixels"),
            real("height", 1e9, "1080", "image height in pixels"),
            json,
            oddInt("maxm", "21", "largest buffer count M considered"),
            oddInt("maxk", "15", "largest window side k considered"),
            oddInt("m", "3,5,7", "buffer counts of the hybrid tables, comma-separated"),
            real("p", 1.0, "0.001", "probability of a rare sample: the minimum spp to include one"),
            real("certainty", 1.0, "0.99", "confidence of including it, below 1"),
        };
    }();
    return params;
}

namespace {

using namespace mcstat::planner;

struct PlanOptions {
    double np = 0.0;
    double width = 0.0, height = 0.0;
    int maxm = 0, maxk = 0;
    std::vector<int> ms;
    double p = 0.0, certainty = 0.0;
    bool json = false;
};

/// Parses mods[key] (or the default) with `key`'s spec; a comma-separated list for "m".
bool value(const Modifiers& mods, const std::string& key, std::vector<ParamValue>& out,
           std::string& err) {
    const ParamSpec* spec = nullptr;
    for (const ParamSpec& s : planParams())
        if (s.name == key) spec = &s;
    auto it = mods.find(key);
    const std::string& text = it == mods.end() ? spec->defaultValue : it->second;
    out.clear();
    size_t start = 0;
    do {
        const size_t comma =
            key == "m" ? std::min(text.find(',', start), text.size()) : text.size();
        ParamValue v;
        if (!parseParamValue("--plan", *spec, text.substr(start, comma - start), v, err))
            return false;
        out.push_back(v);
        start = comma + 1;
    } while (start <= text.size());
    return true;
}

bool parse(const Modifiers& mods, PlanOptions& o, std::string& err) {
    std::vector<ParamValue> v;
    auto one = [&](const std::string& key) { return value(mods, key, v, err); };
    if (!one("np")) return false;
    o.np = v[0].real;
    if (!one("width")) return false;
    o.width = v[0].real;
    if (!one("height")) return false;
    o.height = v[0].real;
    if (!one("p")) return false;
    o.p = v[0].real;
    if (!one("certainty")) return false;
    o.certainty = v[0].real;
    if (o.certainty >= 1.0) {
        err =
            "--plan: certainty must be below 1 (no finite spp includes a sample with certainty 1)";
        return false;
    }
    if (!one("maxm")) return false;
    o.maxm = int(v[0].integer);
    if (!one("maxk")) return false;
    o.maxk = int(v[0].integer);
    if (!one("m")) return false;
    o.ms.clear();
    for (const ParamValue& m : v) o.ms.push_back(int(m.integer));
    if (!one("json")) return false;
    o.json = v[0].integer != 0;
    return true;
}

/// A probability for JSON: its value (0 when it underflows) and its log10 (finite down to
/// ~1e-308^k).
std::string jsonProb(const LogProb& r) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "{\"p\": %.6g, \"log10p\": %.6f}", r.value(), r.log10());
    return buf;
}

/// "1.3e-08" for representable values, "10^-612.3" below the double range.
std::string textProb(const LogProb& r) {
    char buf[64];
    if (r.value() > 0.0 || r.lnP == -HUGE_VAL)
        std::snprintf(buf, sizeof buf, "%.4g", r.value());
    else
        std::snprintf(buf, sizeof buf, "10^%.1f", r.log10());
    return buf;
}

struct Hybrid {
    int m = 0, kMif = 0, kDmf = 0;
};

}  // namespace

bool cmdPlan(State&, const std::string&, const std::vector<std::string>&, const Modifiers& mods,
             std::string& err) {
    PlanOptions o;
    if (!parse(mods, o, err)) return false;
    const double pixels = std::floor(o.width) * std::floor(o.height);
    const double target = 1.0 / std::max(pixels, 1.0);
    const int bestM = smallestBuffers(o.np, pixels, 101);
    std::vector<Hybrid> hybrids;
    for (int m : o.ms)
        hybrids.push_back({m, smallestWindow(Method::MPEMIF, m, o.np, pixels, o.maxk),
                           smallestWindow(Method::DMF3, m, o.np, pixels, o.maxk)});
    const int kMifAlone = smallestWindow(Method::MIF, 1, o.np, pixels, o.maxk);
    // Designs for the minimum-spp question: the recommended ones.
    std::vector<Design> sppDesigns;
    if (bestM) sppDesigns.push_back({Method::MPE, bestM, 1});
    for (const Hybrid& h : hybrids) {
        if (h.kMif) sppDesigns.push_back({Method::MPEMIF, h.m, h.kMif * h.kMif});
        if (h.kDmf) sppDesigns.push_back({Method::DMF3, h.m, h.kDmf * h.kDmf});
    }

    if (o.json) {
        std::printf(
            "{\n  \"np\": %.6g, \"width\": %.0f, \"height\": %.0f, \"pixels\": %.0f, "
            "\"target\": %.6g,\n  \"mpe\": [",
            o.np, std::floor(o.width), std::floor(o.height), pixels, target);
        for (int m = 1; m <= o.maxm; m += 2) {
            const LogProb r = errorRate({Method::MPE, m, 1}, o.np);
            std::printf("%s\n    {\"m\": %d, \"rate\": %s, \"expectedPixels\": %.6g}",
                        m > 1 ? "," : "", m, jsonProb(r).c_str(), pixels * r.value());
        }
        std::printf("\n  ],\n  \"recommendedM\": %d,\n  \"hybrids\": [", bestM);
        bool first = true;
        for (int m : o.ms) {
            for (int k = 1; k <= o.maxk; k += 2) {
                std::printf("%s\n    {\"m\": %d, \"k\": %d, \"mpeMif\": %s, \"dmf3\": %s}",
                            first ? "" : ",", m, k,
                            jsonProb(errorRate({Method::MPEMIF, m, k * k}, o.np)).c_str(),
                            jsonProb(errorRate({Method::DMF3, m, k * k}, o.np)).c_str());
                first = false;
            }
        }
        std::printf("\n  ],\n  \"mif\": [");
        for (int k = 1; k <= o.maxk; k += 2)
            std::printf("%s\n    {\"k\": %d, \"rate\": %s}", k > 1 ? "," : "", k,
                        jsonProb(errorRate({Method::MIF, 1, k * k}, o.np)).c_str());
        std::printf("\n  ],\n  \"smallestWindows\": [");
        for (size_t i = 0; i < hybrids.size(); ++i)
            std::printf("%s\n    {\"m\": %d, \"mpeMif\": %d, \"dmf3\": %d}", i ? "," : "",
                        hybrids[i].m, hybrids[i].kMif, hybrids[i].kDmf);
        std::printf(
            "\n  ],\n  \"smallestMifWindow\": %d,\n  \"minimumSpp\": {\"p\": %.6g, "
            "\"certainty\": %.6g, \"designs\": [",
            kMifAlone, o.p, o.certainty);
        for (size_t i = 0; i < sppDesigns.size(); ++i) {
            const SppPlan s = minimumSpp(sppDesigns[i], o.p, o.certainty);
            std::printf(
                "%s\n    {\"design\": \"%s\", \"feasible\": %s, \"np\": %.6g, "
                "\"sppLinear\": %.6g, \"sppExact\": %.6g}",
                i ? "," : "", designName(sppDesigns[i]).c_str(), s.feasible ? "true" : "false",
                s.np, s.sppLinear, s.sppExact);
        }
        std::printf("\n  ]}\n}\n");
        std::fflush(stdout);
        return true;
    }

    std::printf("Jung's analytic error rates at N*p = %g (thesis eq. 4.13, 5.3, 5.9, 5.16, 5.22)\n",
                o.np);
    std::printf(
        "image %.0f x %.0f = %.0f pixels: fewer than one overestimated pixel needs P < %.4g\n\n",
        std::floor(o.width), std::floor(o.height), pixels, target);
    std::printf("MPE(m), eq. 5.3: probability that the sample reaches the pixel\n");
    std::printf("  %5s  %-12s %s\n", "m", "P", "expected overestimated pixels");
    for (int m = 1; m <= o.maxm; m += 2) {
        const LogProb r = errorRate({Method::MPE, m, 1}, o.np);
        std::printf("  %5d  %-12s %.4g%s\n", m, textProb(r).c_str(), pixels * r.value(),
                    m == bestM ? "   <- recommended" : "");
    }
    if (bestM)
        std::printf("recommended M (smallest odd m, MPE alone): %d\n\n", bestM);
    else
        std::printf("recommended M: none up to 101 meets the target\n\n");
    std::printf("MPE(m)+MIF(k x k), eq. 5.16, and 3DMF(m x k x k), eq. 5.22\n");
    std::printf("  %5s  %5s  %-12s %-12s\n", "m", "k", "MPE+MIF", "3DMF");
    for (int m : o.ms)
        for (int k = 1; k <= o.maxk; k += 2)
            std::printf("  %5d  %5d  %-12s %-12s\n", m, k,
                        textProb(errorRate({Method::MPEMIF, m, k * k}, o.np)).c_str(),
                        textProb(errorRate({Method::DMF3, m, k * k}, o.np)).c_str());
    std::printf("smallest windows meeting the target (k <= %d):\n", o.maxk);
    for (const Hybrid& h : hybrids) {
        auto win = [](int k) { return k ? std::to_string(k) + "x" + std::to_string(k) : "none"; };
        std::printf("  m = %d: MPE+MIF %s, 3DMF %s\n", h.m, win(h.kMif).c_str(),
                    win(h.kDmf).c_str());
    }
    std::printf("  MIF alone (eq. 5.9): %s\n\n",
                kMifAlone ? (std::to_string(kMifAlone) + "x" + std::to_string(kMifAlone)).c_str()
                          : "none (MIF cannot remove a sample with N*p >= 0.5, eq. 5.11)");
    std::printf(
        "minimum spp to include a sample of probability p = %g with certainty %g "
        "(section 5.3.1)\n",
        o.p, o.certainty);
    std::printf("  %-22s %-10s %-14s %s\n", "design", "N*p", "spp (thesis)", "spp (exact)");
    for (const Design& d : sppDesigns) {
        const SppPlan s = minimumSpp(d, o.p, o.certainty);
        if (!s.feasible) {
            std::printf("  %-22s unreachable\n", designName(d).c_str());
            continue;
        }
        std::printf("  %-22s %-10.4g %-14.6g %.6g\n", designName(d).c_str(), s.np, s.sppLinear,
                    s.sppExact);
    }
    std::printf("(thesis: N*p/m per buffer, eq. 4.10 linearised; exact: 1 - (1 - p)^(N/m))\n");
    std::fflush(stdout);
    return true;
}

}  // namespace mcstat::cli
