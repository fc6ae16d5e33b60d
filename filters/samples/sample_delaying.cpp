// Density-based sample delaying (Pajot, Barthe and Paulin, "Sample-Space Bright Spots Removal
// Using Density Estimation", GI 2011, Algorithm 1), the registry's operation "pajot".
// `mcstat FILE --pajot` and the plugin's `?estimator=pajot` (docs/pajot.md, "Offline"): Pajot's
// estimate recomputed from the per-sample records, pixel by pixel in the order the samples were
// taken, through the same PajotPixel the renderer feeds, so that it equals the online result bit
// for bit; or, without records, the online result the file stores. Reads through SampleSource
// (exr-deep opens the file), by blocks of rows: memory holds one block of samples.
#include "mcstat/filters/samples/sample_delaying.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "mcstat/core/parallel.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/filters/aov_weights.h"
#include "mcstat/filters/samples/sample_delaying_kde.h"
#include "mcstat/filters/samples/sample_delaying_state.h"

namespace mcstat {

namespace {

/// The luminance weights of the log-luminance (section 3): the colour config's unless given; a
/// stored run names its own.
ParamSpec lumaParam() {
    // Text, not a list of reals: an empty default means the colour config's (pajotParamsFrom
    // reads the three numbers with the one number syntax).
    return textParam("luma", "",
                     "luminance weights R,G,B of the log-luminance (default: the working colour "
                     "space's)");
}

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

/// Without records: the online result the file stores (R, G, B and the delayed count), which
/// holds for its own parameters only.
bool storedResult(const std::string& path, const PajotImage& stored, const PajotParams& p,
                  size_t pixels, OperationImage& out, std::string& err) {
    if (pajotParamText(p) != pajotParamText(stored.params)) {
        err = path + ": holds the online result for " + pajotParamText(stored.params) +
              "; computing " + pajotParamText(p) +
              " needs per-sample records (render with --keep-samples), or use method=stored";
        return false;
    }
    for (size_t px = 0; px < pixels; ++px) {
        for (size_t c = 0; c < 3; ++c) out.pixels[px * 4 + c] = stored.estimate[px * 3 + c];
        out.pixels[px * 4 + 3] = float(stored.pixels[px].delayed.size());
    }
    return true;
}

/// The per-sample AOVs the records hold (channels "aov.<name>" for the file's AOVs): the samples
/// the estimate averages carry their AOVs with the same weights (docs/aovs.md).
struct RecordAovs {
    std::vector<std::string> channels;  ///< in the records
    std::vector<std::string> names;     ///< in the output
    std::vector<AovClass> classes;
};

RecordAovs recordAovs(const StatsHeader& h, const std::vector<std::string>& available) {
    RecordAovs aovs;
    for (const AovChannel& a : h.aovs) {
        const std::string name = std::string(kRecordAovPrefix) + a.name;
        if (std::find(available.begin(), available.end(), name) == available.end()) continue;
        aovs.channels.push_back(name);
        aovs.names.push_back(a.name);
        aovs.classes.push_back(a.cls);
    }
    return aovs;
}

/// One thread's buffers, kept from pixel to pixel.
struct PixelScratch {
    std::vector<int64_t> log;  ///< the samples the pixel's estimate splatted (logSplats)
    std::vector<double> weight;
    std::vector<float> values;  ///< the AOVs of the samples averaged, sample by sample
    AovScratch aov;
};

/// The AOVs of a pixel (docs/aovs.md): every sample the estimate averages, with the same weight.
/// `samples` are the pixel's records (`stride` floats each), `aovAt` where each AOV sits in one.
void pixelAovs(const PajotPixel& px, const float* samples, size_t stride,
               const std::vector<size_t>& aovAt, const std::vector<AovClass>& classes, float* out,
               PixelScratch& sc) {
    const std::vector<int64_t> tags = px.splatTags(sc.log);
    sc.weight.assign(tags.size(), tags.empty() ? 0.0 : 1.0 / double(tags.size()));
    sc.values.clear();
    for (int64_t t : tags) {
        const float* smp = samples + size_t(t) * stride;
        for (size_t at : aovAt) sc.values.push_back(smp[at]);
    }
    applyAovWeights(sc.weight.data(), sc.weight.size(), sc.values.data(), aovAt.size(),
                    classes.data(), out, sc.aov);
}

/// Algorithm 1 over one pixel's `count` records in the order taken, through the PajotPixel the
/// renderer feeds, so that it equals the online result bit for bit: R, G, B, the delayed count
/// and the AOVs into `out`.
void recomputePixel(const float* samples, size_t count, size_t stride, const PajotParams& p,
                    const std::vector<size_t>& aovAt, const std::vector<AovClass>& classes,
                    float* out, PixelScratch& sc) {
    PajotPixel px;
    sc.log.clear();
    if (!aovAt.empty()) px.logSplats(&sc.log);
    for (size_t k = 0; k < count; ++k)  // non-finite: refused
        px.add(samples + k * stride, p, int64_t(k));
    const std::array<float, 3> e = px.estimate();
    out[0] = e[0];
    out[1] = e[1];
    out[2] = e[2];
    out[3] = float(px.state().delayed.size());
    if (!aovAt.empty()) pixelAovs(px, samples, stride, aovAt, classes, out + 4, sc);
}

/// Blocks of rows of about 128 MiB of samples (the per-pixel counts say how many exactly).
int blockRows(const StatsHeader& h) {
    const double rowBytes = std::max(
        1.0, double(h.width) * double(std::max<int64_t>(h.spp, 1)) * kRecordFloats * sizeof(float));
    return int(std::clamp(std::floor(double(128 << 20) / rowBytes), 1.0, 64.0));
}

/// Rows [y0, y0 + rows) recomputed from their records into `out`, the pixels on a few threads:
/// every pixel is one PajotPixel fed in sample order, so the split does not change a bit.
bool recomputeBlock(SampleSource& src, int y0, int rows, const PajotParams& p,
                    const RecordAovs& aovs, int nthreads, SampleBlock& block, OperationImage& out,
                    std::string& err) {
    if (!src.readRecords(y0, rows, block, err)) return false;
    std::vector<size_t> offset(block.counts.size() + 1, 0);  // where each pixel's samples start
    for (size_t i = 0; i < block.counts.size(); ++i) offset[i + 1] = offset[i] + block.counts[i];
    std::vector<size_t> aovAt;  // where each carried AOV sits in a sample
    for (const std::string& c : aovs.channels) aovAt.push_back(size_t(block.channel(c)));
    const size_t width = size_t(out.width), nch = out.channels.size();
    const size_t stride = block.stride();
    auto work = [&](size_t begin, size_t end) {
        PixelScratch sc;
        for (size_t i = begin; i < end; ++i)
            recomputePixel(block.samples.data() + offset[i] * stride, offset[i + 1] - offset[i],
                           stride, p, aovAt, aovs.classes,
                           out.pixels.data() + (size_t(y0) * width + i) * nch, sc);
    };
    parallelFor(0, int64_t(block.counts.size()), 0, std::min(threadCount(nthreads), rows),
                [&](int64_t b, int64_t e) { work(size_t(b), size_t(e)); });
    return true;
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
    const std::string& given = v.at("luma").text;
    if (!given.empty() && !parseRealTriple(given, p.luma)) {
        err = "pajot: luma must be three weights R,G,B, not '" + printable(given) + "'";
        return false;
    }
    return validatePajotParams(p, err);
}

std::string pajotParamText(const PajotParams& p) {
    return paramText(
        {{"method", pajotMethodName(p.method)},
         {"n", std::to_string(p.learning)},
         {"delayed", std::to_string(p.maxDelayed)},
         {"t", std::to_string(p.T)},
         {"delta", realText(p.delta)},
         {"luma", realText(p.luma[0]) + "," + realText(p.luma[1]) + "," + realText(p.luma[2])}});
}

bool pajotParamsFromText(const std::string& text, PajotParams& p, std::string& problem) {
    std::map<std::string, std::string> kv;
    ParamValues values;
    bool ok = parseParamText(text, kv, problem);
    for (const char* key : {"method", "n", "delayed", "t", "delta", "luma"})
        if (ok && kv.count(key) == 0) {
            problem = std::string("no ") + key + " in '" + text + "'";
            ok = false;
        }
    ok = ok && parseOperationParams(pajotOperation(), kv, values, problem) &&
         pajotParamsFrom(values, p.luma, p, problem);
    if (!ok) problem = printable(problem, 300);  // the text is the file's: untrusted
    return ok;
}

bool pajotSamples(const SamplesRequest& req, OperationImage& out, std::string& err) {
    SampleSource* src = req.source;
    if (src == nullptr || req.params == nullptr) {
        err = req.path + ": pajot needs an opened statistics file";
        return false;
    }
    const StatsHeader& h = src->header();
    const std::string& path = src->path();
    const bool haveStored = h.state.operation == kPajotName;
    if (!h.hasRecords && !haveStored) {
        err = path +
              ": has neither per-sample records nor Pajot's online state: render with "
              "mcstat-render --keep-samples (to compute it here, any parameters) or --online "
              "pajot:method=hybrid (the online result)";
        return false;
    }
    PajotImage stored;
    if (haveStored && !readPajotState(*src, stored, err)) return false;
    PajotParams p;
    if (!requestedParams(req, haveStored ? &stored : nullptr, p, err)) return false;

    const size_t pixels = size_t(h.width) * size_t(h.height);
    out.width = h.width;
    out.height = h.height;
    out.channels = {"R", "G", "B", "delayed"};
    out.pixels.assign(pixels * 4, 0.f);
    if (!h.hasRecords) return storedResult(path, stored, p, pixels, out, err);

    // R, G, B (with Z, always read) of the records, and the per-sample AOVs they hold.
    const RecordAovs aovs = recordAovs(h, src->recordChannels());
    if (!src->selectRecordChannels(aovs.channels, err)) return false;
    if (!aovs.channels.empty()) {
        out.pixels.assign(pixels * (4 + aovs.channels.size()), 0.f);
        out.channels.insert(out.channels.end(), aovs.names.begin(), aovs.names.end());
    }
    const int rows = blockRows(h);
    SampleBlock block;
    for (int y0 = 0; y0 < h.height; y0 += rows)
        if (!recomputeBlock(*src, y0, std::min(rows, h.height - y0), p, aovs, req.nthreads, block,
                            out, err))
            return false;
    return true;
}

// Pajot et al. 2011 (docs/pajot.md): per pixel, its samples in the order taken.
Operation pajotOperation() {
    const ParamSpec method = enumParam(
        "method", {"stored", "adr", "rot", "hybrid"}, "stored",
        "stored: the parameters of the render's online run (hybrid, n=50 when the file has only "
        "records), the other keys ignored; adr (eq. 4), rot (eq. 5), hybrid (section 4.6)");
    Operation op = samplesOperation(
        kPajotName, "Pajot (ADR/ROT)",
        "Pajot et al.: samples above the last extended kernel-density mode of log-luminance are "
        "delayed (Algorithm 1); from the per-sample records, or the stored online result",
        "Pajot et al. Algorithm 1, eq. 3-5",
        {method, intParam("n", 1, 1e6, "50", "samples of the learning phase (section 4.1)"),
         intParam("delayed", 0, 1e6, "64",
                  "bound of the dubious list; when full the brightest is discarded"),
         intParam("t", 1, 1e6, "2", "hybrid: successive close maxima before ROT alone"),
         realParam("delta", 0.0, HUGE_VAL, false, "0",
                   "hybrid: largest |m_rot - m_adr| / |m_adr| counted as close"),
         lumaParam()},
        &pajotSamples);
    op.state = pajotStateHooks();
    return op;
}

}  // namespace mcstat
