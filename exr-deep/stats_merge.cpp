// mergeStats: renders of the same image combined as if one render had taken all their samples
// (FORMAT.md "Merge"), N inputs in one pass; mergeOrder, the canonical order of the inputs that
// makes an N-way merge's tree, and so its bytes, independent of the order files were given in.
// Everything is computed in double from the stored float32 values and rounded once when stored.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>

#include "mcstat/core/moments.h"
#include "mcstat/core/parallel.h"
#include "mcstat/exr-deep/stats_file.h"
#include "stats_layout.h"

namespace mcstat {

namespace {

/// The items of a list joined by `sep`: seeds "1, 2" (trimmed, empty items dropped) or renderer
/// names "a + b" (kept as they are).
std::vector<std::string> splitList(const std::string& s, const std::string& sep, bool trim) {
    std::vector<std::string> out;
    size_t start = 0;
    while (start <= s.size()) {
        size_t end = s.find(sep, start);
        if (end == std::string::npos) end = s.size();
        std::string item = s.substr(start, end - start);
        if (trim) {
            const size_t first = item.find_first_not_of(" \t");
            if (first == std::string::npos)
                item.clear();
            else
                item = item.substr(first, item.find_last_not_of(" \t") - first + 1);
        }
        if (!trim || !item.empty()) out.push_back(item);
        start = end + sep.size();
    }
    return out;
}

std::vector<std::string> splitSeeds(const std::string& s) { return splitList(s, ",", true); }

/// Number of hits recovered from coverage A and count n, kept in [0, n] (also for a NaN A).
double hitsOf(float A, double n) { return std::fmax(0.0, std::fmin(n, std::round(double(A) * n))); }

/// The weighted mean of values x_i with weights w_i, summed in input order in double over the
/// inputs with w_i > 0 only (a non-finite value of an empty input stays out); 0 when every weight
/// is 0. One input of weight > 0 gives its value exactly (n x / n is exact for a float x and an
/// integral n < 2^24).
struct WeightedMean {
    double sum = 0.0, weight = 0.0;
    void add(double w, double x) {
        if (w == 0.0) return;
        sum += w * x;
        weight += w;
    }
    double value() const { return weight == 0.0 ? 0.0 : sum / weight; }
};

/// Whether seed a sorts before seed b: decimal numbers by value, before any other seed (an
/// ingested file's "h<hash>"), which sort as text.
bool seedLess(const std::string& a, const std::string& b) {
    const auto isNumber = [](const std::string& s) {
        return !s.empty() &&
               std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
    };
    const bool na = isNumber(a), nb = isNumber(b);
    if (na != nb) return na;
    if (!na) return a < b;
    const auto digits = [](const std::string& s) {
        const size_t i = s.find_first_not_of('0');
        return i == std::string::npos ? std::string() : s.substr(i);
    };
    const std::string da = digits(a), db = digits(b);
    return da.size() != db.size() ? da.size() < db.size() : da < db;
}

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
            printable(a.assignment), printable(b.assignment)));
    if (a.variance != b.variance)
        return fail(fmt::format("variance sources differ ('{}' vs '{}')", printable(a.variance),
                                printable(b.variance)));
    if (a.features != b.features)
        return fail(fmt::format("feature sets differ ('{}' vs '{}')", featureListText(a.features),
                                featureListText(b.features)));
    if (a.colorSpace != b.colorSpace)
        return fail(fmt::format("colour spaces differ ('{}' vs '{}')", printable(a.colorSpace),
                                printable(b.colorSpace)));
    // Version 5: the same render layout (FORMAT.md "Version 5", Merge).
    const auto shown = [](const std::string& s) { return printable(s); };
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

std::vector<size_t> mergeOrder(const std::vector<const StatsHeader*>& in) {
    std::vector<std::vector<std::string>> keys(in.size());
    for (size_t i = 0; i < in.size(); ++i) keys[i] = splitSeeds(in[i]->seeds);
    std::vector<size_t> order(in.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](size_t x, size_t y) {
        return std::lexicographical_compare(keys[x].begin(), keys[x].end(), keys[y].begin(),
                                            keys[y].end(), seedLess);
    });
    return order;
}

