// Density-based sample delaying's online state (Pajot, Barthe and Paulin, GI 2011) <-> its state
// parts in a statistics file, and the registry entry's state hooks
// (include/mcstat/filters/samples/sample_delaying_state.h).
#include "mcstat/filters/samples/sample_delaying_state.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>

#include "mcstat/core/untrusted_text.h"
#include "mcstat/filters/samples/sample_delaying.h"

namespace mcstat {

namespace {

constexpr double kMaxExactCount = 16777216.0;  // 2^24: counts are float32 in the file
/// The parts' names, as every file since format 4 has them.
constexpr const char* kFlatPart = "pajot";
constexpr const char* kDeepPart = "modes";

/// Flat part `pajot`: FLOAT channels, then UINT pairs holding doubles' bit patterns.
const std::vector<std::string> kPajotFloats = {"R",        "G",         "B",     "delayed",
                                               "splatted", "discarded", "taken", "phase",
                                               "run",      "mAdr",      "mRot",  "rotN"};
const std::vector<std::string> kPajotWords = {"sum.R.hi", "sum.R.lo", "sum.G.hi",   "sum.G.lo",
                                              "sum.B.hi", "sum.B.lo", "rotMean.hi", "rotMean.lo",
                                              "rotM2.hi", "rotM2.lo"};
/// Deep part `modes`: one record per mode, ROT single, delayed or learning sample; Z is the
/// record's index within its pixel and A = 1, for deep tools.
const std::vector<std::string> kModeChannels = {"kind", "lo", "hi", "count", "R",
                                                "G",    "B",  "Z",  "A"};
enum RecordKind { kAdrMode = 1, kRotSingle = 2, kDelayed = 3, kLearning = 4 };

size_t recordCount(const PajotState& s) {
    return s.modes.size() + s.rotSingles.size() + s.delayed.size() + s.learning.size();
}

/// Where each of `wanted` is in `have`; false with `err` naming the first one missing.
bool channelIndices(const std::vector<std::string>& have, const std::vector<std::string>& wanted,
                    const char* what, std::vector<size_t>& index, std::string& err) {
    index.clear();
    for (const std::string& w : wanted) {
        const auto it = std::find(have.begin(), have.end(), w);
        if (it == have.end()) {
            err = std::string(what) + " '" + printable(w) + "'";
            return false;
        }
        index.push_back(size_t(it - have.begin()));
    }
    return true;
}

/// One pixel's state from its flat values (in kPajotFloats / kPajotWords order) and records.
bool decodePixel(const float* f, const uint32_t* w, const float* const* rec, uint32_t n, size_t p,
                 int width, PajotState& s, float estimate[3], std::string& err) {
    bool ok = true;
    auto count = [&](float v, const char* what) -> int64_t {
        if (ok && (!(v >= 0.f) || v > float(kMaxExactCount) || v != std::floor(v))) {
            err = "pixel (" + std::to_string(p % size_t(width)) + ", " +
                  std::to_string(p / size_t(width)) + "): part 'pajot' " + what + " = " +
                  std::to_string(v) + " is not a count";
            ok = false;
        }
        return ok ? int64_t(v) : 0;
    };
    for (size_t c = 0; c < 3; ++c) estimate[c] = f[c];
    s.splatted = count(f[4], "splatted");
    s.discarded = count(f[5], "discarded");
    s.taken = count(f[6], "taken");
    const int64_t phase = count(f[7], "phase");
    if (ok && phase > 2) {
        err = "pixel " + std::to_string(p) + ": unknown phase " + std::to_string(phase);
        return false;
    }
    s.phase = PajotPhase(phase);
    s.run = int(count(f[8], "run"));
    s.mAdr = f[9];
    s.mRot = f[10];
    s.rotN = count(f[11], "rotN");
    for (size_t c = 0; c < 3; ++c) s.sum[c] = getStateDouble(w + 2 * c);
    s.rotMean = getStateDouble(w + 6);
    s.rotM2 = getStateDouble(w + 8);
    for (uint32_t i = 0; i < n && ok; ++i) {
        const float* x = rec[i];
        const int64_t kind = count(x[0], "kind");
        const PajotSample smp{{x[4], x[5], x[6]}, x[1]};
        switch (kind) {
            case kAdrMode:
                s.modes.push_back({x[1], x[2], uint32_t(count(x[3], "count"))});
                break;
            case kRotSingle:
                s.rotSingles.push_back(x[1]);
                break;
            case kDelayed:
                s.delayed.push_back(smp);
                break;
            case kLearning:
                s.learning.push_back(smp);
                break;
            default:
                if (ok)
                    err = "pixel " + std::to_string(p) + ": part 'modes' record of unknown kind " +
                          std::to_string(kind);
                ok = false;
        }
    }
    if (ok && double(s.delayed.size()) != double(f[3])) {
        err = "pixel " + std::to_string(p) + ": part 'pajot' says " + std::to_string(f[3]) +
              " delayed, part 'modes' holds " + std::to_string(s.delayed.size());
        ok = false;
    }
    return ok;
}

}  // namespace

bool encodePajotState(const PajotImage& pj, PixelStateParts& out, std::string& err) {
    const size_t pixels = pj.pixels.size(), nf = kPajotFloats.size(), nw = kPajotWords.size();
    if (pj.estimate.size() != pixels * 3) {
        err = "Pajot state does not match the image size";
        return false;
    }
    for (const PajotState& s : pj.pixels)
        if (double(s.taken) > kMaxExactCount) {
            err = "a pixel took more than 2^24 samples, beyond what part 'pajot' stores exactly";
            return false;
        }
    PixelStateParts r;
    r.owner.operation = kPajotName;
    r.owner.params = pajotParamText(pj.params);
    r.owner.flatPart = kFlatPart;
    r.owner.deepPart = kDeepPart;
    r.floatChannels = kPajotFloats;
    r.uintChannels = kPajotWords;
    r.recordChannels = kModeChannels;
    r.floats.resize(pixels * nf);
    r.words.resize(pixels * nw);
    r.recordCounts.resize(pixels);
    for (size_t p = 0; p < pixels; ++p) {
        const PajotState& s = pj.pixels[p];
        float* f = r.floats.data() + p * nf;
        for (size_t c = 0; c < 3; ++c) f[c] = pj.estimate[p * 3 + c];
        f[3] = float(s.delayed.size());
        f[4] = float(s.splatted);
        f[5] = float(s.discarded);
        f[6] = float(s.taken);
        f[7] = float(int(s.phase));
        f[8] = float(s.run);
        f[9] = s.mAdr;
        f[10] = s.mRot;
        f[11] = float(s.rotN);
        uint32_t* w = r.words.data() + p * nw;
        for (size_t c = 0; c < 3; ++c) putStateDouble(w + 2 * c, s.sum[c]);
        putStateDouble(w + 6, s.rotMean);
        putStateDouble(w + 8, s.rotM2);
        r.recordCounts[p] = uint32_t(recordCount(s));
        size_t index = 0;
        auto put = [&](int kind, float lo, float hi, float n, const float* rgb) {
            const float rec[] = {float(kind),
                                 lo,
                                 hi,
                                 n,
                                 rgb ? rgb[0] : 0.f,
                                 rgb ? rgb[1] : 0.f,
                                 rgb ? rgb[2] : 0.f,
                                 float(index++),
                                 1.f};
            r.records.insert(r.records.end(), std::begin(rec), std::end(rec));
        };
        for (const PajotMode& m : s.modes) put(kAdrMode, m.lo, m.hi, float(m.n), nullptr);
        for (float l : s.rotSingles) put(kRotSingle, l, l, 1.f, nullptr);
        for (const PajotSample& d : s.delayed) put(kDelayed, d.l, d.l, 1.f, d.rgb.data());
        for (const PajotSample& d : s.learning) put(kLearning, d.l, d.l, 1.f, d.rgb.data());
    }
    out = std::move(r);
    return true;
}

bool decodePajotState(const PixelStateParts& parts, int width, PajotImage& pj, std::string& err) {
    PajotImage r;
    std::string problem;
    if (parts.owner.operation != kPajotName) {
        err = "the state parts belong to '" + printable(parts.owner.operation) + "', not " +
              kPajotName;
        return false;
    }
    if (!pajotParamsFromText(parts.owner.params, r.params, problem)) {
        err = "part '" + printable(parts.owner.flatPart) + "': parameters: " + problem;
        return false;
    }
    std::vector<size_t> fi, wi, ri;
    if (!channelIndices(parts.floatChannels, kPajotFloats, "part 'pajot' has no FLOAT channel", fi,
                        err) ||
        !channelIndices(parts.uintChannels, kPajotWords, "part 'pajot' has no UINT channel", wi,
                        err) ||
        !channelIndices(parts.recordChannels, kModeChannels, "part 'modes' has no channel", ri,
                        err))
        return false;
    const size_t pixels = parts.recordCounts.size();
    const size_t nf = parts.floatChannels.size(), nw = parts.uintChannels.size();
    const size_t nr = parts.recordChannels.size();
    r.pixels.resize(pixels);
    r.estimate.resize(pixels * 3);
    std::vector<float> f(fi.size()), rec;
    std::vector<uint32_t> w(wi.size());
    std::vector<const float*> recs;
    size_t k = 0;
    for (size_t p = 0; p < pixels; ++p) {
        for (size_t c = 0; c < fi.size(); ++c) f[c] = parts.floats[p * nf + fi[c]];
        for (size_t c = 0; c < wi.size(); ++c) w[c] = parts.words[p * nw + wi[c]];
        const uint32_t n = parts.recordCounts[p];
        rec.resize(size_t(n) * ri.size());
        recs.resize(n);
        for (uint32_t i = 0; i < n; ++i, ++k) {
            for (size_t c = 0; c < ri.size(); ++c)
                rec[i * ri.size() + c] = parts.records[k * nr + ri[c]];
            recs[i] = rec.data() + i * ri.size();
        }
        if (!decodePixel(f.data(), w.data(), recs.data(), n, p, width, r.pixels[p],
                         r.estimate.data() + p * 3, err))
            return false;
    }
    pj = std::move(r);
    return true;
}

bool readPajotParts(const std::string& path, PajotImage& out, std::string& err,
                    const ReadLimits& limits) {
    StatsHeader h;
    PixelStateParts parts;
    if (!readPixelStateParts(path, parts, err, limits, &h)) return false;
    if (!decodePajotState(parts, h.width, out, err)) {
        err = path + ": " + err;
        return false;
    }
    return true;
}

bool readPajotState(SampleSource& src, PajotImage& out, std::string& err) {
    PixelStateParts parts;
    if (!src.readPixelState(parts, err)) return false;
    if (!decodePajotState(parts, src.header().width, out, err)) {
        err = src.path() + ": " + err;
        return false;
    }
    return true;
}

namespace {

/// --info and --check: the state in numbers (docs/pajot.md), what the benchmark's tables report.
bool describePajotState(const PixelStateParts& parts, int width, std::string& text,
                        std::string& err) {
    PajotImage pj;
    if (!decodePajotState(parts, width, pj, err)) return false;
    int64_t single = 0, extended = 0, delayed = 0, discarded = 0, taken = 0, bytes = 0,
            learning = 0, rotOnly = 0;
    for (const PajotState& s : pj.pixels) {
        const PajotCounts c = PajotPixel(s).counts();
        single += c.singleModes;
        extended += c.extendedModes;
        delayed += c.delayed;
        bytes += c.bytes;
        discarded += s.discarded;
        taken += s.taken;
        learning += s.phase == PajotPhase::Learning;
        rotOnly += s.phase == PajotPhase::ROT;
    }
    const double n = double(std::max<size_t>(1, pj.pixels.size()));
    char line[512];
    std::snprintf(line, sizeof line,
                  "  pajot (online, %s): modes per pixel %.3f single, %.3f extended; %.2f bytes "
                  "per pixel (%.3f image buffers of 12 bytes)\n",
                  pajotParamText(pj.params).c_str(), double(single) / n, double(extended) / n,
                  double(bytes) / n, double(bytes) / n / 12.0);
    text = line;
    std::snprintf(line, sizeof line,
                  "  pajot: samples delayed %.4f %% (%lld of %lld), discarded %lld; pixels still "
                  "learning %lld, on ROT alone %lld\n",
                  taken ? 100.0 * double(delayed) / double(taken) : 0.0, (long long)delayed,
                  (long long)taken, (long long)discarded, (long long)learning, (long long)rotOnly);
    text += line;
    return true;
}

/// The renderer's online run: one PajotPixel per pixel, fed float32 RGB in the order taken.
class PajotRun : public OnlineRun {
  public:
    PajotParams params;
    std::vector<PajotPixel> pixels;

