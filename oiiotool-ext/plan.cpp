// `mcstat --plan`: Jung's design questions answered from the analytic error rates (thesis eq. 4.13,
// 5.3, 5.9, 5.16, 5.22 and section 5.3.1) by the pure planner (include/mcstat/planner.h). It needs
// nothing on the stack and prints a table, or JSON with :json=1. docs/planner.md describes it.
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "cli.h"
#include "mcstat/planner.h"

namespace mcstat::cli {

namespace {

using namespace mcstat::planner;

struct PlanOptions {
    double np = 1.0;
    double width = 1920, height = 1080;
    int maxm = 21, maxk = 15;
    std::vector<int> ms{3, 5, 7};
    double p = 1e-3, certainty = 0.99;
    bool json = false;
};

bool number(const Modifiers& mods, const std::string& key, double lo, double hi, double& out,
            std::string& err) {
    auto it = mods.find(key);
    if (it == mods.end()) return true;
    errno = 0;
    char* end = nullptr;
    const double v = std::strtod(it->second.c_str(), &end);
    if (it->second.empty() || *end != '\0' || errno != 0 || !std::isfinite(v) || !(v > lo) ||
        v > hi) {
        err = "--plan: " + key + " must be a number in (" + std::to_string(lo) + ", " +
              std::to_string(hi) + "], not '" + it->second + "'";
        return false;
    }
    out = v;
    return true;
}

bool oddInt(const std::string& key, const std::string& s, int lo, int hi, int& out,
            std::string& err) {
    errno = 0;
    char* end = nullptr;
    const long v = std::strtol(s.c_str(), &end, 10);
    if (s.empty() || *end != '\0' || errno != 0 || v < lo || v > hi || v % 2 == 0) {
        err = "--plan: " + key + " must be an odd integer in [" + std::to_string(lo) + ", " +
              std::to_string(hi) + "], not '" + s + "'";
        return false;
    }
    out = int(v);
    return true;
}

bool parse(const Modifiers& mods, PlanOptions& o, std::string& err) {
    if (!number(mods, "np", 0.0, 1e6, o.np, err) ||
        !number(mods, "width", 0.0, 1e9, o.width, err) ||
        !number(mods, "height", 0.0, 1e9, o.height, err) ||
        !number(mods, "p", 0.0, 1.0, o.p, err) ||
        !number(mods, "certainty", 0.0, 1.0, o.certainty, err))
        return false;
    if (o.certainty >= 1.0) {
        err =
            "--plan: certainty must be below 1 (no finite spp includes a sample with certainty 1)";
        return false;
    }
    if (mods.count("maxm") && !oddInt("maxm", mods.at("maxm"), 1, 101, o.maxm, err)) return false;
    if (mods.count("maxk") && !oddInt("maxk", mods.at("maxk"), 1, 101, o.maxk, err)) return false;
    if (mods.count("m")) {
        o.ms.clear();
        const std::string& list = mods.at("m");
        size_t start = 0;
        while (start <= list.size()) {
            const size_t comma = std::min(list.find(',', start), list.size());
            int m = 0;
            if (!oddInt("m", list.substr(start, comma - start), 1, 101, m, err)) return false;
            o.ms.push_back(m);
            start = comma + 1;
        }
    }
    auto it = mods.find("json");
    if (it != mods.end()) {
        if (it->second != "0" && it->second != "1") {
            err = "--plan: json must be 0 or 1, not '" + it->second + "'";
            return false;
        }
        o.json = it->second == "1";
    }
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
