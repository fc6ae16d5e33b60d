// Speed work must not change a bit: every BufferMeans estimator of the registry, in both modes and
// with several parameter sets, must return bit for bit what the straightforward implementation
// returned (reference_estimators.cpp, the oracle). Pixels are random and adversarial: ties,
// all-equal sets, NaN/Inf buffers, zero and invalid counts, M = 1, 2, even M, M above the fast
// paths' fixed sizes, negatives, signed zeros, denormals, values near FLT_MAX, huge counts. The
// image loop (estimate()) is checked with 1 and 2 threads against the oracle run pixel by pixel.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "mcstat/filters/pixel/detail/rank_keys.h"
#include "mcstat/filters/pixel/gmon.h"
#include "mcstat/filters/pixel/meridian.h"
#include "mcstat/filters/pixel/myriad.h"
#include "mcstat/filters/pixel/ranking.h"
#include "mcstat/filters/pixel/tmpe.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "reference_estimators.h"

using namespace mcstat;

namespace {

const std::array<double, 3> kLuma{0.2126, 0.7152, 0.0722};

using reference::EstimatorFn;

/// The oracle of each estimator that was rewritten for speed, by registry name. An estimator
/// written after that has no oracle and is not checked here (its own tests check its values).
EstimatorFn referenceFor(const std::string& name) {
    static const std::map<std::string, EstimatorFn> table = {
        {"mean", &reference::estimateMean},     {"mon", &reference::estimateMoN},
        {"median", &reference::estimateMoN},    {"gmon", &reference::estimateGMoN},
        {"gmonb", &reference::estimateGMoNb},   {"tmpe", &reference::estimateTMPE},
        {"myriad", &reference::estimateMyriad}, {"meridian", &reference::estimateMeridian},
    };
    const auto it = table.find(name);
    return it == table.end() ? nullptr : it->second;
}

/// One parameter set: the oracle's struct and the same values as the registry's text, so that
/// the library's estimator is bound through its registry entry as every caller binds it.
struct ParamSet {
    reference::EstimatorParams ref;
    std::map<std::string, std::string> text;  ///< every estimator's keys; each takes its own
};

/// `op` bound to `set` (the keys it has).
PixelKernel bind(const Operation& op, const ParamSet& set) {
    std::map<std::string, std::string> kv;
    for (const auto& [k, v] : set.text)
        if (op.param(k)) kv[k] = v;
    ParamValues values;
    std::string err;
    if (!parseOperationParams(op, kv, values, err)) ADD_FAILURE() << err;
    return op.bindPixel(values, set.ref.luma);
}

/// Bit-for-bit equality of every field (memcmp of the floats: -0 vs +0 and NaN payloads count).
bool sameBits(const PixelEstimate& a, const PixelEstimate& b) {
    return std::memcmp(a.rgb.data(), b.rgb.data(), sizeof(a.rgb)) == 0 &&
           std::memcmp(a.gini.data(), b.gini.data(), sizeof(a.gini)) == 0 && a.kept == b.kept &&
           a.excluded == b.excluded;
}

std::string describe(const std::vector<float>& mean, const std::vector<float>& count) {
    std::ostringstream o;
    o.precision(9);
    for (size_t j = 0; j < count.size(); ++j)
        o << "(" << mean[3 * j] << "," << mean[3 * j + 1] << "," << mean[3 * j + 2] << " n"
          << count[j] << ") ";
    return o.str();
}

std::string describe(const PixelEstimate& e) {
    std::ostringstream o;
    o.precision(9);
    o << "rgb " << e.rgb[0] << " " << e.rgb[1] << " " << e.rgb[2] << " gini " << e.gini[0] << " "
      << e.gini[1] << " " << e.gini[2] << " kept " << e.kept[0] << " " << e.kept[1] << " "
      << e.kept[2] << " excluded " << e.excluded;
    return o.str();
}

/// Random adversarial pixels: one of several value families, count families and colour
/// structures, with duplicates and invalid buffers mixed in.
class PixelGen {
  public:
    explicit PixelGen(uint32_t seed) : rng_(seed) {}

