// mergeStats: two renders of the same image combined as if one render had taken all samples
// (FORMAT.md "Merge"). Everything is computed in double from the stored float32 values and rounded
// once when stored.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <set>

#include "mcstat/core/moments.h"
#include "mcstat/stats_file.h"
#include "stats_layout.h"

namespace mcstat {

namespace {

std::vector<std::string> splitSeeds(const std::string& s) {
    std::vector<std::string> out;
    size_t start = 0;
    while (start <= s.size()) {
        size_t end = s.find(',', start);
        if (end == std::string::npos) end = s.size();
        std::string item = s.substr(start, end - start);
        const size_t b = item.find_first_not_of(" \t");
        const size_t e = item.find_last_not_of(" \t");
        if (b != std::string::npos) out.push_back(item.substr(b, e - b + 1));
        start = end + 1;
    }
    return out;
}

/// Count-weighted mean of two means; 0 when both weights are 0.
double weighted(double wa, double ma, double wb, double mb) {
    const double w = wa + wb;
    if (w == 0.0) return 0.0;
    if (wa == 0.0) return mb;  // also keeps a non-finite value of the empty side out
    if (wb == 0.0) return ma;
    return (wa * ma + wb * mb) / w;
}

/// Number of hits recovered from coverage A and count n, kept in [0, n] (also for a NaN A).
double hitsOf(float A, double n) { return std::fmax(0.0, std::fmin(n, std::round(double(A) * n))); }

bool checkCompatible(const StatsHeader& a, const StatsHeader& b, std::string& err) {
    const auto fail = [&](const std::string& what) {
        err = "cannot merge: " + what;
        return false;
    };
    if (a.width != b.width || a.height != b.height)
        return fail(
            fmt::format("sizes differ ({}x{} vs {}x{})", a.width, a.height, b.width, b.height));
    if (a.originX != b.originX || a.originY != b.originY)
        return fail(fmt::format("data window origins differ (({},{}) vs ({},{}))", a.originX,
                                a.originY, b.originX, b.originY));
    if (a.adaptiveM != b.adaptiveM)
        return fail(fmt::format("one input has adaptive M, the other M = {} in every pixel",
                                a.adaptiveM ? b.M : a.M));
    if (a.M != b.M)
        return fail(fmt::format("{} differs ({} vs {})", a.adaptiveM ? "M_max" : "M", a.M, b.M));
    if (a.assignment != b.assignment)
        return fail(fmt::format(
            "sample assignments differ ('{}' vs '{}'): buffer j holds a different kind of sample "
            "set in each (FORMAT.md, \"Sample-to-buffer assignment\"), so their sums would "
            "mean nothing",
            a.assignment, b.assignment));
    if (a.variance != b.variance)
        return fail(fmt::format("variance sources differ ('{}' vs '{}')", a.variance, b.variance));
    if (a.features != b.features)
        return fail(fmt::format("feature sets differ ('{}' vs '{}')", featureListText(a.features),
                                featureListText(b.features)));
    if (a.colorSpace != b.colorSpace)
        return fail(fmt::format("colour spaces differ ('{}' vs '{}')", a.colorSpace, b.colorSpace));
    // Version 5: the same render layout (FORMAT.md "Version 5", Merge).
    const auto shown = [](const std::string& s) { return detail::oneLine(s); };
    // The display window as a box; displayWidth 0 means the data window (equal in both here).
    const auto display = [](const StatsHeader& h) {
        return h.displayWidth > 0
                   ? std::array<int, 4>{h.displayX, h.displayY, h.displayWidth, h.displayHeight}
                   : std::array<int, 4>{h.originX, h.originY, h.width, h.height};
    };
    const auto displayText = [&](const StatsHeader& h) {
        const std::array<int, 4> d = display(h);
        return fmt::format("{}x{} at ({},{})", d[2], d[3], d[0], d[1]);
    };
    if (display(a) != display(b))
        return fail(
            fmt::format("display windows differ ({} vs {})", displayText(a), displayText(b)));
    for (size_t c = 0; c < 3; ++c)
        if (a.beautyNames[c] != b.beautyNames[c])
            return fail(fmt::format("beauty channel names differ ('{}' vs '{}')",
                                    shown(a.beautyNames[c]), shown(b.beautyNames[c])));
    if (a.beautyPart != b.beautyPart)
        return fail(fmt::format("beauty parts differ ('{}' vs '{}')", shown(a.beautyPart),
                                shown(b.beautyPart)));
    for (size_t i = 0; i < std::min(a.aovs.size(), b.aovs.size()); ++i) {
        const AovChannel &x = a.aovs[i], &y = b.aovs[i];
        if (x.name != y.name)
            return fail(
                fmt::format("AOV {} differs ('{}' vs '{}')", i, shown(x.name), shown(y.name)));
        if (x.cls != y.cls)
            return fail(fmt::format("AOV '{}' has class {} in one input, {} in the other",
                                    shown(x.name), aovClassName(x.cls), aovClassName(y.cls)));
        if (x.part != y.part)
            return fail(fmt::format("AOV '{}' comes from part '{}' in one input, '{}' in the other",
                                    shown(x.name), shown(x.part), shown(y.part)));
    }
    if (a.aovs.size() != b.aovs.size()) {
        const bool aLonger = a.aovs.size() > b.aovs.size();
        const AovChannel& extra = (aLonger ? a : b).aovs[std::min(a.aovs.size(), b.aovs.size())];
        return fail(fmt::format("AOV lists differ ({} vs {} AOVs; '{}' is only in the {} input)",
                                a.aovs.size(), b.aovs.size(), shown(extra.name),
                                aLonger ? "first" : "second"));
    }
    if (!a.seeds.empty() && !b.seeds.empty()) {
        const std::vector<std::string> sa = splitSeeds(a.seeds);
        const std::set<std::string> setA(sa.begin(), sa.end());
        for (const std::string& s : splitSeeds(b.seeds))
            if (setA.count(s))
                return fail(
                    fmt::format("seed {} is in both inputs (the same samples would be "
                                "counted twice)",
                                s));
    }
    if (a.spp > std::numeric_limits<int>::max() - b.spp) return fail("spp overflows");
    return true;
}

}  // namespace

double bufferVariance(const StatsImage& img, size_t p, size_t c, double mean) {
    const size_t k0 = img.bufferBegin(p), m = size_t(img.buffersOf(p));
    double ss = 0.0;
    size_t filled = 0;
    for (size_t j = 0; j < m; ++j) {
        const double n = img.bufferCount[k0 + j];
        if (n == 0.0) continue;
        const double d = double(img.bufferMean[(k0 + j) * 3 + c]) - mean;
        ss += n * d * d;
        ++filled;
    }
    return filled >= 2 ? ss / double(filled - 1) : std::numeric_limits<double>::quiet_NaN();
}

bool mergeHeaders(const StatsHeader& a, const StatsHeader& b, StatsHeader& out, std::string& err) {
    if (!checkCompatible(a, b, err)) return false;
    StatsHeader r = a;
    r.spp = a.spp + b.spp;
    if (a.seeds.empty() || b.seeds.empty())
        r.seeds = a.seeds + b.seeds;
    else
        r.seeds = a.seeds + "," + b.seeds;
    if (a.renderer != b.renderer) r.renderer = a.renderer + " + " + b.renderer;
    if (a.sources.empty() || b.sources.empty())
        r.sources = a.sources + b.sources;
    else
        r.sources = a.sources + "," + b.sources;
    r.formatVersion = std::max(a.formatVersion, b.formatVersion);
    out = std::move(r);
    return true;
}

bool mergeStats(const StatsImage& a, const StatsImage& b, StatsImage& out, std::string& err) {
    if (!validateStats(a, "first merge input", err) || !validateStats(b, "second merge input", err))
        return false;
    StatsImage r;
    if (!mergeHeaders(a.header, b.header, r.header, err)) return false;
    const size_t pixels = r.pixelCount();
    if (r.header.adaptiveM) {
        // Buffer j of a pixel holds the samples i = j mod m_p of each input; with different m_p the
        // buffers hold different sample sets and cannot be combined without the samples.
        std::vector<uint32_t> m(pixels);
        for (size_t p = 0; p < pixels; ++p) {
            if (a.buffersOf(p) != b.buffersOf(p)) {
                err = fmt::format(
                    "cannot merge: adaptive M differs at pixel ({}, {}): {} vs {} sub-buffers "
                    "(adaptive renders merge only with the same buffer count per pixel: "
                    "mcstat-render --m-strategy pilot with the same --pilot-seed, --pilot and "
                    "--m-max)",
                    r.header.originX + int64_t(p % size_t(r.header.width)),
                    r.header.originY + int64_t(p / size_t(r.header.width)), a.buffersOf(p),
                    b.buffersOf(p));
                return false;
            }
            m[p] = uint32_t(a.buffersOf(p));
        }
        if (!r.allocateAdaptive(m, err)) return false;
    } else if (!r.allocate(err)) {
        return false;
    }

    const size_t A = r.header.aovs.size();  // fixed M only (the header checks refuse others)
    std::vector<bool> isId(A);
    for (size_t i = 0; i < A; ++i) isId[i] = r.header.aovs[i].cls == AovClass::Id;
    for (size_t p = 0; p < pixels; ++p) {
        // Sub-buffers: count-weighted means, counts add.
        const size_t k0 = r.bufferBegin(p), m = size_t(r.buffersOf(p));
        for (size_t j = 0; j < m; ++j) {
            const size_t k = k0 + j;
            const double na = a.bufferCount[k], nb = b.bufferCount[k];
            for (size_t c = 0; c < 3; ++c)
                r.bufferMean[k * 3 + c] =
                    float(weighted(na, a.bufferMean[k * 3 + c], nb, b.bufferMean[k * 3 + c]));
            r.bufferCount[k] = float(na + nb);
            // AOVs (version 5): as the buffer means, except labels, taken whole from the input
            // whose buffer holds more samples (the first on ties, the second when the first is
            // empty).
            for (size_t i = 0; i < A; ++i) {
                const float va = a.aov[k * A + i], vb = b.aov[k * A + i];
                r.aov[k * A + i] =
                    isId[i] ? (na == 0.0 || nb > na ? vb : va) : float(weighted(na, va, nb, vb));
            }
        }
        // Moments: Chan et al.'s pooling (core/moments.h); M2 recovered as variance * (n - 1).
        const double na = a.count[p], nb = b.count[p], n = na + nb;
        r.count[p] = float(n);
        for (size_t c = 0; c < 3; ++c) {
            const size_t i = p * 3 + c;
            double mean = 0.0, var = 0.0;
            if (na == 0.0) {
                mean = b.mean[i];
                var = b.variance[i];
            } else if (nb == 0.0) {
                mean = a.mean[i];
                var = a.variance[i];
            } else {
                RunningMoments pooled = RunningMoments::fromVariance(na, a.mean[i], a.variance[i]);
                pooled.merge(RunningMoments::fromVariance(nb, b.mean[i], b.variance[i]));
                mean = pooled.mean;
                var = pooled.variance();
            }
            if (n == 0.0) mean = var = 0.0;
            // Version 3: a variance estimated from the buffers is re-estimated from the merged
            // buffers (its definition, FORMAT.md); an unknown one stays unknown.
            if (r.header.variance == kVarianceBuffers)
                var = bufferVariance(r, p, c, mean);
            else if (r.header.variance == kVarianceUnknown)
                var = std::numeric_limits<double>::quiet_NaN();
            r.mean[i] = float(mean);
            r.variance[i] = float(var);
            r.beauty[i] = float(mean);
        }
        // Features: N, P, Z weighted by hit counts, Albedo by sample counts, A recomputed.
        const double ha = hitsOf(a.coverage[p], na);
        const double hb = hitsOf(b.coverage[p], nb);
        for (size_t c = 0; c < 3; ++c) {
            const size_t i = p * 3 + c;
            r.normal[i] = float(weighted(ha, a.normal[i], hb, b.normal[i]));
            r.position[i] = float(weighted(ha, a.position[i], hb, b.position[i]));
            r.albedo[i] = float(weighted(na, a.albedo[i], nb, b.albedo[i]));
        }
        r.depth[p] = ha + hb == 0.0 ? std::numeric_limits<float>::infinity()
                                    : float(weighted(ha, a.depth[p], hb, b.depth[p]));
        r.coverage[p] = n == 0.0 ? 0.f : float((ha + hb) / n);
    }
    out = std::move(r);
    return true;
}

}  // namespace mcstat