bool mergeHeaders(const std::vector<const StatsHeader*>& in, StatsHeader& out, std::string& err,
                  const std::vector<std::string>& names) {
    const auto nameOf = [&](size_t i) {
        return i < names.size() ? names[i] : fmt::format("input {}", i + 1);
    };
    if (in.empty()) {
        err = "cannot merge: no input";
        return false;
    }
    // Whether a pixel of the merge is heavy-tailed depends on its merged buffers, which a compact
    // file dropped where its own were light-tailed: the merge could not know which to keep.
    for (size_t i = 0; i < in.size(); ++i)
        if (in[i]->compact) {
            err = fmt::format(
                "cannot merge: {} is a compact file, whose pixels without heavy tails keep only "
                "their mean, and whether a merged pixel is heavy-tailed cannot be known without "
                "its buffers: merge the full files, then --compact",
                nameOf(i));
            return false;
        }
    for (size_t i = 1; i < in.size(); ++i)
        if (!checkCompatible(*in[0], *in[i], err)) {
            if (in.size() > 2 || !names.empty())
                err = fmt::format("{} and {}: {}", nameOf(0), nameOf(i), err);
            return false;
        }
    // A seed in two inputs: the same samples would be counted twice.
    std::map<std::string, size_t> seen;
    for (size_t i = 0; i < in.size(); ++i)
        for (const std::string& s : splitSeeds(in[i]->seeds)) {
            const auto [it, fresh] = seen.emplace(s, i);
            if (!fresh && it->second != i) {
                err = fmt::format(
                    "cannot merge: seed {} is in both {} and {} (the same samples would be "
                    "counted twice)",
                    s, nameOf(it->second), nameOf(i));
                if (in.size() == 2 && names.empty())
                    err = fmt::format(
                        "cannot merge: seed {} is in both inputs (the same samples would be "
                        "counted twice)",
                        s);
                return false;
            }
        }
    StatsHeader r = *in[0];
    std::vector<std::string> seeds, sources, renderers, scenes;
    r.spp = 0;
    for (const StatsHeader* h : in) {
        if (h->spp > std::numeric_limits<int>::max() - r.spp) {
            err = "cannot merge: spp overflows";
            return false;
        }
        r.spp += h->spp;
        if (!h->seeds.empty()) seeds.push_back(h->seeds);
        if (!h->sources.empty()) sources.push_back(h->sources);
        // Each name once, in the order first seen: the same text for any grouping of the inputs.
        for (const std::string& name : splitList(h->renderer, " + ", false))
            if (std::find(renderers.begin(), renderers.end(), name) == renderers.end())
                renderers.push_back(name);
        for (const std::string& name : splitList(h->scene, " + ", true))
            if (std::find(scenes.begin(), scenes.end(), name) == scenes.end())
                scenes.push_back(name);
        r.formatVersion = std::max(r.formatVersion, h->formatVersion);
    }
    const auto join = [](const std::vector<std::string>& v, const char* sep) {
        std::string s;
        for (size_t i = 0; i < v.size(); ++i) s += (i ? sep : "") + v[i];
        return s;
    };
    r.seeds = join(seeds, ",");
    r.sources = join(sources, ",");
    r.renderer = join(renderers, " + ");
    r.scene = join(scenes, " + ");
    out = std::move(r);
    return true;
}

bool mergeHeaders(const StatsHeader& a, const StatsHeader& b, StatsHeader& out, std::string& err) {
    return mergeHeaders(std::vector<const StatsHeader*>{&a, &b}, out, err);
}