    void make(int M, std::vector<float>& mean, std::vector<float>& count) {
        mean.assign(size_t(M) * 3, 0.f);
        count.assign(size_t(M), 0.f);
        const int family = pick(10);
        const int counts = pick(6);
        const int color = pick(3);
        for (int j = 0; j < M; ++j) {
            const float v = value(family);
            for (int c = 0; c < 3; ++c)
                mean[size_t(j) * 3 + c] = color == 0 ? v : color == 1 ? value(family) : v * (c + 1);
            count[size_t(j)] = countValue(counts);
        }
        // Duplicates: whole buffers copied (luminance and channel ties), sometimes other counts.
        if (M > 1 && pick(2) == 0) {
            const int dups = 1 + pick(M);
            for (int d = 0; d < dups; ++d) {
                const int a = pick(M), b = pick(M);
                for (int c = 0; c < 3; ++c) mean[size_t(a) * 3 + c] = mean[size_t(b) * 3 + c];
                if (pick(2) == 0) count[size_t(a)] = count[size_t(b)];
            }
        }
        // Invalid buffers: NaN/Inf in a channel or in the count, negative counts.
        if (pick(4) == 0) {
            const int bad = 1 + pick(std::max(1, M / 3));
            for (int d = 0; d < bad; ++d) {
                const int j = pick(M);
                const float special[] = {std::numeric_limits<float>::quiet_NaN(),
                                         std::numeric_limits<float>::infinity(),
                                         -std::numeric_limits<float>::infinity()};
                switch (pick(3)) {
                    case 0:
                        mean[size_t(j) * 3 + size_t(pick(3))] = special[pick(3)];
                        break;
                    case 1:
                        count[size_t(j)] = special[pick(3)];
                        break;
                    default:
                        count[size_t(j)] = -1.f;
                        break;
                }
            }
        }
    }

  private:
    int pick(int n) { return int(rng_() % uint32_t(n)); }
    float uni(float a, float b) { return std::uniform_real_distribution<float>(a, b)(rng_); }

    float value(int family) {
        switch (family) {
            case 0:  // a noisy pixel
                return uni(0.2f, 0.3f);
            case 1:  // fireflies
                return uni(0.f, 1.f) * (pick(10) == 0 ? 1000.f : 1.f);
            case 2: {  // few distinct values: ties everywhere
                const float v[] = {0.f, 0.5f, 1.f, 2.f};
                return v[pick(4)];
            }
            case 3:  // all equal
                return 0.75f;
            case 4:  // negatives and signed zeros
                return pick(5) == 0 ? (pick(2) ? -0.f : 0.f) : uni(-1.f, 1.f);
            case 5: {  // denormals and zeros
                const float v[] = {0.f, 1e-45f, 3e-45f, 1e-40f, 1e-38f, -1e-45f};
                return v[pick(6)];
            }
            case 6: {  // near FLT_MAX, both signs
                const float v[] = {1e38f, 3.4e38f, -3.4e38f, 3.3e38f, 1.f, 0.f};
                return v[pick(6)];
            }
            case 7:  // wide dynamic range
                return std::ldexp(uni(0.5f, 1.f), pick(200) - 100) * (pick(4) == 0 ? -1.f : 1.f);
            case 8:  // values one ulp apart (float keys close, luminance keys distinct)
                return std::nextafter(1.f, 2.f) * float(1 + pick(3)) +
                       float(pick(3)) * std::numeric_limits<float>::epsilon();
            default:  // any float bit pattern that is finite
            {
                float f;
                do {
                    const uint32_t bits = uint32_t(rng_());
                    std::memcpy(&f, &bits, sizeof f);
                } while (!std::isfinite(f));
                return f;
            }
        }
    }

    float countValue(int family) {
        switch (family) {
            case 0:
                return 64.f;
            case 1:  // spp < M: many empty buffers
                return float(pick(3));
            case 2:
                return float(1 + pick(1000));
            case 3: {  // huge and fractional counts
                const float v[] = {1e30f, 3e38f, 0.5f, 1e-30f, 7.f};
                return v[pick(5)];
            }
            case 4:
                return 1.f;
            default:
                return uni(0.f, 100.f);
        }
    }

