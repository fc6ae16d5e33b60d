// `mcstat --plan`: Jung's design questions answered from the analytic error rates (thesis eq. 4.13,
// 5.3, 5.9, 5.16, 5.22 and section 5.3.1) by the pure planner (include/mcstat/analysis/planner.h).
// It needs nothing on the stack and prints a table, or JSON with :json=1. docs/planner.md describes
// it.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli.h"
#include "mcstat/analysis/planner.h"

namespace mcstat::cli {

const std::vector<ParamSpec>& planParams() {
    static const std::vector<ParamSpec> params = [] {
        auto real = [](const std::string& name, double hi, const std::string& def,
                       const std::string& help) {
            return realParam(name, 0.0, hi, true, def, help);
        };
        auto oddInt = [](const std::string& name, const std::string& def, const std::string& help) {
            ParamSpec s = intParam(name, 1, 101, def, help);
            s.odd = true;
            return s;
        };
        ParamSpec m = oddInt("m", "3,5,7", "buffer counts of the hybrid tables, comma-separated");
        m.list = true;
        return std::vector<ParamSpec>{
            real("np", 1e6, "1", "overestimated pixels tolerated per image"),
            real("width", 1e9, "1920", "image width in pixels"),
            real("height", 1e9, "1080", "image height in pixels"),
            flagParam("json", "0", "1 prints JSON instead of tables"),
            oddInt("maxm", "21", "largest buffer count M considered"),
            oddInt("maxk", "15", "largest window side k considered"),
            m,
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

/// The modifiers (checked by the command table against planParams(), defaults filled in).
bool parse(const Modifiers& mods, PlanOptions& o, std::string& err) {
    const std::vector<ParamSpec>& specs = planParams();
    const auto value = [&](const std::string& key) { return modifierValue(specs, mods, key); };
    o.np = value("np").real;
    o.width = value("width").real;
    o.height = value("height").real;
    o.p = value("p").real;
    o.certainty = value("certainty").real;
    if (o.certainty >= 1.0) {
        err =
            "--plan: certainty must be below 1 (no finite spp includes a sample with certainty 1)";
        return false;
    }
    o.maxm = int(value("maxm").integer);
    o.maxk = int(value("maxk").integer);
    o.ms.clear();
    for (const ParamValue& m : modifierList(specs, mods, "m")) o.ms.push_back(int(m.integer));
    o.json = value("json").integer != 0;
    return true;
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

/// The planner's answers, shared by the table and the JSON.
struct PlanAnswers {
    double pixels = 0.0;  ///< floor(width) x floor(height)
    double target = 0.0;  ///< the error rate below which fewer than one pixel is expected wrong
    int bestM = 0;        ///< smallest odd M meeting the target with MPE alone, 0: none
    std::vector<Hybrid> hybrids;     ///< per buffer count m of the tables: the smallest windows
    int kMifAlone = 0;               ///< smallest window of MIF alone, 0: none
    std::vector<Design> sppDesigns;  ///< the recommended designs, for the minimum-spp question
};

/// Jung's design questions answered for `o`.
PlanAnswers answer(const PlanOptions& o) {
    PlanAnswers a;
    a.pixels = std::floor(o.width) * std::floor(o.height);
    a.target = 1.0 / std::max(a.pixels, 1.0);
    a.bestM = smallestBuffers(o.np, a.pixels, 101);
    for (int m : o.ms)
        a.hybrids.push_back({m, smallestWindow(Method::MPEMIF, m, o.np, a.pixels, o.maxk),
                             smallestWindow(Method::DMF3, m, o.np, a.pixels, o.maxk)});
    a.kMifAlone = smallestWindow(Method::MIF, 1, o.np, a.pixels, o.maxk);
    if (a.bestM) a.sppDesigns.push_back({Method::MPE, a.bestM, 1});
    for (const Hybrid& h : a.hybrids) {
        if (h.kMif) a.sppDesigns.push_back({Method::MPEMIF, h.m, h.kMif * h.kMif});
        if (h.kDmf) a.sppDesigns.push_back({Method::DMF3, h.m, h.kDmf * h.kDmf});
    }
    return a;
}

// ---- JSON (docs/planner.md, "JSON fields") ------------------------------------------------------

/// ordered_json keeps the keys in the order written, the order docs/planner.md lists them.
using Json = nlohmann::ordered_json;

/// A probability: its value (0 when it underflows) and its log10 (finite down to ~1e-308^k).
Json jsonProb(const LogProb& r) { return Json{{"p", r.value()}, {"log10p", r.log10()}}; }

/// MPE(m), eq. 5.3, for m = 1, 3, ..., maxm: its error rate and the pixels it would spoil.
Json jsonMpe(const PlanOptions& o, double pixels) {
    Json rows = Json::array();
    for (int m = 1; m <= o.maxm; m += 2) {
        const LogProb r = errorRate({Method::MPE, m, 1}, o.np);
        rows.push_back({{"m", m}, {"rate", jsonProb(r)}, {"expectedPixels", pixels * r.value()}});
    }
    return rows;
}

/// MPE(m)+MIF(k x k), eq. 5.16, and 3DMF(m x k x k), eq. 5.22, for each m asked and odd k.
Json jsonHybrids(const PlanOptions& o) {
    Json rows = Json::array();
    for (int m : o.ms)
        for (int k = 1; k <= o.maxk; k += 2)
            rows.push_back({{"m", m},
                            {"k", k},
                            {"mpeMif", jsonProb(errorRate({Method::MPEMIF, m, k * k}, o.np))},
                            {"dmf3", jsonProb(errorRate({Method::DMF3, m, k * k}, o.np))}});
    return rows;
}

/// MIF(k x k) alone, eq. 5.9, for odd k.
Json jsonMif(const PlanOptions& o) {
    Json rows = Json::array();
    for (int k = 1; k <= o.maxk; k += 2)
        rows.push_back({{"k", k}, {"rate", jsonProb(errorRate({Method::MIF, 1, k * k}, o.np))}});
    return rows;
}

/// Section 5.3.1 for each recommended design: the smallest spp including the rare sample.
Json jsonMinimumSpp(const PlanOptions& o, const std::vector<Design>& designs) {
    Json list = Json::array();
    for (const Design& d : designs) {
        const SppPlan s = minimumSpp(d, o.p, o.certainty);
        list.push_back({{"design", designName(d)},
                        {"feasible", s.feasible},
                        {"np", s.np},
                        {"sppLinear", s.sppLinear},
                        {"sppExact", s.sppExact}});
    }
    return Json{{"p", o.p}, {"certainty", o.certainty}, {"designs", std::move(list)}};
}

void printPlanJson(const PlanOptions& o, const PlanAnswers& a) {
    Json j;
    j["np"] = o.np;
    // Whole numbers: integers in JSON (as %.0f printed them), not 1920.0.
    j["width"] = int64_t(std::floor(o.width));
    j["height"] = int64_t(std::floor(o.height));
    j["pixels"] = int64_t(a.pixels);
    j["target"] = a.target;
    j["mpe"] = jsonMpe(o, a.pixels);
    j["recommendedM"] = a.bestM;
    j["hybrids"] = jsonHybrids(o);
    j["mif"] = jsonMif(o);
    Json windows = Json::array();
    for (const Hybrid& h : a.hybrids)
        windows.push_back({{"m", h.m}, {"mpeMif", h.kMif}, {"dmf3", h.kDmf}});
    j["smallestWindows"] = std::move(windows);
    j["smallestMifWindow"] = a.kMifAlone;
    j["minimumSpp"] = jsonMinimumSpp(o, a.sppDesigns);
    std::printf("%s\n", j.dump(2).c_str());
    std::fflush(stdout);
}

// ---- the table ----------------------------------------------------------------------------------

/// The error rates: MPE(m) with the recommended M, MPE+MIF and 3DMF, the smallest windows.
void printRateTables(const PlanOptions& o, const PlanAnswers& a) {
    std::printf("Jung's analytic error rates at N*p = %g (thesis eq. 4.13, 5.3, 5.9, 5.16, 5.22)\n",
                o.np);
    std::printf(
        "image %.0f x %.0f = %.0f pixels: fewer than one overestimated pixel needs P < %.4g\n\n",
        std::floor(o.width), std::floor(o.height), a.pixels, a.target);
    std::printf("MPE(m), eq. 5.3: probability that the sample reaches the pixel\n");
    std::printf("  %5s  %-12s %s\n", "m", "P", "expected overestimated pixels");
    for (int m = 1; m <= o.maxm; m += 2) {
        const LogProb r = errorRate({Method::MPE, m, 1}, o.np);
        std::printf("  %5d  %-12s %.4g%s\n", m, textProb(r).c_str(), a.pixels * r.value(),
                    m == a.bestM ? "   <- recommended" : "");
    }
    if (a.bestM)
        std::printf("recommended M (smallest odd m, MPE alone): %d\n\n", a.bestM);
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
    for (const Hybrid& h : a.hybrids) {
        auto win = [](int k) { return k ? std::to_string(k) + "x" + std::to_string(k) : "none"; };
        std::printf("  m = %d: MPE+MIF %s, 3DMF %s\n", h.m, win(h.kMif).c_str(),
                    win(h.kDmf).c_str());
    }
    std::printf("  MIF alone (eq. 5.9): %s\n\n",
                a.kMifAlone
                    ? (std::to_string(a.kMifAlone) + "x" + std::to_string(a.kMifAlone)).c_str()
                    : "none (MIF cannot remove a sample with N*p >= 0.5, eq. 5.11)");
}

/// Section 5.3.1: the minimum spp of each recommended design.
void printSppTable(const PlanOptions& o, const PlanAnswers& a) {
    std::printf(
        "minimum spp to include a sample of probability p = %g with certainty %g "
        "(section 5.3.1)\n",
        o.p, o.certainty);
    std::printf("  %-22s %-10s %-14s %s\n", "design", "N*p", "spp (thesis)", "spp (exact)");
    for (const Design& d : a.sppDesigns) {
        const SppPlan s = minimumSpp(d, o.p, o.certainty);
        if (!s.feasible) {
            std::printf("  %-22s unreachable\n", designName(d).c_str());
            continue;
        }
        std::printf("  %-22s %-10.4g %-14.6g %.6g\n", designName(d).c_str(), s.np, s.sppLinear,
                    s.sppExact);
    }
    std::printf("(thesis: N*p/m per buffer, eq. 4.10 linearised; exact: 1 - (1 - p)^(N/m))\n");
}

}  // namespace

bool cmdPlan(State&, const std::string&, const std::vector<std::string>&, const Modifiers& mods,
             std::string& err) {
    PlanOptions o;
    if (!parse(mods, o, err)) return false;
    const PlanAnswers a = answer(o);
    if (o.json) {
        printPlanJson(o, a);
        return true;
    }
    printRateTables(o, a);
    printSppTable(o, a);
    std::fflush(stdout);
    return true;
}

}  // namespace mcstat::cli