namespace {

/// Allocates the merged image's buffers: the inputs' M, which with adaptive M must agree pixel by
/// pixel.
bool allocateMerged(const std::vector<const StatsImage*>& in, StatsImage& r, std::string& err) {
    const size_t n = in.size(), pixels = r.pixelCount();
    if (!r.header.adaptiveM) return r.allocate(err);
    // Buffer j of a pixel holds the samples i = j mod m_p of each input; with different m_p the
    // buffers hold different sample sets and cannot be combined without the samples.
    std::vector<uint32_t> m(pixels);
    for (size_t p = 0; p < pixels; ++p) {
        for (size_t i = 1; i < n; ++i)
            if (in[i]->buffersOf(p) != in[0]->buffersOf(p)) {
                err = fmt::format(
                    "cannot merge: adaptive M differs at pixel ({}, {}): {} vs {} sub-buffers "
                    "(adaptive renders merge only with the same buffer count per pixel: "
                    "mcstat-render --m-strategy pilot with the same --pilot-seed, --pilot and "
                    "--m-max)",
                    r.header.originX + int64_t(p % size_t(r.header.width)),
                    r.header.originY + int64_t(p / size_t(r.header.width)), in[0]->buffersOf(p),
                    in[i]->buffersOf(p));
                return false;
            }
        m[p] = uint32_t(in[0]->buffersOf(p));
    }
    return r.allocateAdaptive(m, err);
}

/// Pixel p's sub-buffers: count-weighted means, counts add; with their AOVs.
void mergeBuffers(const std::vector<const StatsImage*>& in, const std::vector<bool>& isId,
                  StatsImage& r, size_t p) {
    const size_t n = in.size(), A = isId.size();
    const size_t k0 = r.bufferBegin(p), m = size_t(r.buffersOf(p));
    for (size_t j = 0; j < m; ++j) {
        const size_t k = k0 + j;
        WeightedMean mean[3];
        double count = 0.0;
        for (const StatsImage* s : in) {
            const size_t ks = s->bufferBegin(p) + j;
            const double w = s->bufferCount[ks];
            for (size_t c = 0; c < 3; ++c) mean[c].add(w, s->bufferMean[ks * 3 + c]);
            count += w;
        }
        for (size_t c = 0; c < 3; ++c) r.bufferMean[k * 3 + c] = float(mean[c].value());
        r.bufferCount[k] = float(count);
        // AOVs (version 5): as the buffer means, except labels, taken whole from the
        // input whose buffer holds the most samples (the first such; an empty buffer
        // never wins over a later one, so the last input's when all are empty).
        // That input depends on the buffer only: found once for all its labels.
        size_t best = 0;
        if (A > 0)
            for (size_t i = 1; i < n; ++i)
                if (in[best]->bufferCount[k] == 0.f ||
                    in[i]->bufferCount[k] > in[best]->bufferCount[k])
                    best = i;
        for (size_t a = 0; a < A; ++a) {
            if (isId[a]) {
                r.aov[k * A + a] = in[best]->aov[k * A + a];
            } else {
                WeightedMean v;
                for (const StatsImage* s : in) v.add(s->bufferCount[k], s->aov[k * A + a]);
                r.aov[k * A + a] = float(v.value());
            }
        }
    }
}

/// Pixel p's count, mean, variance and beauty; returns the merged count (in double).
double mergeMoments(const std::vector<const StatsImage*>& in, StatsImage& r, size_t p) {
    const size_t n = in.size();
    // Moments: the pooled mean and sum of squared deviations of every input's samples,
    // M2 = sum_i [M2_i + n_i (mean_i - mean)^2] with M2_i = variance_i (n_i - 1), the
    // one-pass form of Chan et al.'s pairwise update (core/moments.h).
    double total = 0.0;
    for (const StatsImage* s : in) total += s->count[p];
    r.count[p] = float(total);
    size_t nonEmpty = 0, only = 0;
    for (size_t i = 0; i < n; ++i)
        if (in[i]->count[p] > 0.f) {
            ++nonEmpty;
            only = i;
        }
    for (size_t c = 0; c < 3; ++c) {
        const size_t e = p * 3 + c;
        double mean = 0.0, var = 0.0;
        if (nonEmpty == 1) {  // that input's values, bit for bit
            mean = in[only]->mean[e];
            var = in[only]->variance[e];
        } else if (nonEmpty > 1) {
            WeightedMean wm;
            for (const StatsImage* s : in) wm.add(s->count[p], s->mean[e]);
            mean = wm.value();
            double m2 = 0.0;
            for (const StatsImage* s : in) {
                const double ni = s->count[p];
                if (ni == 0.0) continue;
                const double d = double(s->mean[e]) - mean;
                m2 += RunningMoments::fromVariance(ni, s->mean[e], s->variance[e]).m2 + ni * d * d;
            }
            var = total > 1.0 ? m2 / (total - 1.0) : 0.0;
        }
        // Version 3: a variance estimated from the buffers is re-estimated from the
        // merged buffers (its definition, FORMAT.md); an unknown one stays unknown.
        if (r.header.variance == kVarianceBuffers)
            var = bufferVariance(r, p, c, mean);
        else if (r.header.variance == kVarianceUnknown)
            var = std::numeric_limits<double>::quiet_NaN();
        r.mean[e] = float(mean);
        r.variance[e] = float(var);
        r.beauty[e] = float(mean);
    }
    return total;
}

/// Pixel p's features: N, P, Z weighted by hit counts, Albedo by sample counts, A recomputed
/// from the merged count `total`. `hits` is scratch of one entry per input.
void mergeFeatures(const std::vector<const StatsImage*>& in, double total, StatsImage& r, size_t p,
                   std::vector<double>& hits) {
    const size_t n = in.size();
    double allHits = 0.0;
    for (size_t i = 0; i < n; ++i) {
        hits[i] = hitsOf(in[i]->coverage[p], in[i]->count[p]);
        allHits += hits[i];
    }
    for (size_t c = 0; c < 3; ++c) {
        const size_t e = p * 3 + c;
        WeightedMean normal, position, albedo;
        for (size_t i = 0; i < n; ++i) {
            normal.add(hits[i], in[i]->normal[e]);
            position.add(hits[i], in[i]->position[e]);
            albedo.add(in[i]->count[p], in[i]->albedo[e]);
        }
        r.normal[e] = float(normal.value());
        r.position[e] = float(position.value());
        r.albedo[e] = float(albedo.value());
    }
    WeightedMean depth;
    for (size_t i = 0; i < n; ++i) depth.add(hits[i], in[i]->depth[p]);
    r.depth[p] = allHits == 0.0 ? std::numeric_limits<float>::infinity() : float(depth.value());
    r.coverage[p] = total == 0.0 ? 0.f : float(allHits / total);
}

}  // namespace

