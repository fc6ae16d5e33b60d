// `mcstat FILE --rpf` and the plugin's `?estimator=rpf` (docs/rpf.md): random parameter filtering
// over part `records`, read through SampleSource by blocks of output rows with the passes' halo
// (55 rows each side for the report's boxes), so memory holds a window of rows, never the image.
// Channels are found by name (FORMAT.md "Per-sample fields"): colour R, G, B; screen position
// screen.x, screen.y; random parameters rand.*; scene features N1, P1, T1, N2, P2 (and feat.*).
#include "mcstat/filters/samples/rpf.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "mcstat/filters/samples/rpf_filter.h"
#include "mcstat/sample_records.h"

namespace mcstat {

namespace {

/// maps=1 (Fig. 6), per pixel from pass 0: W_c^r (eq. 11), W_f^r of the texture value (eq. 9,
/// mean over T1.*), mean alpha (eq. 15), mean beta of T1 (eq. 16) and |N|.
const std::vector<std::string> kMapChannels{"rpf.colourOnRandom", "rpf.textureOnRandom",
                                            "rpf.alpha", "rpf.textureBeta", "rpf.neighbours"};

bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

bool isFeatureChannel(const std::string& c) {
    for (const char* f : {"N1.", "P1.", "T1.", "N2.", "P2."})
        if (startsWith(c, f)) return true;
    return startsWith(c, kFeaturePrefix);
}

bool isPositionChannel(const std::string& c) {
    return startsWith(c, "P1.") || startsWith(c, "P2.") || startsWith(c, "feat.P.");
}

/// Which channels of the records are which role; false with the missing fields named.
bool planChannels(const std::string& path, const std::vector<std::string>& available,
                  std::vector<std::string>& channels, RpfLayout& layout, std::string& err) {
    std::vector<std::string> randoms, features;
    bool sx = false, sy = false;
    for (const std::string& c : available) {
        if (c == "screen.x") sx = true;
        if (c == "screen.y") sy = true;
        if (startsWith(c, kRandomParameterPrefix)) randoms.push_back(c);
        if (isFeatureChannel(c)) features.push_back(c);
    }
    std::vector<std::string> missing;
    if (!sx || !sy) missing.emplace_back("screen (screen.x, screen.y)");
    if (randoms.empty())
        missing.emplace_back("random parameters (rand.*: lens, time, light, bounce)");
    if (features.empty()) missing.emplace_back("scene features (N1, P1, T1, N2, P2)");
    if (!missing.empty()) {
        std::string list;
        for (const std::string& m : missing) list += (list.empty() ? "" : "; ") + m;
        err = path + ": rpf needs per-sample fields it does not hold: " + list +
              " (render with mcstat-render --keep-samples)";
        return false;
    }
    channels = {"R", "G", "B", "screen.x", "screen.y"};
    channels.insert(channels.end(), randoms.begin(), randoms.end());
    channels.insert(channels.end(), features.begin(), features.end());
    layout.randoms = int(randoms.size());
    layout.features = int(features.size());
    layout.isPosition.clear();
    for (const std::string& f : features) layout.isPosition.push_back(isPositionChannel(f));
    return true;
}

/// Packs a block of records into the window's sample vectors (RpfLayout order). Samples with a
/// non-finite value in any field used are left out (docs/rpf.md, "Extremes"); `dropped` counts
/// them.
void pack(const SampleBlock& block, const std::vector<std::string>& channels,
          const std::vector<std::string>& aovChannels, int height, RpfWindow& w, int64_t& dropped) {
    const size_t dims = channels.size(), stride = block.stride();
    std::vector<int> from(dims);
    for (size_t d = 0; d < dims; ++d) from[d] = block.channel(channels[d]);
    std::vector<int> aovFrom;
    for (const std::string& c : aovChannels) aovFrom.push_back(block.channel(c));
    w.aov.clear();
    w.width = block.width;
    w.height = height;
    w.y0 = block.y0;
    w.rows = block.rows;
    w.offset.assign(block.counts.size() + 1, 0);
    w.x.clear();
    w.x.reserve(block.samples.size() / std::max<size_t>(stride, 1) * dims);
    size_t k = 0;
    for (size_t p = 0; p < block.counts.size(); ++p) {
        uint64_t kept = 0;
        for (uint32_t i = 0; i < block.counts[p]; ++i, ++k) {
            const float* s = block.samples.data() + k * stride;
            bool finite = true;
            for (size_t d = 0; d < dims; ++d) finite = finite && std::isfinite(s[from[d]]);
            if (!finite) {
                ++dropped;
                continue;
            }
            for (size_t d = 0; d < dims; ++d) w.x.push_back(s[from[d]]);
            for (int a : aovFrom) w.aov.push_back(s[a]);  // non-finite ones: left out later
            ++kept;
        }
        w.offset[p + 1] = w.offset[p] + kept;
    }
}

}  // namespace

bool rpfParamsFrom(const ParamValues& v, RpfParams& p, std::string& err) {
    p.sigma8sq = v.at("sigma8").real;
    p.samplesFactor = v.at("samples").real;
    p.maxNeighbourhood = v.at("max").integer;
    p.spikes = v.at("spikes").integer != 0;
    p.seed = uint64_t(v.at("seed").integer);
    const int passes = int(v.at("passes").integer);
    p.boxes = {55, 35, 17, 7};
    p.boxes.resize(size_t(std::min(passes, 4)));
    return validateRpfParams(p, err);
}

bool rpfSamples(const SamplesRequest& req, OperationImage& out, std::string& err) {
    SampleSource* src = req.source;
    if (src == nullptr || req.params == nullptr) {
        err = req.path + ": rpf needs an opened statistics file";
        return false;
    }
    const StatsHeader& h = src->header();
    const std::string& path = src->path();
    if (!h.hasRecords) {
        err = path +
              ": no per-sample records (part 'records'): rpf filters samples; render with "
              "mcstat-render --keep-samples";
        return false;
    }
    RpfParams prm;
    if (!rpfParamsFrom(*req.params, prm, err)) {
        err = path + ": " + err;
        return false;
    }
    std::vector<std::string> channels;
    RpfWindow w;
    if (!planChannels(path, src->recordChannels(), channels, w.layout, err)) return false;
    // Per-sample AOVs ("aov.<name>" for the file's AOVs): filtered with the colour's weights.
    std::vector<std::string> aovChannels, aovNames;
    {
        const std::vector<std::string> available = src->recordChannels();
        for (const AovChannel& a : h.aovs) {
            const std::string c = std::string(kRecordAovPrefix) + a.name;
            if (std::find(available.begin(), available.end(), c) == available.end()) continue;
            aovChannels.push_back(c);
            aovNames.push_back(a.name);
            w.aovFixed.push_back(a.cls == AovClass::Id);
            // Spikes follow the colour channel of the same letter (light and data passes).
            const char last = a.name.empty() ? 0 : a.name.back();
            const bool colour = a.cls == AovClass::Light || a.cls == AovClass::Data;
            w.aovFollows.push_back(!colour || a.name.size() < 2 || a.name[a.name.size() - 2] != '.'
                                       ? -1
                                   : last == 'R' || last == 'r' ? 0
                                   : last == 'G' || last == 'g' ? 1
                                   : last == 'B' || last == 'b' ? 2
                                                                : -1);
        }
        w.aovs = aovChannels.size();
    }
    std::vector<std::string> selected = channels;
    selected.insert(selected.end(), aovChannels.begin(), aovChannels.end());
    if (!src->selectRecordChannels(selected, err)) return false;

    // Output rows per block: a window of (rows + 2 halo) rows of samples within about 256 MiB
    // (the counts of the file decide exactly; the reader bounds them), or the `rows` asked for.
    const int halo = rpfHalo(prm);
    const double rowBytes = std::max(1.0, double(h.width) * double(std::max<int64_t>(h.spp, 1)) *
                                              double(channels.size() + 1) * sizeof(float) * 2.0);
    int rows = int(req.params->at("rows").integer);
    if (rows <= 0)
        rows = int(std::clamp(std::floor(double(256 << 20) / rowBytes) - 2.0 * halo, 16.0,
                              double(h.height)));
    rows = std::min(rows, h.height);

    out.width = h.width;
    out.height = h.height;
    // maps=1: the dependency maps of the report's Fig. 6, from the first pass.
    const bool maps = req.params->at("maps").integer != 0;
    out.channels = {"R", "G", "B"};
    if (maps) out.channels.insert(out.channels.end(), kMapChannels.begin(), kMapChannels.end());
    const size_t firstAov = out.channels.size();
    out.channels.insert(out.channels.end(), aovNames.begin(), aovNames.end());
    const size_t nch = out.channels.size();
    out.pixels.assign(size_t(h.width) * size_t(h.height) * nch, 0.f);
    std::vector<int> texture;  // features of the texture value T1 (Fig. 6g)
    for (size_t k = 0; k < channels.size(); ++k)
        if (startsWith(channels[k], "T1.")) texture.push_back(int(k) - 5 - w.layout.randoms);
    const int passes = int(prm.boxes.size());
    int64_t dropped = 0, rowsDone = 0, rowsTotal = 0;
    for (int y0 = 0; y0 < h.height; y0 += rows) {  // rows every pass filters, for progress
        int lo = y0, hi = std::min(h.height, y0 + rows);
        rowsTotal += hi - lo;
        for (int t = passes - 2; t >= 0; --t) {
            lo = std::max(0, lo - prm.boxes[size_t(t + 1)] / 2);
            hi = std::min(h.height, hi + prm.boxes[size_t(t + 1)] / 2);
            rowsTotal += hi - lo;
        }
    }
    auto rowDone = [&](int) {
        ++rowsDone;
        if (req.progress) req.progress(double(rowsDone) / double(std::max<int64_t>(rowsTotal, 1)));
    };
    SampleBlock block;
    std::vector<float> rgb, aovRows;
    std::vector<RpfPixelReport> report;
    for (int y0 = 0; y0 < h.height; y0 += rows) {
        const int y1 = std::min(h.height, y0 + rows);
        const int a = std::max(0, y0 - halo), e = std::min(h.height, y1 + halo);
        if (!src->readRecords(a, e - a, block, err)) return false;
        pack(block, channels, aovChannels, h.height, w, dropped);
        block.samples = std::vector<float>();  // the window holds the samples now
        rpfFilterRows(w, prm, y0, y1, rgb, req.nthreads, rowDone, maps ? &report : nullptr,
                      w.aovs ? &aovRows : nullptr);
        const size_t pixels = size_t(y1 - y0) * size_t(h.width);
        for (size_t i = 0; i < pixels; ++i) {
            float* o = out.pixels.data() + (size_t(y0) * size_t(h.width) + i) * nch;
            std::copy_n(rgb.data() + i * 3, 3, o);
            if (w.aovs) std::copy_n(aovRows.data() + i * w.aovs, w.aovs, o + firstAov);
            if (!maps) continue;
            const RpfPixelReport& r = report[i];
            double tr = 0, tb = 0;
            for (int k : texture) {
                tr += r.featureOnRandom.empty() ? 0.0 : r.featureOnRandom[size_t(k)];
                tb += r.beta.empty() ? 0.0 : r.beta[size_t(k)];
            }
            const double nt = std::max<size_t>(texture.size(), 1);
            o[3] = float(r.colourOnRandom);
            o[4] = float(tr / nt);
            o[5] = float((r.alpha[0] + r.alpha[1] + r.alpha[2]) / 3.0);
            o[6] = float(tb / nt);
            o[7] = float(r.neighbours);
        }
    }
    if (req.progress) req.progress(1.0);
    return true;
}

Operation rpfOperation() {
    Operation op;
    op.name = "rpf";
    op.title = "RPF";
    op.help =
        "random parameter filtering (Sen & Darabi): cross-bilateral filter of the per-sample "
        "records weighted by the mutual information of colour and features with the random "
        "parameters; needs mcstat-render --keep-samples";
    op.equation = "Sen & Darabi Algorithms 1-4, eq. 1-20";
    op.input = InputKind::Samples;
    op.samples = &rpfSamples;
    const ParamSpec spikes =
        flagParam("spikes", "0",
                  "section 6.1 (for path-traced scenes with small bright lights, as "
                  "the report applies it): a filtered sample above its pixel's mean "
                  "by more than one deviation becomes the mean; it loses the energy "
                  "of partly covered bright edges (docs/rpf.md)");
    const ParamSpec maps =
        flagParam("maps", "0",
                  "add the first pass's dependency maps (the report's Fig. 6): channels "
                  "rpf.colourOnRandom (eq. 11), rpf.textureOnRandom (eq. 9), rpf.alpha (eq. 15), "
                  "rpf.textureBeta (eq. 16), rpf.neighbours (|N|)");
    op.params = {
        realParam("sigma8", 0.0, 1e6, true, "0.002",
                  "sigma_8^2 of section 6 (bilateral variance at 8 spp; the report uses 0.02 "
                  "for noisy indoor path tracing)"),
        realParam("samples", 0.0, 64.0, true, "0.5",
                  "at most box^2 x spp x this samples per neighbourhood (Algorithm 1 line 8)"),
        intParam("max", 1, 1e7, "16384",
                 "but never more than this many (a pixel costs its samples x |N|)"),
        intParam("passes", 1, 4, "4", "passes with boxes 55, 35, 17, 7 (section 3.2)"),
        spikes,
        intParam("seed", 0, 2147483647, "0", "seed of the neighbourhoods' random draws"),
        maps,
        intParam("rows", 0, 1e6, "0",
                 "output rows per block (0: as many as fit in about 256 MiB of samples); the "
                 "result does not depend on it"),
    };
    return op;
}

}  // namespace mcstat
