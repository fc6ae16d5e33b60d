// Cascade reweighting (Zirr, Hanika and Dachsbacher, "Re-weighting Firefly Samples for Improved
// Finite-Sample Monte Carlo Estimates", CGF 37(6) 2018), the registry's operation "reweight":
// `mcstat FILE --reweight` and the plugin's `?estimator=reweight` (docs/reweighting.md). The
// cascades come from the renderer's online run (state parts, `mcstat-render --reweight`) when
// their shape is the one asked for, else from the per-sample records, pixel by pixel in the
// order the samples were taken through the same splatSample the renderer feeds, so that both
// give the same cascades bit for bit. Reads through SampleSource (exr-deep opens the file), the
// records by blocks of rows. The state parts and the registry entry's hooks are here too.
#include "mcstat/filters/samples/cascade_reweighting_operation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <vector>

#include "mcstat/core/parallel.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/filters/aov_weights.h"

namespace mcstat {

namespace {

/// The parts' names (the operation's choice).
constexpr const char* kFlatPart = "cascades";
constexpr const char* kDeepPart = "cascades.deep";

/// Flat part: FLOAT R, G, B (the plain mean of the finite samples, for a viewer), UINT n and
/// skipped, and every cascade's three double sums as their exact 64-bit patterns in UINT pairs
/// ("c0.R.hi", "c0.R.lo", ...). The deep part holds no records (channels Z, A for deep tools).
const std::vector<std::string> kFloats = {"R", "G", "B"};
const std::vector<std::string> kDeepChannels = {"Z", "A"};

std::vector<std::string> wordChannels(int count) {
    std::vector<std::string> w = {"n", "skipped"};
    for (int i = 0; i < count; ++i)
        for (const char* c : {"R", "G", "B"})
            for (const char* h : {"hi", "lo"})
                w.push_back("c" + std::to_string(i) + "." + c + "." + h);
    return w;
}

ParamSpec lumaParam() {
    return textParam("luma", "",
                     "luminance weights R,G,B of the split and the reliabilities (default: the "
                     "working colour space's)");
}

/// The cascades' shape as text: what must match between a stored run and a request.
std::string shapeText(const ReweightParams& p) { return reweightStateText(p); }

/// Blocks of rows of about 128 MiB of samples.
int blockRows(const StatsHeader& h) {
    const double rowBytes = std::max(
        1.0, double(h.width) * double(std::max<int64_t>(h.spp, 1)) * kRecordFloats * sizeof(float));
    return int(std::clamp(std::floor(double(128 << 20) / rowBytes), 1.0, 64.0));
}

/// The cascades from the records, every pixel's samples in the order taken.
bool cascadesFromRecords(SampleSource& src, const ReweightParams& p, int nthreads,
                         CascadeImage& img, std::string& err) {
    const StatsHeader& h = src.header();
    if (!src.selectRecordChannels({}, err)) return false;
    const int rows = blockRows(h);
    SampleBlock block;
    for (int y0 = 0; y0 < h.height; y0 += rows) {
        const int n = std::min(rows, h.height - y0);
        if (!src.readRecords(y0, n, block, err)) return false;
        std::vector<size_t> offset(block.counts.size() + 1, 0);
        for (size_t i = 0; i < block.counts.size(); ++i)
            offset[i + 1] = offset[i] + block.counts[i];
        const size_t stride = block.stride();
        auto work = [&](int64_t b, int64_t e) {
            CascadePixel one;
            for (int64_t i = b; i < e; ++i) {
                one.sum.assign(size_t(p.count) * 3, 0.0);
                one.n = one.skipped = 0;
                for (size_t k = offset[size_t(i)]; k < offset[size_t(i) + 1]; ++k)
                    splatSample(one, block.samples.data() + k * stride, p);
                const size_t pix = size_t(y0) * size_t(h.width) + size_t(i);
                std::copy(one.sum.begin(), one.sum.end(),
                          img.sum.begin() + std::ptrdiff_t(pix * size_t(p.count) * 3));
                img.n[pix] = one.n;
            }
        };
        // Pixels in chunks handed out as threads free up (a pixel's sums depend on its samples
        // alone, in the order taken).
        parallelFor(0, int64_t(block.counts.size()), 64, nthreads, work);
    }
    return true;
}

/// The per-sample AOVs the records hold (channels "aov.<name>"), weighted as the beauty weights
/// its samples (docs/aovs.md): sample k of a pixel counts kept_k / N (sampleShares), so light
/// AOVs are sum_k kept_k x_k / N and sum to the beauty; alpha and data passes are the average with
/// those weights; id mattes the label of the sample of largest weight. With spread, the light
/// AOVs' removed part is scattered as the beauty's is. Adds the channels to `out`.
bool recordAovs(SampleSource& src, const ReweightParams& p, const std::vector<double>& weights,
                const CascadeImage& img, int nthreads, OperationImage& out, std::string& err) {
    const StatsHeader& h = src.header();
    const std::vector<std::string> available = src.recordChannels();
    std::vector<std::string> channels, names;
    std::vector<AovClass> classes;
    for (const AovChannel& a : h.aovs) {
        const std::string name = std::string(kRecordAovPrefix) + a.name;
        if (std::find(available.begin(), available.end(), name) == available.end()) continue;
        channels.push_back(name);
        names.push_back(a.name);
        classes.push_back(a.cls);
    }
    if (channels.empty()) return true;
    if (!src.selectRecordChannels(channels, err)) return false;
    const size_t A = channels.size(), pixels = img.n.size(), C = size_t(img.count);
    std::vector<float> convex(pixels * A, 0.f);
    std::vector<double> light(pixels * A, 0.0), removed(p.spread > 0 ? pixels * A : 0, 0.0);
    const int rows = blockRows(h);
    SampleBlock block;
    for (int y0 = 0; y0 < h.height; y0 += rows) {
        const int nrows = std::min(rows, h.height - y0);
        if (!src.readRecords(y0, nrows, block, err)) return false;
        const size_t stride = block.stride();
        const int at[3] = {block.channel("R"), block.channel("G"), block.channel("B")};
        std::vector<size_t> aovAt;
        for (const std::string& c : channels) aovAt.push_back(size_t(block.channel(c)));
        std::vector<size_t> offset(block.counts.size() + 1, 0);
        for (size_t i = 0; i < block.counts.size(); ++i)
            offset[i + 1] = offset[i] + block.counts[i];
        // Every pixel from its own samples and weights: chunks of pixels on any thread.
        parallelFor(0, int64_t(block.counts.size()), 64, nthreads, [&](int64_t pb, int64_t pe) {
            std::vector<double> u, t;
            std::vector<float> x;
            AovScratch scratch;
            for (size_t i = size_t(pb); i < size_t(pe); ++i) {
                const size_t pix = size_t(y0) * size_t(h.width) + i, n = block.counts[i];
                const float* smp = block.samples.data() + offset[i] * stride;
                if (img.n[pix] == 0) continue;
                const double N = double(img.n[pix]);
                u.assign(n, 0.0);
                t.assign(n, 0.0);
                x.resize(n * A);
                for (size_t k = 0; k < n; ++k) {
                    const float* c = smp + k * stride;
                    for (size_t a = 0; a < A; ++a) x[k * A + a] = c[aovAt[a]];
                    const float rgb[3] = {c[at[0]], c[at[1]], c[at[2]]};
                    if (!std::isfinite(rgb[0]) || !std::isfinite(rgb[1]) || !std::isfinite(rgb[2]))
                        continue;
                    const double Y = p.luma[0] * rgb[0] + p.luma[1] * double(rgb[1]) +
                                     p.luma[2] * double(rgb[2]);
                    if (!std::isfinite(Y)) continue;
                    double kept = 0.0, taken = 0.0;
                    sampleShares(Y, p, weights.data() + pix * C, kept, taken);
                    u[k] = kept / N;
                    t[k] = taken / N;
                }
                applyAovWeights(u.data(), n, x.data(), A, classes.data(), convex.data() + pix * A,
                                scratch);
                for (size_t a = 0; a < A; ++a) {
                    if (classes[a] != AovClass::Light) continue;
                    double e = 0.0, all = 0.0;
                    for (size_t k = 0; k < n; ++k) {
                        const double v = x[k * A + a];
                        if (!std::isfinite(v)) continue;
                        e += u[k] * v;
                        all += t[k] * v;
                    }
                    light[pix * A + a] = e;
                    if (p.spread > 0) removed[pix * A + a] = all - e;
                }
            }
        });
    }
    if (p.spread > 0) {
        std::vector<double> add;
        scatterRemoved(h.width, h.height, p.spread, A, removed, add, nthreads);
        for (size_t q = 0; q < pixels; ++q)
            if (img.n[q] > 0)
                for (size_t a = 0; a < A; ++a) light[q * A + a] += add[q * A + a];
    }
    const size_t nch = 3 + A;
    std::vector<float> px(pixels * nch);
    for (size_t q = 0; q < pixels; ++q) {
        for (size_t c = 0; c < 3; ++c) px[q * nch + c] = out.pixels[q * 3 + c];
        for (size_t a = 0; a < A; ++a)
            px[q * nch + 3 + a] =
                classes[a] == AovClass::Light ? float(light[q * A + a]) : convex[q * A + a];
    }
    out.pixels = std::move(px);
    out.channels.insert(out.channels.end(), names.begin(), names.end());
    return true;
}

/// --info and --check: the state in numbers.
bool describeCascades(const PixelStateParts& parts, int width, std::string& text,
                      std::string& err) {
    CascadeImage img;
    std::vector<uint64_t> skipped;
    ReweightParams p;
    if (!decodeCascadeState(parts, width, img, skipped, p, err)) return false;
    uint64_t n = 0, sk = 0, empty = 0;
    std::vector<double> energy(size_t(p.count), 0.0);
    double total = 0.0;
    for (size_t q = 0; q < img.n.size(); ++q) {
        n += img.n[q];
        sk += skipped[q];
        empty += img.n[q] == 0;
        for (int i = 0; i < p.count; ++i) {
            const double* s = img.sum.data() + (q * size_t(p.count) + size_t(i)) * 3;
            const double y = p.luma[0] * s[0] + p.luma[1] * s[1] + p.luma[2] * s[2];
            energy[size_t(i)] += y;
            total += y;
        }
    }
    char line[256];
    std::snprintf(line, sizeof line,
                  "  reweight (online, %s): %d cascades; samples %llu, non-finite skipped %llu, "
                  "pixels without samples %llu\n",
                  reweightStateText(p).c_str(), p.count, (unsigned long long)n,
                  (unsigned long long)sk, (unsigned long long)empty);
    text = line;
    text += "  reweight: share of the luminance per cascade:";
    for (int i = 0; i < p.count; ++i) {
        std::snprintf(line, sizeof line, " %.4f", total != 0.0 ? energy[size_t(i)] / total : 0.0);
        text += line;
    }
    text += "\n";
    return true;
}

/// The renderer's online run: one CascadePixel per pixel, fed float32 RGB in the order taken.
class CascadeRun : public OnlineRun {
  public:
    ReweightParams params;
    std::vector<CascadePixel> pixels;
    int width = 0;

