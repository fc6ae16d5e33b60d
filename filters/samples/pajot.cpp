// `mcstat FILE --pajot` and the plugin's `?estimator=pajot` (docs/pajot.md, "Offline"): Pajot's
// estimate recomputed from the per-sample records, pixel by pixel in the order the samples were
// taken, through the same PajotPixel the renderer feeds, so that it equals the online result bit
// for bit; or, without records, the online result the file stores. Reads through SampleSource
// (exr-deep opens the file), by blocks of rows: memory holds one block of samples.
#include "mcstat/filters/samples/pajot.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "mcstat/core/parallel.h"
#include "mcstat/filters/aov_weights.h"
#include "mcstat/filters/samples/pajot_kde.h"
#include "mcstat/filters/samples/pajot_state.h"
#include "mcstat/sample_records.h"

namespace mcstat {

namespace {

/// The parameters asked for: method "stored" takes the online run's (or, with records only, the
/// paper's defaults) and ignores the other keys.
bool requestedParams(const SamplesRequest& req, const PajotImage* stored, PajotParams& p,
                     std::string& err) {
    const ParamValues& v = *req.params;
    const std::string method = v.at("method").text;
    if (method == "stored") {
        if (stored) {
            p = stored->params;
            return true;
        }
        p = PajotParams();
        p.luma = req.luma;
        return true;
    }
    return pajotParamsFrom(v, req.luma, p, err);
}

}  // namespace

bool pajotParamsFrom(const ParamValues& v, const std::array<double, 3>& luma, PajotParams& p,
                     std::string& err) {
    const std::string& method = v.at("method").text;
    if (!parsePajotMethod(method, p.method)) {
        err = "pajot: method '" + method + "' names no estimator of its own";
        return false;
    }
    p.learning = int(v.at("n").integer);
    p.maxDelayed = int(v.at("delayed").integer);
    p.T = int(v.at("t").integer);
    p.delta = v.at("delta").real;
    p.luma = luma;
    return validatePajotParams(p, err);
}

bool pajotSamples(const SamplesRequest& req, OperationImage& out, std::string& err) {
    SampleSource* src = req.source;
    if (src == nullptr || req.params == nullptr) {
        err = req.path + ": pajot needs an opened statistics file";
        return false;
    }
    const StatsHeader& h = src->header();
    const std::string& path = src->path();
    if (!h.hasRecords && !h.hasPajot) {
        err = path +
              ": has neither per-sample records nor Pajot's online state: render with "
              "mcstat-render --keep-samples (to compute it here, any parameters) or --pajot "
              "hybrid (the online result)";
        return false;
    }
    PajotImage stored;
    const bool haveStored = h.hasPajot;
    if (haveStored && !readPajotState(*src, stored, err)) return false;
    PajotParams p;
    if (!requestedParams(req, haveStored ? &stored : nullptr, p, err)) return false;

    const size_t width = size_t(h.width), pixels = width * size_t(h.height);
    out.width = h.width;
    out.height = h.height;
    out.channels = {"R", "G", "B", "delayed"};
    out.pixels.assign(pixels * 4, 0.f);

    if (!h.hasRecords) {  // the stored online result, for its own parameters only
        if (pajotParamsText(p) != pajotParamsText(stored.params)) {
            err = path + ": holds the online result for " + pajotParamsText(stored.params) +
                  "; computing " + pajotParamsText(p) +
                  " needs per-sample records (render with --keep-samples), or use method=stored";
            return false;
        }
        for (size_t px = 0; px < pixels; ++px) {
            for (size_t c = 0; c < 3; ++c) out.pixels[px * 4 + c] = stored.estimate[px * 3 + c];
            out.pixels[px * 4 + 3] = float(stored.pixels[px].delayed.size());
        }
        return true;
    }

    // R, G, B (with Z, always read) of the records, and the per-sample AOVs the records hold
    // (channels "aov.<name>" for the file's AOVs): the samples the estimate averages carry their
    // AOVs with the same weights (docs/aovs.md).
    std::vector<std::string> aovChannels;
    std::vector<size_t> aovOf;  // index into h.aovs of each AOV carried
    {
        const std::vector<std::string> available = src->recordChannels();
        for (size_t a = 0; a < h.aovs.size(); ++a) {
            const std::string name = std::string(kRecordAovPrefix) + h.aovs[a].name;
            if (std::find(available.begin(), available.end(), name) != available.end()) {
                aovChannels.push_back(name);
                aovOf.push_back(a);
            }
        }
    }
    if (!src->selectRecordChannels(aovChannels, err)) return false;
    const size_t A = aovChannels.size(), nch = 4 + A;
    if (A > 0) {
        out.pixels.assign(pixels * nch, 0.f);
        for (size_t a : aovOf) out.channels.push_back(h.aovs[a].name);
    }
    std::vector<AovClass> classes;
    for (size_t a : aovOf) classes.push_back(h.aovs[a].cls);
    // Blocks of rows of about 128 MiB of samples (the per-pixel counts say how many exactly).
    const double rowBytes = std::max(
        1.0, double(width) * double(std::max<int64_t>(h.spp, 1)) * kRecordFloats * sizeof(float));
    const int rows = int(std::clamp(std::floor(double(128 << 20) / rowBytes), 1.0, 64.0));
    SampleBlock block;
    for (int y0 = 0; y0 < h.height; y0 += rows) {
        const int n = std::min(rows, h.height - y0);
        if (!src->readRecords(y0, n, block, err)) return false;
        // Where each pixel's samples start, then the pixels of the block on a few threads: every
        // pixel is one PajotPixel fed in sample order, so the split does not change a bit.
        std::vector<size_t> offset(block.counts.size() + 1, 0);
        for (size_t i = 0; i < block.counts.size(); ++i)
            offset[i + 1] = offset[i] + block.counts[i];
        std::vector<size_t> aovAt;  // where each carried AOV sits in a sample
        for (const std::string& c : aovChannels) aovAt.push_back(size_t(block.channel(c)));
        auto work = [&](size_t begin, size_t end) {
            std::vector<int64_t> log;
            std::vector<double> w;
            std::vector<float> values;
            AovScratch as;
            for (size_t i = begin; i < end; ++i) {
                PajotPixel px;
                log.clear();
                if (A > 0) px.logSplats(&log);
                for (size_t k = offset[i]; k < offset[i + 1]; ++k)  // non-finite: refused
                    px.add(block.samples.data() + k * block.stride(), p, int64_t(k - offset[i]));
                const std::array<float, 3> e = px.estimate();
                float* o = out.pixels.data() + (size_t(y0) * width + i) * nch;
                o[0] = e[0];
                o[1] = e[1];
                o[2] = e[2];
                o[3] = float(px.state().delayed.size());
                if (A == 0) continue;
                // Every sample the estimate averages, with the same weight.
                const std::vector<int64_t> tags = px.splatTags(log);
                w.assign(tags.size(), tags.empty() ? 0.0 : 1.0 / double(tags.size()));
                values.clear();
                for (int64_t t : tags) {
                    const float* smp =
                        block.samples.data() + (offset[i] + size_t(t)) * block.stride();
                    for (size_t at : aovAt) values.push_back(smp[at]);
                }
                applyAovWeights(w.data(), w.size(), values.data(), A, classes.data(), o + 4, as);
            }
        };
        parallelFor(0, int64_t(block.counts.size()), 0, std::min(threadCount(req.nthreads), n),
                    [&](int64_t b, int64_t e) { work(size_t(b), size_t(e)); });
    }
    return true;
}

// Pajot et al. 2011 (docs/pajot.md): per pixel, its samples in the order taken.
Operation pajotOperation() {
    Operation op;
    op.name = "pajot";
    op.title = "Pajot (ADR/ROT)";
    op.help =
        "Pajot et al.: samples above the last extended kernel-density mode of log-luminance are "
        "delayed (Algorithm 1); from the per-sample records, or the stored online result";
    op.equation = "Pajot et al. Algorithm 1, eq. 3-5";
    op.input = InputKind::Samples;
    op.samples = &pajotSamples;
    ParamSpec method;
    method.name = "method";
    method.type = ParamType::Enum;
    method.defaultValue = "stored";
    method.choices = {"stored", "adr", "rot", "hybrid"};
    method.help =
        "stored: the parameters of the render's online run (hybrid, n=50 when the file has only "
        "records), the other keys ignored; adr (eq. 4), rot (eq. 5), hybrid (section 4.6)";
    op.params = {method, intParam("n", 1, 1e6, "50", "samples of the learning phase (section 4.1)"),
                 intParam("delayed", 0, 1e6, "64",
                          "bound of the dubious list; when full the brightest is discarded"),
                 intParam("t", 1, 1e6, "2", "hybrid: successive close maxima before ROT alone"),
                 realParam("delta", 0.0, HUGE_VAL, false, "0",
                           "hybrid: largest |m_rot - m_adr| / |m_adr| counted as close")};
    return op;
}

// Sen and Darabi 2011 (docs/rpf.md): every sample's colour, screen position, random parameters
// and scene features, filtered by the dependency of colour on the random parameters.
}  // namespace mcstat
