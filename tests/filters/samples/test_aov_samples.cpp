// AOVs through the per-sample operations (docs/aovs.md): Pajot splats or delays whole samples, RPF
// gives every sample's AOVs the weights its colour gets, so per-sample AOVs that sum to the
// colour keep summing in the result. Over records held in memory (a SampleSource of the test's
// own), so nothing here depends on the file format.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/filters/registry.h"

namespace mcstat {
namespace {

/// Records of a whole image in memory.
class MemorySamples final : public SampleSource {
  public:
    StatsHeader h;
    SampleBlock all;  ///< every row, every channel
    std::vector<std::string> selected;
    std::string name = "memory.mcstat";
    const StatsHeader& header() const override { return h; }
    std::vector<std::string> recordChannels() const override { return all.channels; }
    bool selectRecordChannels(const std::vector<std::string>& channels, std::string&) override {
        selected = {"R", "G", "B", "Z"};
        for (const std::string& c : channels)
            if (std::find(selected.begin(), selected.end(), c) == selected.end())
                selected.push_back(c);
        return true;
    }
    bool readRecords(int y0, int rows, SampleBlock& block, std::string&) override {
        block.clear(y0, rows, all.width);
        block.channels = selected;
        size_t k = 0;
        for (int y = 0; y < y0 + rows; ++y)
            for (int x = 0; x < all.width; ++x) {
                const size_t p = size_t(y) * size_t(all.width) + size_t(x);
                for (uint32_t i = 0; i < all.counts[p]; ++i, ++k) {
                    if (y < y0) continue;
                    for (const std::string& c : selected)
                        block.samples.push_back(
                            all.samples[k * all.stride() + size_t(all.channel(c))]);
                }
                if (y >= y0)
                    block.counts[size_t(y - y0) * size_t(all.width) + size_t(x)] = all.counts[p];
            }
        return true;
    }
    bool readPixelState(PixelStateParts&, std::string& err) override {
        err = name + ": no Pajot state";
        return false;
    }
    const std::string& path() const override { return name; }
};

/// W x H pixels of `spp` samples: the colour is key + fill exactly (values on a 1/64 grid), with
/// fireflies in the key light; alpha 1 or 0; an object label; RPF's fields.
MemorySamples scene(int W, int H, int spp, unsigned seed) {
    MemorySamples m;
    m.h.width = W;
    m.h.height = H;
    m.h.M = 1;
    m.h.spp = spp;
    m.h.hasRecords = true;
    m.h.aovs = {{"A", AovClass::Alpha, ""},      {"key.R", AovClass::Light, ""},
                {"key.G", AovClass::Light, ""},  {"key.B", AovClass::Light, ""},
                {"fill.R", AovClass::Light, ""}, {"fill.G", AovClass::Light, ""},
                {"fill.B", AovClass::Light, ""}, {"objid", AovClass::Id, ""}};
    m.all.width = W;
    m.all.channels = {"R",           "G",           "B",    "Z",    "screen.x", "screen.y",
                      "rand.lens.u", "rand.lens.v", "N1.X", "N1.Y", "N1.Z"};
    for (const AovChannel& a : m.h.aovs) m.all.channels.push_back(kRecordAovPrefix + a.name);
    m.all.counts.assign(size_t(W) * size_t(H), uint32_t(spp));
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> grid(0, 64);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
            for (int i = 0; i < spp; ++i) {
                float key[3], fill[3];
                const bool firefly = u(rng) < 0.03f;
                for (int c = 0; c < 3; ++c) {
                    key[c] = float(grid(rng)) / 64.f * (firefly ? 256.f : 1.f);
                    fill[c] = float(grid(rng)) / 64.f;
                }
                const float alpha = x < W / 2 ? 1.f : 0.f;
                std::vector<float> v = {key[0] + fill[0],
                                        key[1] + fill[1],
                                        key[2] + fill[2],
                                        1.f,
                                        float(x) + u(rng),
                                        float(y) + u(rng),
                                        u(rng),
                                        u(rng),
                                        0.f,
                                        x < W / 2 ? 1.f : 0.f,
                                        0.f};
                v.push_back(alpha);
                v.insert(v.end(), key, key + 3);
                v.insert(v.end(), fill, fill + 3);
                v.push_back(float(1 + (x + i) % 3));
                m.all.samples.insert(m.all.samples.end(), v.begin(), v.end());
            }
    return m;
}

OperationImage runSamples(const char* name, MemorySamples& src,
                          const std::map<std::string, std::string>& kv, int nthreads = 2) {
    const Operation* op = findOperation(name);
    ParamValues values;
    std::string err;
    EXPECT_TRUE(parseOperationParams(*op, kv, values, err)) << err;
    SamplesRequest req;
    req.path = src.name;
    req.source = &src;
    req.params = &values;
    req.luma = {0.2126, 0.7152, 0.0722};
    req.nthreads = nthreads;
    OperationImage out;
    EXPECT_TRUE(op->samples(req, out, err)) << err;
    return out;
}

/// Per pixel and colour channel, |colour - (key + fill)| relative to the colour.
double worstSum(const OperationImage& out) {
    const auto ch = [&](const std::string& n) {
        return size_t(std::find(out.channels.begin(), out.channels.end(), n) -
                      out.channels.begin());
    };
    const size_t nch = out.channels.size();
    double worst = 0;
    for (size_t p = 0; p < size_t(out.width) * size_t(out.height); ++p)
        for (int c = 0; c < 3; ++c) {
            const std::string l(1, "RGB"[c]);
            const double col = out.pixels[p * nch + size_t(c)];
            const double sum = double(out.pixels[p * nch + ch("key." + l)]) +
                               double(out.pixels[p * nch + ch("fill." + l)]);
            worst = std::max(worst, std::abs(col - sum) / std::max(1e-3, std::abs(col)));
        }
    return worst;
}

TEST(AovSamples, PajotSplatsWholeSamples) {
    MemorySamples src = scene(6, 5, 96, 5);
    for (const char* method : {"adr", "rot", "hybrid"}) {
        const OperationImage out = runSamples("pajot", src, {{"method", method}, {"n", "16"}});
        ASSERT_EQ(out.channels.size(), 4 + src.h.aovs.size()) << method;
        EXPECT_EQ(out.channels[4], "A");
        EXPECT_LT(worstSum(out), 1e-6) << method;
        // Labels are one of the samples' labels; alpha the mean of 1s (left) or 0s (right).
        const size_t nch = out.channels.size();
        for (size_t p = 0; p < 30; ++p) {
            const float id = out.pixels[p * nch + nch - 1];
            EXPECT_TRUE(id == 1.f || id == 2.f || id == 3.f) << id;
            EXPECT_EQ(out.pixels[p * nch + 4], (p % 6) < 3 ? 1.f : 0.f);
        }
    }
    // Without AOVs in the file, the result is as before: R, G, B, delayed.
    src.h.aovs.clear();
    EXPECT_EQ(runSamples("pajot", src, {{"method", "hybrid"}}).channels.size(), 4u);
}

TEST(AovSamples, RpfGivesAovsTheColorsWeights) {
    MemorySamples src = scene(12, 10, 8, 9);
    for (const char* spikes : {"0", "1"}) {
        const OperationImage out =
            runSamples("rpf", src, {{"passes", "2"}, {"spikes", spikes}, {"samples", "0.25"}});
        ASSERT_EQ(out.channels.size(), 3 + src.h.aovs.size());
        EXPECT_LT(worstSum(out), 2e-6) << "spikes=" << spikes;
    }
    // The same result with 1 and 2 threads.
    src.h.aovs.resize(4);
    const OperationImage a = runSamples("rpf", src, {{"passes", "1"}});
    const OperationImage b = runSamples("rpf", src, {{"passes", "1"}}, 1);
    EXPECT_EQ(a.pixels, b.pixels);
}

}  // namespace
}  // namespace mcstat
