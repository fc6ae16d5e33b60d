// `mcstat FILE --rpf` and the plugin's `?estimator=rpf` (docs/rpf.md): random parameter filtering
// over part `records`, read through SampleSource by blocks of output rows with the passes' halo
// (55 rows each side for the report's boxes), so memory holds a window of rows, never the image.
// Channels are found by name (FORMAT.md "Per-sample fields"): colour R, G, B; screen position
// screen.x, screen.y; random parameters rand.*; scene features N1, P1, T1, N2, P2 (and feat.*).
#include "mcstat/filters/samples/rpf.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "mcstat/core/parallel.h"
#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/filters/samples/rpf_filter.h"

namespace mcstat {

namespace {

/// maps=1 (Fig. 6), per pixel from pass 0: W_c^r (eq. 11), W_f^r of the texture value (eq. 9,
/// mean over T1.*), mean alpha (eq. 15), mean beta of T1 (eq. 16) and |N|.
const std::vector<std::string> kMapChannels{"rpf.colorOnRandom", "rpf.textureOnRandom", "rpf.alpha",
                                            "rpf.textureBeta", "rpf.neighbours"};

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
/// them. Two passes over the pixels, each on any thread: the samples each keeps, then (their
/// places known) the copies.
void pack(const SampleBlock& block, const std::vector<std::string>& channels,
          const std::vector<std::string>& aovChannels, int height, int nthreads, RpfWindow& w,
          int64_t& dropped) {
    const size_t dims = channels.size(), stride = block.stride(), pixels = block.counts.size();
    std::vector<int> from(dims);
    for (size_t d = 0; d < dims; ++d) from[d] = block.channel(channels[d]);
    std::vector<int> aovFrom;
    for (const std::string& c : aovChannels) aovFrom.push_back(block.channel(c));
    const size_t A = aovFrom.size();
    w.width = block.width;
    w.height = height;
    w.y0 = block.y0;
    w.rows = block.rows;
    std::vector<size_t> first(pixels + 1, 0);  // each pixel's first record in the block
    for (size_t p = 0; p < pixels; ++p) first[p + 1] = first[p] + block.counts[p];
    auto finite = [&](size_t k) {
        const float* s = block.samples.data() + k * stride;
        bool ok = true;
        for (size_t d = 0; d < dims; ++d) ok = ok && std::isfinite(s[from[d]]);
        return ok;
    };
    w.offset.assign(pixels + 1, 0);
    parallelFor(0, int64_t(pixels), 256, nthreads, [&](int64_t b, int64_t e) {
        for (size_t p = size_t(b); p < size_t(e); ++p) {
            uint64_t kept = 0;
            for (size_t k = first[p]; k < first[p + 1]; ++k) kept += finite(k) ? 1 : 0;
            w.offset[p + 1] = kept;
        }
    });
    for (size_t p = 0; p < pixels; ++p) w.offset[p + 1] += w.offset[p];
    dropped += int64_t(first[pixels] - w.offset[pixels]);
    w.x.resize(size_t(w.offset[pixels]) * dims);
    w.aov.resize(size_t(w.offset[pixels]) * A);  // non-finite AOVs: left out later
    parallelFor(0, int64_t(pixels), 256, nthreads, [&](int64_t b, int64_t e) {
        for (size_t p = size_t(b); p < size_t(e); ++p) {
            size_t to = size_t(w.offset[p]);
            for (size_t k = first[p]; k < first[p + 1]; ++k) {
                if (!finite(k)) continue;
                const float* s = block.samples.data() + k * stride;
                for (size_t d = 0; d < dims; ++d) w.x[to * dims + d] = s[from[d]];
                for (size_t a = 0; a < A; ++a) w.aov[to * A + a] = s[aovFrom[a]];
                ++to;
            }
        }
    });
}

}  // namespace

bool rpfParamsFrom(const ParamValues& v, RpfParams& p, std::string& err) {
    p.sigma8sq = v.at("sigma8").real;
    p.samplesFactor = v.at("samples").real;
    p.maxNeighbourhood = v.at("max").integer;
    p.maxKept = v.at("kept").integer;
    p.spikes = v.at("spikes").integer != 0;
    p.seed = uint64_t(v.at("seed").integer);
    const int passes = int(v.at("passes").integer);
    p.boxes = {55, 35, 17, 7};
    p.boxes.resize(size_t(std::min(passes, 4)));
    return validateRpfParams(p, err);
}

namespace {

/// What rpfSamples reads and writes, decided before the first block.
struct RpfPlan {
    RpfParams params;
    std::vector<std::string> channels;     ///< the records' fields, in RpfLayout order
    std::vector<std::string> aovChannels;  ///< "aov.<name>" of the AOVs carried
    std::vector<std::string> aovNames;     ///< their output channels
    std::vector<int> texture;              ///< features of the texture value T1 (Fig. 6g)
    int rowsPerBlock = 0;
    bool maps = false;  ///< maps=1: the dependency maps of the report's Fig. 6, from pass 0
    size_t firstAov = 0, nch = 0;  ///< where the AOVs start in an output pixel; its channels
};

/// The colour channel (0..2) whose spikes (section 6.1) an AOV follows: the one of the same
/// letter for light and data passes ("diffuse.R"), else -1.
int spikeChannelOf(const AovChannel& a) {
    const bool color = a.cls == AovClass::Light || a.cls == AovClass::Data;
    if (!color || a.name.size() < 2 || a.name[a.name.size() - 2] != '.') return -1;
    switch (a.name.back()) {
        case 'R':
        case 'r':
            return 0;
        case 'G':
        case 'g':
            return 1;
        case 'B':
        case 'b':
            return 2;
        default:
            return -1;
    }
}

/// The per-sample AOVs the records hold ("aov.<name>" for the file's AOVs): filtered with the
/// colour's weights, a label (AovClass::Id) kept as it is.
void carriedAovs(const StatsHeader& h, const std::vector<std::string>& available, RpfPlan& plan,
                 RpfWindow& w) {
    for (const AovChannel& a : h.aovs) {
        const std::string c = std::string(kRecordAovPrefix) + a.name;
        if (std::find(available.begin(), available.end(), c) == available.end()) continue;
        plan.aovChannels.push_back(c);
        plan.aovNames.push_back(a.name);
        w.aovFixed.push_back(a.cls == AovClass::Id);
        w.aovFollows.push_back(spikeChannelOf(a));
    }
    w.aovs = plan.aovChannels.size();
}

/// Checks the request and the file (records, parameters, the fields RPF needs), decides which
/// record channels play which role and selects them for reading; false with a one-line `err`.
bool planRecords(const SamplesRequest& req, RpfPlan& plan, RpfWindow& w, std::string& err) {
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
    if (!rpfParamsFrom(*req.params, plan.params, err)) {
        err = path + ": " + err;
        return false;
    }
    const std::vector<std::string> available = src->recordChannels();
    if (!planChannels(path, available, plan.channels, w.layout, err)) return false;
    carriedAovs(h, available, plan, w);
    std::vector<std::string> selected = plan.channels;
    selected.insert(selected.end(), plan.aovChannels.begin(), plan.aovChannels.end());
    return src->selectRecordChannels(selected, err);
}

/// Output rows per block: a window of (rows + 2 halo) rows of samples within about 256 MiB (the
/// counts of the file decide exactly; the reader bounds them), or the `asked` rows when > 0.
int blockRows(const StatsHeader& h, const RpfParams& prm, size_t fields, int64_t asked) {
    const int halo = rpfHalo(prm);
    const double rowBytes = std::max(1.0, double(h.width) * double(std::max<int64_t>(h.spp, 1)) *
                                              double(fields + 1) * sizeof(float) * 2.0);
    int rows = int(asked);
    if (rows <= 0)
        rows = int(std::clamp(std::floor(double(256 << 20) / rowBytes) - 2.0 * halo, 16.0,
                              double(h.height)));
    return std::min(rows, h.height);
}

/// The output image, all 0: R, G, B, then the maps when asked, then the AOVs carried.
void layoutOutput(const StatsHeader& h, RpfPlan& plan, OperationImage& out) {
    out.width = h.width;
    out.height = h.height;
    out.channels = {"R", "G", "B"};
    if (plan.maps)
        out.channels.insert(out.channels.end(), kMapChannels.begin(), kMapChannels.end());
    plan.firstAov = out.channels.size();
    out.channels.insert(out.channels.end(), plan.aovNames.begin(), plan.aovNames.end());
    plan.nch = out.channels.size();
    out.pixels.assign(size_t(h.width) * size_t(h.height) * plan.nch, 0.f);
}

/// The rows every pass filters over all the blocks (a block's passes widen it by the later
/// passes' box/2), the denominator of the progress.
int64_t rowsToFilter(int height, const RpfParams& prm, int rowsPerBlock) {
    const int passes = int(prm.boxes.size());
    int64_t total = 0;
    for (int y0 = 0; y0 < height; y0 += rowsPerBlock) {
        int lo = y0, hi = std::min(height, y0 + rowsPerBlock);
        total += hi - lo;
        for (int t = passes - 2; t >= 0; --t) {
            lo = std::max(0, lo - prm.boxes[size_t(t + 1)] / 2);
            hi = std::min(height, hi + prm.boxes[size_t(t + 1)] / 2);
            total += hi - lo;
        }
    }
    return total;
}

/// maps=1's channels of one pixel (kMapChannels) from pass 0's report: W_c^r (eq. 11), W_f^r and
/// beta averaged over the texture features (eq. 9, 16), alpha averaged over RGB (eq. 15), |N|.
void storeMaps(const RpfPixelReport& r, const std::vector<int>& texture, float* o) {
    double tr = 0, tb = 0;
    for (int k : texture) {
        tr += r.featureOnRandom.empty() ? 0.0 : r.featureOnRandom[size_t(k)];
        tb += r.beta.empty() ? 0.0 : r.beta[size_t(k)];
    }
    const double nt = std::max<size_t>(texture.size(), 1);
    o[0] = float(r.colorOnRandom);
    o[1] = float(tr / nt);
    o[2] = float((r.alpha[0] + r.alpha[1] + r.alpha[2]) / 3.0);
    o[3] = float(tb / nt);
    o[4] = float(r.neighbours);
}

/// One block's buffers, kept from block to block.
struct BlockBuffers {
    SampleBlock records;
    std::vector<float> rgb, aovs;
    std::vector<RpfPixelReport> report;
};

/// Filters output rows [y0, y1) from the records of those rows and their halo, and stores them
/// (colour, maps, AOVs) in `out`.
bool filterBlock(SampleSource& src, const RpfPlan& plan, int y0, int y1, int threads,
                 const std::function<void(int)>& rowDone, RpfWindow& w, BlockBuffers& buf,
                 int64_t& dropped, OperationImage& out, std::string& err) {
    const StatsHeader& h = src.header();
    const int halo = rpfHalo(plan.params);
    const int a = std::max(0, y0 - halo), e = std::min(h.height, y1 + halo);
    if (!src.readRecords(a, e - a, buf.records, err)) return false;
    pack(buf.records, plan.channels, plan.aovChannels, h.height, threads, w, dropped);
    buf.records.samples = std::vector<float>();  // the window holds the samples now
    rpfFilterRows(w, plan.params, y0, y1, buf.rgb, threads, rowDone,
                  plan.maps ? &buf.report : nullptr, w.aovs ? &buf.aovs : nullptr);
    const size_t pixels = size_t(y1 - y0) * size_t(h.width);
    for (size_t i = 0; i < pixels; ++i) {
        float* o = out.pixels.data() + (size_t(y0) * size_t(h.width) + i) * plan.nch;
        std::copy_n(buf.rgb.data() + i * 3, 3, o);
        if (w.aovs) std::copy_n(buf.aovs.data() + i * w.aovs, w.aovs, o + plan.firstAov);
        if (plan.maps) storeMaps(buf.report[i], plan.texture, o + 3);
    }
    return true;
}

}  // namespace

bool rpfSamples(const SamplesRequest& req, OperationImage& out, std::string& err) {
    RpfPlan plan;
    RpfWindow w;
    if (!planRecords(req, plan, w, err)) return false;
    SampleSource& src = *req.source;
    const StatsHeader& h = src.header();
    plan.rowsPerBlock =
        blockRows(h, plan.params, plan.channels.size(), req.params->at("rows").integer);
    plan.maps = req.params->at("maps").integer != 0;
    layoutOutput(h, plan, out);
    for (size_t k = 0; k < plan.channels.size(); ++k)
        if (startsWith(plan.channels[k], "T1."))
            plan.texture.push_back(int(k) - 5 - w.layout.randoms);
    const int64_t rowsTotal = rowsToFilter(h.height, plan.params, plan.rowsPerBlock);
    int64_t dropped = 0, rowsDone = 0;
    auto rowDone = [&](int) {
        ++rowsDone;
        if (req.progress) req.progress(double(rowsDone) / double(std::max<int64_t>(rowsTotal, 1)));
    };
    BlockBuffers buf;
    for (int y0 = 0; y0 < h.height; y0 += plan.rowsPerBlock) {
        const int y1 = std::min(h.height, y0 + plan.rowsPerBlock);
        if (!filterBlock(src, plan, y0, y1, req.nthreads, rowDone, w, buf, dropped, out, err))
            return false;
    }
    if (req.progress) req.progress(1.0);
    return true;
}

Operation rpfOperation() {
    const ParamSpec spikes =
        flagParam("spikes", "0",
                  "section 6.1 (for path-traced scenes with small bright lights, as "
                  "the report applies it): a filtered sample above its pixel's mean "
                  "by more than one deviation becomes the mean; it loses the energy "
                  "of partly covered bright edges (docs/rpf.md)");
    const ParamSpec maps =
        flagParam("maps", "0",
                  "add the first pass's dependency maps (the report's Fig. 6): channels "
                  "rpf.colorOnRandom (eq. 11), rpf.textureOnRandom (eq. 9), rpf.alpha (eq. 15), "
                  "rpf.textureBeta (eq. 16), rpf.neighbours (|N|)");
    return samplesOperation(
        "rpf", "RPF",
        "random parameter filtering (Sen & Darabi): cross-bilateral filter of the per-sample "
        "records weighted by the mutual information of colour and features with the random "
        "parameters; needs mcstat-render --keep-samples",
        "Sen & Darabi Algorithms 1-4, eq. 1-20",
        {
            realParam("sigma8", 0.0, 1e6, true, "0.002",
                      "sigma_8^2 of section 6 (bilateral variance at 8 spp; the report uses 0.02 "
                      "for noisy indoor path tracing)"),
            realParam("samples", 0.0, 64.0, true, "0.5",
                      "at most box^2 x spp x this samples per neighbourhood (Algorithm 1 line 8)"),
            intParam("max", 1, 1e7, "16384",
                     "but never more than this many (a pixel costs its samples x |N|)"),
            intParam("kept", 0, 1e7, "1536",
                     "stop drawing once N holds this many (a random subset; 0: every draw, the "
                     "report's rule)"),
            intParam("passes", 1, 4, "4", "passes with boxes 55, 35, 17, 7 (section 3.2)"),
            spikes,
            intParam("seed", 0, 2147483647, "0", "seed of the neighbourhoods' random draws"),
            maps,
            intParam("rows", 0, 1e6, "0",
                     "output rows per block (0: as many as fit in about 256 MiB of samples); the "
                     "result does not depend on it"),
        },
        &rpfSamples);
}

}  // namespace mcstat