    void add(size_t p, const float rgb[3]) override { splatSample(pixels[p], rgb, params); }
    bool encode(PixelStateParts& out, std::string& err) override {
        CascadeImage img;
        img.width = width;
        img.height = width > 0 ? int(pixels.size() / size_t(width)) : 0;
        img.count = params.count;
        img.sum.assign(pixels.size() * size_t(params.count) * 3, 0.0);
        img.n.resize(pixels.size());
        std::vector<uint64_t> skipped(pixels.size());
        for (size_t q = 0; q < pixels.size(); ++q) {
            if (!pixels[q].sum.empty())
                std::copy(pixels[q].sum.begin(), pixels[q].sum.end(),
                          img.sum.begin() + std::ptrdiff_t(q * size_t(params.count) * 3));
            img.n[q] = pixels[q].n;
            skipped[q] = pixels[q].skipped;
        }
        return encodeCascadeState(img, skipped, params, out, err);
    }
    std::string paramText() const override { return reweightStateText(params); }
    int64_t learningSamples() const override { return 0; }
};

std::unique_ptr<OnlineRun> startCascadeRun(const ParamValues& values,
                                           const std::array<double, 3>& luma, int width,
                                           size_t pixels, const PixelStateParts* resume,
                                           std::string& err) {
    auto run = std::make_unique<CascadeRun>();
    run->width = width;
    if (!reweightParamsFrom(values, luma, run->params, err)) return nullptr;
    try {
        run->pixels.resize(pixels);
        if (resume != nullptr) {
            CascadeImage img;
            std::vector<uint64_t> skipped;
            ReweightParams stored = run->params;
            if (!decodeCascadeState(*resume, width, img, skipped, stored, err)) return nullptr;
            if (img.n.size() != pixels) {
                err = "the state to resume has " + std::to_string(img.n.size()) +
                      " pixels, the image " + std::to_string(pixels);
                return nullptr;
            }
            run->params = stored;  // a resumed run continues its own cascades
            for (size_t q = 0; q < pixels; ++q) {
                CascadePixel& px = run->pixels[q];
                px.sum.assign(img.sum.begin() + std::ptrdiff_t(q * size_t(img.count) * 3),
                              img.sum.begin() + std::ptrdiff_t((q + 1) * size_t(img.count) * 3));
                px.n = img.n[q];
                px.skipped = skipped[q];
            }
        }
    } catch (const std::exception& e) {
        err = std::string("cannot allocate the cascades: ") + e.what();
        return nullptr;
    }
    return run;
}

OperationState cascadeStateHooks() {
    OperationState s;
    s.flatPart = kFlatPart;
    s.deepPart = kDeepPart;
    s.describe = &describeCascades;
    s.start = &startCascadeRun;
    return s;
}

}  // namespace

bool reweightParamsFrom(const ParamValues& v, const std::array<double, 3>& luma, ReweightParams& p,
                        std::string& err) {
    p.count = int(v.at("count").integer);
    p.base = v.at("base").real;
    p.start = v.at("start").real;
    p.kappa = v.at("kappa").real;
    p.spread = int(v.at("spread").integer);
    p.luma = luma;
    const std::string& given = v.at("luma").text;
    if (!given.empty() && !parseRealTriple(given, p.luma)) {
        err = "reweight: luma must be three weights R,G,B, not '" + printable(given) + "'";
        return false;
    }
    return validateReweightParams(p, err);
}

std::string reweightStateText(const ReweightParams& p) {
    return paramText(
        {{"count", std::to_string(p.count)},
         {"base", realText(p.base)},
         {"start", realText(p.start)},
         {"luma", realText(p.luma[0]) + "," + realText(p.luma[1]) + "," + realText(p.luma[2])}});
}

bool encodeCascadeState(const CascadeImage& img, const std::vector<uint64_t>& skipped,
                        const ReweightParams& p, PixelStateParts& out, std::string& err) {
    const size_t pixels = img.n.size(), C = size_t(p.count);
    if (img.count != p.count || img.sum.size() != pixels * C * 3 || skipped.size() != pixels) {
        err = "reweight: the cascades do not match the image size";
        return false;
    }
    PixelStateParts r;
    r.owner.operation = kReweightName;
    r.owner.params = reweightStateText(p);
    r.owner.flatPart = kFlatPart;
    r.owner.deepPart = kDeepPart;
    r.floatChannels = kFloats;
    r.uintChannels = wordChannels(p.count);
    r.recordChannels = kDeepChannels;
    const size_t nw = r.uintChannels.size();
    r.floats.assign(pixels * 3, 0.f);
    r.words.assign(pixels * nw, 0u);
    r.recordCounts.assign(pixels, 0u);
    for (size_t q = 0; q < pixels; ++q) {
        if (img.n[q] > 0xffffffffu || skipped[q] > 0xffffffffu) {
            err = "reweight: a pixel took more than 2^32 - 1 samples, beyond what part '" +
                  std::string(kFlatPart) + "' stores";
            return false;
        }
        uint32_t* w = r.words.data() + q * nw;
        w[0] = uint32_t(img.n[q]);
        w[1] = uint32_t(skipped[q]);
        double mean[3] = {0.0, 0.0, 0.0};
        for (size_t i = 0; i < C; ++i)
            for (size_t c = 0; c < 3; ++c) {
                const double s = img.sum[(q * C + i) * 3 + c];
                putStateDouble(w + 2 + (i * 3 + c) * 2, s);
                mean[c] += s;
            }
        for (size_t c = 0; c < 3; ++c)
            r.floats[q * 3 + c] = img.n[q] ? float(mean[c] / double(img.n[q])) : 0.f;
    }
    out = std::move(r);
    return true;
}

bool decodeCascadeState(const PixelStateParts& parts, int width, CascadeImage& img,
                        std::vector<uint64_t>& skipped, ReweightParams& p, std::string& err) {
    if (parts.owner.operation != kReweightName) {
        err = "the state parts belong to '" + printable(parts.owner.operation) + "', not " +
              kReweightName;
        return false;
    }
    // The stored shape: parseParamText, then the entry's own checks (kappa: the default).
    std::map<std::string, std::string> kv;
    ParamValues values;
    std::string problem;
    bool ok = parseParamText(parts.owner.params, kv, problem);
    for (const char* key : {"count", "base", "start", "luma"})
        if (ok && kv.count(key) == 0) {
            problem = std::string("no ") + key;
            ok = false;
        }
    ReweightParams stored;
    ok = ok && parseOperationParams(reweightOperation(), kv, values, problem) &&
         reweightParamsFrom(values, p.luma, stored, problem);
    if (!ok) {
        err = "part '" + printable(parts.owner.flatPart) +
              "': parameters: " + printable(problem, 300);
        return false;
    }
    stored.kappa = p.kappa;
    const std::vector<std::string> want = wordChannels(stored.count);
    std::vector<size_t> at;
    for (const std::string& w : want) {
        const auto it = std::find(parts.uintChannels.begin(), parts.uintChannels.end(), w);
        if (it == parts.uintChannels.end()) {
            err = "part '" + printable(parts.owner.flatPart) + "' has no UINT channel '" + w + "'";
            return false;
        }
        at.push_back(size_t(it - parts.uintChannels.begin()));
    }
    const size_t pixels = parts.recordCounts.size(), nw = parts.uintChannels.size();
    if (width <= 0 || pixels % size_t(width) != 0 || parts.words.size() != pixels * nw) {
        err = "part '" + printable(parts.owner.flatPart) + "' does not match the image size";
        return false;
    }
    const size_t C = size_t(stored.count);
    CascadeImage r;
    r.width = width;
    r.height = int(pixels / size_t(width));
    r.count = stored.count;
    r.sum.resize(pixels * C * 3);
    r.n.resize(pixels);
    std::vector<uint64_t> sk(pixels);
    for (size_t q = 0; q < pixels; ++q) {
        const uint32_t* w = parts.words.data() + q * nw;
        r.n[q] = w[at[0]];
        sk[q] = w[at[1]];
        for (size_t i = 0; i < C * 3; ++i) {
            const uint32_t pair[2] = {w[at[2 + 2 * i]], w[at[3 + 2 * i]]};
            const double d = getStateDouble(pair);
            if (!std::isfinite(d)) {
                err = "pixel (" + std::to_string(q % size_t(width)) + ", " +
                      std::to_string(q / size_t(width)) + "): part '" +
                      printable(parts.owner.flatPart) + "' holds a non-finite cascade sum";
                return false;
            }
            r.sum[q * C * 3 + i] = d;
        }
    }
    img = std::move(r);
    skipped = std::move(sk);
    p = stored;
    return true;
}

bool reweightSamples(const SamplesRequest& req, OperationImage& out, std::string& err) {
    SampleSource* src = req.source;
    if (src == nullptr || req.params == nullptr) {
        err = req.path + ": reweight needs an opened statistics file";
        return false;
    }
    const StatsHeader& h = src->header();
    const std::string& path = src->path();
    ReweightParams p;
    if (!reweightParamsFrom(*req.params, req.luma, p, err)) return false;
    const bool haveStored = h.state.operation == kReweightName;
    if (!h.hasRecords && !haveStored) {
        err = path +
              ": has neither per-sample records nor reweighting cascades: render with "
              "mcstat-render --keep-samples (any parameters) or --online reweight (the online "
              "cascades)";
        return false;
    }
    CascadeImage img;
    bool fromState = false;
    if (haveStored) {
        PixelStateParts parts;
        std::vector<uint64_t> skipped;
        ReweightParams stored = p;
        if (!src->readPixelState(parts, err)) return false;
        if (!decodeCascadeState(parts, h.width, img, skipped, stored, err)) {
            err = path + ": " + err;
            return false;
        }
        // The stored luma holds unless the request names one; the shape must match.
        if (req.params->at("luma").text.empty()) p.luma = stored.luma;
        fromState = shapeText(stored) == shapeText(p);
        if (!fromState && !h.hasRecords) {
            err = path + ": holds the cascades for " + shapeText(stored) + "; computing " +
                  shapeText(p) + " needs per-sample records (render with --keep-samples)";
            return false;
        }
    }
    if (!fromState) {
        img = CascadeImage();
        img.width = h.width;
        img.height = h.height;
        img.count = p.count;
        const size_t pixels = size_t(h.width) * size_t(h.height);
        img.sum.assign(pixels * size_t(p.count) * 3, 0.0);
        img.n.assign(pixels, 0);
        if (!cascadesFromRecords(*src, p, req.nthreads, img, err)) return false;
    }
    out.width = h.width;
    out.height = h.height;
    out.channels = {"R", "G", "B"};
    std::vector<double> weights;
    reweightImage(img, p, out.pixels, &weights, req.nthreads);
    // The AOVs follow from the records (the stored cascades hold none).
    if (h.hasRecords && !h.aovs.empty())
        return recordAovs(*src, p, weights, img, req.nthreads, out, err);
    return true;
}

// Zirr et al. 2018 (docs/reweighting.md): per pixel, its samples split between cascades.
Operation reweightOperation() {
    Operation op = samplesOperation(
        kReweightName, "Reweighting (Zirr et al.)",
        "Zirr et al. 2018: every sample split by luminance between cascades of geometric "
        "scales; each cascade weighted by the samples supporting its scale in the pixel and its "
        "3x3 neighbourhood (kappa); from the per-sample records or the stored online cascades",
        "Zirr, Hanika, Dachsbacher 2018; details of the authors' reference implementation",
        {intParam("count", 2, 16, "6", "number of cascades"),
         realParam("base", 1.0, 1e6, true, "8", "ratio of neighbouring cascades' scales"),
         realParam("start", 0.0, HUGE_VAL, true, "1", "luminance scale of cascade 0"),
         realParam("kappa", 0.0, 1e9, true, "32",
                   "samples a cascade's scale needs to be trusted (larger: more removed)"),
         intParam("spread", 0, 64, "0",
                  "not the paper's: r > 0 scatters each pixel's removed energy evenly over its "
                  "(2r+1)^2 window, keeping the image's energy (0: the paper's method)"),
         lumaParam()},
        &reweightSamples);
    op.state = cascadeStateHooks();
    return op;
}

}  // namespace mcstat