    std::mt19937 rng_;
};

/// Parameter sets: the registry defaults in both modes, plus values that move the trim and scale
/// rules (threshold, alpha, gamma, delta, absolute scales), and the rules before issue 38.
std::vector<ParamSet> parameterSets() {
    std::vector<ParamSet> v;
    for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
        // The registry's defaults (issue 38: gini=abs, scale=hampel).
        ParamSet d;
        d.ref.mode = mode;
        d.ref.luma = kLuma;
        d.ref.giniMagnitudes = true;
        d.ref.scaleHampel = true;
        d.text["mode"] = mode == EstimatorMode::Luminance ? "lum" : "channel";
        v.push_back(d);
        ParamSet h = d;  // the new rules with other values
        h.ref.giniThreshold = 0.0;
        h.ref.gamma = 1e-3;
        h.ref.delta = 2.0;
        h.text.insert({{"threshold", "0"}, {"gamma", "1e-3"}, {"delta", "2"}});
        v.push_back(h);
        // The forms before issue 38 (the papers' and this oracle's), with other values.
        ParamSet p;
        p.ref.mode = mode;
        p.ref.luma = kLuma;
        p.text["mode"] = d.text["mode"];
        p.text.insert({{"gini", "shift"}, {"scale", "rel"}});
        v.push_back(p);
        ParamSet q = p;
        q.ref.giniThreshold = 0.0;
        q.ref.alpha = 0.5;
        q.ref.gamma = 1e-3;
        q.ref.delta = 2.0;
        q.text.insert({{"threshold", "0"}, {"alpha", "0.5"}, {"gamma", "1e-3"}, {"delta", "2"}});
        v.push_back(q);
        ParamSet r = p;
        r.ref.giniThreshold = 0.6;
        r.ref.alpha = 0.1;
        r.ref.gamma = 0.5;
        r.ref.delta = 1e-4;
        r.ref.scaleRelative = false;
        r.text.insert({{"threshold", "0.6"},
                       {"alpha", "0.1"},
                       {"gamma", "0.5"},
                       {"delta", "1e-4"},
                       {"scale", "abs"}});
        r.text["scale"] = "abs";  // p's "rel" stays under insert
        v.push_back(r);
        ParamSet z = p;
        z.ref.alpha = 0.0;
        z.ref.gamma = 1e30;
        z.ref.delta = 1e-30;
        z.text.insert({{"alpha", "0"}, {"gamma", "1e30"}, {"delta", "1e-30"}});
        v.push_back(z);
    }
    return v;
}

const std::vector<int> kSizes = {1,  2,  3,  4,  5,  6,  7,  8,  9,  16,
                                 17, 20, 21, 31, 32, 33, 64, 65, 100};

void checkEstimator(const Operation& op, int pixelsPerCase) {
    const EstimatorFn ref = referenceFor(op.name);
    ASSERT_NE(ref, nullptr) << op.name << " has no oracle in reference_estimators";
    PixelGen gen(0x5eed1u + uint32_t(op.name.size()) * 7919u);
    std::vector<float> mean, count;
    EstimatorScratch sNew, sRef;  // reused across pixels, as the image loop does
    int checked = 0;
    for (const ParamSet& set : parameterSets()) {
        const PixelKernel kernel = bind(op, set);
        const reference::EstimatorParams& p = set.ref;
        for (int M : kSizes) {
            // The iterative estimators are slow in the oracle: fewer pixels at large M.
            const int n = op.name == "myriad" && M > 33 ? pixelsPerCase / 8 : pixelsPerCase;
            for (int i = 0; i < n; ++i) {
                gen.make(M, mean, count);
                const PixelBuffers px{mean.data(), count.data(), M};
                PixelEstimate a, b;
                // Garbage in the outputs first: the estimators must set every field.
                std::memset(static_cast<void*>(&a), 0x7f, sizeof a);
                std::memset(static_cast<void*>(&b), 0x7f, sizeof b);
                kernel.estimate(px, a, sNew);
                ref(px, p, b, sRef);
                ASSERT_TRUE(sameBits(a, b))
                    << op.name << " mode " << (p.mode == EstimatorMode::Luminance ? "lum" : "ch")
                    << " M " << M << "\n  new " << describe(a) << "\n  ref " << describe(b)
                    << "\n  pixel " << describe(mean, count);
                ++checked;
            }
        }
    }
    EXPECT_GT(checked, 0);
}

}  // namespace