    void add(size_t p, const float rgb[3]) override {
        pixels[p].add(rgb, params);  // refuses non-finite values (the renderer counts those)
    }
    bool encode(PixelStateParts& out, std::string& err) override {
        PajotImage pj;
        pj.params = params;
        pj.estimate.resize(pixels.size() * 3);
        pj.pixels.resize(pixels.size());
        for (size_t p = 0; p < pixels.size(); ++p) {
            const std::array<float, 3> e = pixels[p].estimate();
            std::copy(e.begin(), e.end(), pj.estimate.begin() + std::ptrdiff_t(p * 3));
            pj.pixels[p] = std::move(pixels[p].state());  // once, at the end of the run
        }
        return encodePajotState(pj, out, err);
    }
    std::string paramText() const override { return pajotParamText(params); }
    int64_t learningSamples() const override { return params.learning; }
};

std::unique_ptr<OnlineRun> startPajotRun(const ParamValues& values,
                                         const std::array<double, 3>& luma, int width,
                                         size_t pixels, const PixelStateParts* resume,
                                         std::string& err) {
    auto run = std::make_unique<PajotRun>();
    const bool stored = values.at("method").text == "stored";
    if (stored && resume == nullptr) {
        // A new online run needs the estimator to run; "stored" (the default) reads a result.
        err =
            "choose the online estimator, method=adr, rot or hybrid (e.g. --online "
            "pajot:method=hybrid)";
        return nullptr;
    }
    if (!stored) {
        if (!pajotParamsFrom(values, luma, run->params, err)) return nullptr;
    }
    try {
        run->pixels.resize(pixels);
        if (resume != nullptr) {
            PajotImage pj;
            if (!decodePajotState(*resume, width, pj, err)) return nullptr;
            if (!stored && pajotParamText(pj.params) != pajotParamText(run->params)) {
                err = "rendered with pajot " + pajotParamText(pj.params) + ", not " +
                      pajotParamText(run->params);
                return nullptr;
            }
            if (pj.pixels.size() != pixels) {
                err = "the state to resume has " + std::to_string(pj.pixels.size()) +
                      " pixels, the image " + std::to_string(pixels);
                return nullptr;
            }
            run->params = pj.params;
            for (size_t p = 0; p < pixels; ++p)
                run->pixels[p] = PajotPixel(std::move(pj.pixels[p]));
        }
    } catch (const std::exception& e) {
        err = std::string("cannot allocate the Pajot state: ") + e.what();
        return nullptr;
    }
    if (!validatePajotParams(run->params, err)) return nullptr;
    return run;
}

}  // namespace

OperationState pajotStateHooks() {
    OperationState s;
    s.flatPart = kFlatPart;
    s.deepPart = kDeepPart;
    s.describe = &describePajotState;
    s.start = &startPajotRun;
    return s;
}

}  // namespace mcstat