bool mergeStats(const std::vector<const StatsImage*>& in, StatsImage& out, std::string& err,
                int nthreads) {
    const size_t n = in.size();
    std::vector<const StatsHeader*> headers;
    for (size_t i = 0; i < n; ++i) {
        const std::string what = n == 2 ? (i == 0 ? "first merge input" : "second merge input")
                                        : fmt::format("merge input {}", i + 1);
        if (!validateStats(*in[i], what, err)) return false;
        headers.push_back(&in[i]->header);
    }
    StatsImage r;
    if (!mergeHeaders(headers, r.header, err)) return false;
    if (!allocateMerged(in, r, err)) return false;

    const size_t A = r.header.aovs.size();  // fixed M only (the header checks refuse others)
    std::vector<bool> isId(A);
    for (size_t a = 0; a < A; ++a) isId[a] = r.header.aovs[a].cls == AovClass::Id;
    // Per pixel, independent of every other pixel: any split over threads gives the same bits.
    parallelFor(0, int64_t(r.pixelCount()), 0, nthreads, [&](int64_t pBegin, int64_t pEnd) {
        std::vector<double> hits(n);
        for (size_t p = size_t(pBegin); p < size_t(pEnd); ++p) {
            mergeBuffers(in, isId, r, p);
            const double total = mergeMoments(in, r, p);
            mergeFeatures(in, total, r, p, hits);
        }
    });
    out = std::move(r);
    return true;
}

bool mergeStats(const StatsImage& a, const StatsImage& b, StatsImage& out, std::string& err) {
    return mergeStats(std::vector<const StatsImage*>{&a, &b}, out, err, 1);
}

}  // namespace mcstat