TEST(BitIdentity, Mean) { checkEstimator(*findEstimator("mean"), 600); }
TEST(BitIdentity, MoN) { checkEstimator(*findEstimator("mon"), 600); }
TEST(BitIdentity, Median) { checkEstimator(*findEstimator("median"), 100); }
TEST(BitIdentity, GMoN) { checkEstimator(*findEstimator("gmon"), 1000); }
TEST(BitIdentity, GMoNb) { checkEstimator(*findEstimator("gmonb"), 600); }
TEST(BitIdentity, TMPE) { checkEstimator(*findEstimator("tmpe"), 600); }

// The rank estimators' portable fast path (taken on CPUs without AVX2) against the oracle too.
TEST(BitIdentity, PortableFastPath) {
    const bool before = detail::setUseAvx2(false);
    for (const char* name : {"mean", "mon", "gmon", "gmonb", "tmpe"})
        checkEstimator(*findEstimator(name), 200);
    detail::setUseAvx2(before);
}

// Luminances that differ in double but round to the same float: the AVX2 ranking compares rounded
// keys first and must fall back to the doubles for them (ties in float, an order in double).
TEST(BitIdentity, KeysEqualInFloat) {
    std::mt19937 rng(77);
    ParamSet set;
    set.ref.luma = kLuma;
    set.ref.giniMagnitudes = true;  // the registry default; positive keys: the same G
    const reference::EstimatorParams& p = set.ref;
    for (int M : {5, 8, 17, 21, 33, 64}) {
        std::vector<float> mean(size_t(M) * 3), count(size_t(M), 4.f);
        for (int rep = 0; rep < 200; ++rep) {
            const float base = std::uniform_real_distribution<float>(0.1f, 10.f)(rng);
            for (int j = 0; j < M; ++j) {
                // Red a few ulps apart, green and blue shared: luminances ~0.2 ulp apart.
                float r = base;
                for (int u = int(rng() % 4); u > 0; --u) r = std::nextafter(r, 100.f);
                mean[3 * size_t(j)] = r;
                mean[3 * size_t(j) + 1] = base;
                mean[3 * size_t(j) + 2] = base;
                if (rng() % 8 == 0) mean[3 * size_t(j) + 1] = base * 3.f;  // an outlier
            }
            const PixelBuffers px{mean.data(), count.data(), M};
            for (const char* name : {"mon", "gmon", "gmonb", "tmpe"}) {
                const Operation& op = *findEstimator(name);
                EstimatorScratch sa, sb;
                PixelEstimate a, b;
                bind(op, set).estimate(px, a, sa);
                referenceFor(op.name)(px, p, b, sb);
                ASSERT_TRUE(sameBits(a, b))
                    << name << " M " << M << "\n  new " << describe(a) << "\n  ref " << describe(b);
            }
        }
    }
}

TEST(BitIdentity, Meridian) { checkEstimator(*findEstimator("meridian"), 250); }
TEST(BitIdentity, Myriad) { checkEstimator(*findEstimator("myriad"), 60); }

// The building blocks the estimators are made of are public API too.
TEST(BitIdentity, BuildingBlocks) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-2.0, 2.0);
    for (int it = 0; it < 2000; ++it) {
        const int K = 1 + int(rng() % 40);
        std::vector<double> x(static_cast<size_t>(K)), w(static_cast<size_t>(K));
        for (int j = 0; j < K; ++j) {
            x[size_t(j)] = u(rng) * (rng() % 5 == 0 ? 1000.0 : 1.0);
            w[size_t(j)] = 1.0 + double(rng() % 5);
        }
        std::sort(x.begin(), x.end());
        x.erase(std::unique(x.begin(), x.end()), x.end());
        const int Kd = int(x.size());
        const double scale = std::pow(10.0, double(int(rng() % 9)) - 4.0);
        const double beta = u(rng);
        auto bits = [](double d) {
            uint64_t b;
            std::memcpy(&b, &d, sizeof b);
            return b;
        };
        EXPECT_EQ(bits(giniSorted(x.data(), size_t(Kd))),
                  bits(reference::giniSorted(x.data(), size_t(Kd))));
        const double G = u(rng) * 0.5 + 0.5;
        EXPECT_EQ(gmonTrim(G, Kd), reference::gmonTrim(G, Kd));
        EXPECT_EQ(bits(meridianCost(x.data(), w.data(), Kd, scale, beta)),
                  bits(reference::meridianCost(x.data(), w.data(), Kd, scale, beta)));
        EXPECT_EQ(bits(myriadCost(x.data(), w.data(), Kd, scale, beta)),
                  bits(reference::myriadCost(x.data(), w.data(), Kd, scale, beta)));
        EXPECT_EQ(meridianSorted(x.data(), w.data(), Kd, scale),
                  reference::meridianSorted(x.data(), w.data(), Kd, scale));
        if (it % 4 == 0) {
            EXPECT_EQ(bits(myriadSorted(x.data(), w.data(), Kd, scale)),
                      bits(reference::myriadSorted(x.data(), w.data(), Kd, scale)));
        }
    }
    for (int M = 0; M < 70; ++M)
        for (double a : {0.0, 0.05, 0.1, 0.25, 1.0 / 3.0, 0.5, 1.0})
            EXPECT_EQ(tmpeTrim(a, M), reference::tmpeTrim(a, M));
}

// The image loop: every BufferMeans estimator over an adversarial image, 1 and 2 threads, equal to
// the oracle pixel by pixel (the loop must not depend on how the image is split over threads).
TEST(BitIdentity, ImageLoopOneAndTwoThreads) {
    const int W = 37, H = 23, M = 9;
    StatsImage img;
    img.header.width = W;
    img.header.height = H;
    img.header.M = M;
    std::string err;
    ASSERT_TRUE(img.allocate(err)) << err;
    PixelGen gen(99);
    std::vector<float> mean, count;
    for (size_t p = 0; p < img.pixelCount(); ++p) {
        gen.make(M, mean, count);
        std::copy(mean.begin(), mean.end(), img.bufferMean.begin() + long(p) * M * 3);
        std::copy(count.begin(), count.end(), img.bufferCount.begin() + long(p) * M);
    }
    for (const Operation& op : estimatorRegistry())
        for (const ParamSet& set : parameterSets()) {
            const reference::EstimatorParams& p = set.ref;
            const EstimatorMode mode = p.mode;
            const EstimatorFn ref = referenceFor(op.name);
            if (ref == nullptr) continue;  // no oracle: not one of the rewritten estimators
            // An estimator without a mode parameter (the mean) is the same in both: its result
            // has the luminance layout of diagnostics.
            if (mode == EstimatorMode::PerChannel && !op.param("mode")) continue;
            for (int threads : {1, 2}) {
                OIIO::ImageBuf out = estimate(img, op, bind(op, set), true, {}, threads);
                ASSERT_FALSE(out.has_error()) << out.geterror();
                const int nch = out.nchannels();
                const float* px = static_cast<const float*>(out.localpixels());
                ASSERT_NE(px, nullptr);
                EstimatorScratch s;
                for (size_t i = 0; i < img.pixelCount(); ++i) {
                    PixelEstimate b;
                    ref(img.pixelBuffers(i), p, b, s);
                    const float* o = px + i * size_t(nch);
                    ASSERT_EQ(std::memcmp(o, b.rgb.data(), 3 * sizeof(float)), 0)
                        << op.name << " pixel " << i << " threads " << threads;
                    if (mode == EstimatorMode::Luminance) {
                        ASSERT_EQ(std::memcmp(o + 3, &b.gini[0], sizeof(float)), 0);
                        ASSERT_EQ(o[4], float(b.kept[0]));
                        ASSERT_EQ(o[5], float(b.excluded));
                    } else {
                        ASSERT_EQ(std::memcmp(o + 3, b.gini.data(), 3 * sizeof(float)), 0);
                        for (int c = 0; c < 3; ++c) ASSERT_EQ(o[6 + c], float(b.kept[size_t(c)]));
                        ASSERT_EQ(o[9], float(b.excluded));
                    }
                }
            }
        }
}
