// Mitsuba 3's references (a mean image plus its per-sample variance image) against statistics
// files: mcstat's own rule with the reference's noise, and Mitsuba 3's render-test rule
// (CompareOptions::Rule::Mitsuba, after mitsuba-renderer/mitsuba3 src/render/tests/test_renders.py)
// on a synthetic pair whose truth is known: both rules agree where the answer is clear, and
// differ where docs/compare.md says they do. Then the reports (compare_report.h) of such a result,
// parsed back.
#include <OpenImageIO/imagebufalgo.h>
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>

#include "mcstat/compare/compare.h"
#include "mcstat/compare/report/compare_report.h"
#include "mcstat/image/imageops.h"

namespace mcstat {
namespace {

constexpr int kW = 64, kH = 64, kM = 8;
constexpr float kCount = 16.f;  // samples per buffer: N = 128 per pixel

using Field = std::function<double(int, int)>;

/// A render of the field `value` whose single samples have deviation `sampleSigma(x, y)`: each
/// buffer mean of 16 samples gets Gaussian noise of sampleSigma / 4, grey (R = G = B).
std::shared_ptr<StatsImage> render(uint64_t seed, const Field& value, const Field& sampleSigma) {
    auto img = std::make_shared<StatsImage>();
    img->header.width = kW;
    img->header.height = kH;
    img->header.M = kM;
    img->header.spp = int(kCount) * kM;
    std::string err;
    EXPECT_TRUE(img->allocate(err)) << err;
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> unit(0.0, 1.0);
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            const size_t p = size_t(y) * kW + size_t(x);
            double sum = 0.0;
            for (int j = 0; j < kM; ++j) {
                const double v = value(x, y) + sampleSigma(x, y) / 4.0 * unit(rng);
                const size_t k = p * kM + size_t(j);
                for (int c = 0; c < 3; ++c) img->bufferMean[k * 3 + size_t(c)] = float(v);
                img->bufferCount[k] = kCount;
                sum += v;
            }
            img->count[p] = kCount * kM;
            for (int c = 0; c < 3; ++c)
                img->beauty[p * 3 + size_t(c)] = img->mean[p * 3 + size_t(c)] = float(sum / kM);
        }
    return img;
}

/// The reference as Mitsuba stores it: the exact mean and the per-sample variance, R, G, B.
void reference(const Field& value, const Field& sampleSigma, OIIO::ImageBuf& mean,
               OIIO::ImageBuf& var) {
    const OIIO::ROI roi(0, kW, 0, kH, 0, 1, 0, 3);
    mean.reset(floatSpec(roi, {"R", "G", "B"}));
    var.reset(floatSpec(roi, {"R", "G", "B"}));
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            const float m[3] = {float(value(x, y)), float(value(x, y)), float(value(x, y))};
            const float s2 = float(sampleSigma(x, y) * sampleSigma(x, y));
            const float v[3] = {s2, s2, s2};
            mean.setpixel(x, y, m);
            var.setpixel(x, y, v);
        }
}

struct Decisions {
    CompareResult mcstat, mitsuba;
};

/// Both rules on the render `b` against the reference of (value, sigma) of 4096 spp.
Decisions decide(const std::shared_ptr<StatsImage>& b, const Field& value, const Field& sigma) {
    OIIO::ImageBuf mean, var;
    reference(value, sigma, mean, var);
    Decisions d;
    std::string err;
    CompareOptions o;
    o.luma = {0.25, 0.5, 0.25};
    o.referenceSpp = 4096.0;
    MemoryStatsSource sb(b, "b.mcstat");
    EXPECT_TRUE(compareStatsToImage(mean, "ref.exr", sb, o, d.mcstat, err, &var)) << err;
    o.rule = CompareOptions::Rule::Mitsuba;
    EXPECT_TRUE(compareStatsToImage(mean, "ref.exr", sb, o, d.mitsuba, err, &var)) << err;
    return d;
}

const Field kOne = [](int, int) { return 1.0; };
const Field kSigma = [](int, int) { return 0.4; };  // per sample; 0.035 per pixel mean

TEST(CompareReference, BothRulesPassTheSameSceneAndFailAClearChange) {
    const Decisions same = decide(render(1, kOne, kSigma), kOne, kSigma);
    EXPECT_FALSE(same.mcstat.fail) << compareVerdict(same.mcstat, {});
    EXPECT_FALSE(same.mitsuba.fail);
    // Mitsuba's Sidak level for 4096 pixels at 1 %: 1 - 0.99^(1/4096).
    EXPECT_NEAR(same.mitsuba.threshold, 2.4537e-6, 1e-9);
    EXPECT_EQ(same.mitsuba.channelTests, size_t(3 * kW * kH));
    EXPECT_EQ(same.mitsuba.tile, 0);
    EXPECT_EQ(same.mitsuba.quantities, (std::vector<std::string>{"R", "G", "B"}));

    // 20 % brighter: 5.7 standard errors per pixel.
    const Field bright = [](int, int) { return 1.2; };
    const Decisions diff = decide(render(2, bright, kSigma), kOne, kSigma);
    EXPECT_TRUE(diff.mcstat.fail);
    EXPECT_TRUE(diff.mitsuba.fail);
    EXPECT_GT(diff.mitsuba.pixelsRejected, size_t(kW * kH / 4));
    EXPECT_GT(diff.mcstat.pixelsRejected, size_t(kW * kH / 4));
    EXPECT_EQ(compareVerdict(diff.mitsuba, {}).rfind("DIFFERENT", 0), 0u);
}

TEST(CompareReference, WhereTheRulesDiffer) {
    // A dark region (per-sample deviation 0.004: variance 1.6e-5, under Mitsuba's 1e-4 floor)
    // twice as bright: mcstat finds it (5.7 standard errors); the floor silences it for Mitsuba (z
    // = 2.3).
    const Field darkSigma = [](int x, int) { return x < 32 ? 0.004 : 0.4; };
    const Field dark = [](int x, int) { return x < 32 ? 0.002 : 1.0; };
    const Field darker = [](int x, int) { return x < 32 ? 0.004 : 1.0; };
    const Decisions d1 = decide(render(3, darker, darkSigma), dark, darkSigma);
    EXPECT_TRUE(d1.mcstat.fail);
    EXPECT_GT(d1.mcstat.pixelsRejected, size_t(32 * 64 / 2));
    EXPECT_FALSE(d1.mitsuba.fail);
    // ... and the same render against itself passes both (the floor is no false alarm there).
    const Decisions d1same = decide(render(4, dark, darkSigma), dark, darkSigma);
    EXPECT_FALSE(d1same.mcstat.fail);
    EXPECT_FALSE(d1same.mitsuba.fail);

    // 8 pixels of 4096 changed beyond doubt: Mitsuba lets 0.25 % of channel tests fail (30 of
    // 12,288), so 24 failures pass; mcstat declares them.
    const Field spot = [](int x, int y) { return x < 8 && y == 5 ? 2.0 : 1.0; };
    const Decisions d2 = decide(render(5, spot, kSigma), kOne, kSigma);
    EXPECT_TRUE(d2.mcstat.fail);
    EXPECT_EQ(d2.mcstat.pixelsRejected, 8u);
    EXPECT_FALSE(d2.mitsuba.fail);
    EXPECT_EQ(d2.mitsuba.pixelsRejected, 8u);
    EXPECT_EQ(d2.mitsuba.channelTests - d2.mitsuba.channelTestsPassed, 24u);

    // Everything 2 % brighter: 0.57 standard errors per pixel, which no pixel test shows;
    // mcstat's 16 x 16 tiles (9 standard errors) do.
    const Field two = [](int, int) { return 1.02; };
    const Decisions d3 = decide(render(6, two, kSigma), kOne, kSigma);
    EXPECT_TRUE(d3.mcstat.fail);
    EXPECT_EQ(d3.mcstat.tilesRejected, 16u);
    EXPECT_FALSE(d3.mitsuba.fail);
}

TEST(CompareReference, RefusesWhatTheRulesCannotUse) {
    OIIO::ImageBuf mean, var;
    reference(kOne, kSigma, mean, var);
    auto b = render(7, kOne, kSigma);
    MemoryStatsSource sb(b, "b.mcstat");
    CompareOptions o;
    CompareResult r;
    std::string err;
    // The variance of one sample needs the reference's sample count.
    EXPECT_FALSE(compareStatsToImage(mean, "ref.exr", sb, o, r, err, &var));
    EXPECT_NE(err.find("refspp"), std::string::npos) << err;
    o.rule = CompareOptions::Rule::Mitsuba;
    EXPECT_FALSE(compareStatsToImage(mean, "ref.exr", sb, o, r, err));
    EXPECT_NE(err.find("refvar"), std::string::npos) << err;
    MemoryStatsSource sa(b, "a.mcstat");
    EXPECT_FALSE(compareStats(sa, sb, o, r, err));
    EXPECT_NE(err.find("statistics files"), std::string::npos) << err;
    OIIO::ImageBuf small(floatSpec(OIIO::ROI(0, 8, 0, 8, 0, 1, 0, 3), {"R", "G", "B"}));
    EXPECT_FALSE(compareStatsToImage(mean, "ref.exr", sb, o, r, err, &small));
    EXPECT_NE(err.find("variance image"), std::string::npos) << err;
}

TEST(CompareReport, JsonAndJUnitHoldTheVerdictAndItsNumbers) {
    const Field spot = [](int x, int y) { return x < 8 && y == 5 ? 2.0 : 1.0; };
    OIIO::ImageBuf mean, var;
    reference(kOne, kSigma, mean, var);
    auto b = render(8, spot, kSigma);
    MemoryStatsSource sb(b, "b.mcstat");
    CompareOptions o;
    o.luma = {0.25, 0.5, 0.25};
    CompareResult r;
    std::string err;
    ASSERT_TRUE(compareStatsToImage(mean, "ref.exr", sb, o, r, err)) << err;
    ASSERT_TRUE(r.fail);
    CompareReportRequest req;
    req.name = "spot <&\"'> test";
    req.a = {"ref.exr", {"ref.exr"}};
    req.b = {"b.mcstat", {"seed_1.exr", "seed_2.exr"}};
    const nlohmann::json j = nlohmann::json::parse(compareJson(r, o, req));
    EXPECT_EQ(j["verdict"], "DIFFERENT");
    EXPECT_EQ(j["exit_code"], 2);
    EXPECT_EQ(j["name"], req.name);
    EXPECT_EQ(j["test"]["test"], "one-sample-t");
    EXPECT_EQ(j["test"]["level"], 0.01);
    EXPECT_EQ(j["pixels"]["total"], kW * kH);
    EXPECT_EQ(j["pixels"]["differing"], r.pixelsRejected);
    EXPECT_EQ(j["tiles"]["tested"], 16);
    EXPECT_EQ(j["strongest_pixel"]["y"], 5);
    EXPECT_LT(j["strongest_pixel"]["x"].get<int>(), 8);
    EXPECT_NEAR(j["strongest_pixel"]["effect"].get<double>(), 1.0, 0.2);
    EXPECT_EQ(j["strongest_tile"]["x"], 0);
    EXPECT_EQ(j["inputs"]["b"]["files"].size(), 2u);
    EXPECT_EQ(j["verdict_line"], compareVerdict(r, o));

    const std::string x = compareJUnit(r, o, req);
    EXPECT_NE(x.find("name=\"spot &lt;&amp;&quot;&apos;&gt; test\""), std::string::npos) << x;
    EXPECT_NE(x.find("<failure message=\"DIFFERENT: "), std::string::npos) << x;
    EXPECT_NE(x.find("tests=\"1\" failures=\"1\""), std::string::npos) << x;
    EXPECT_EQ(x.find(req.name), std::string::npos);  // never unescaped

    // The same render against the unchanged reference passes: no <failure>.
    auto same = render(9, kOne, kSigma);
    MemoryStatsSource ss(same, "same.mcstat");
    ASSERT_TRUE(compareStatsToImage(mean, "ref.exr", ss, o, r, err)) << err;
    EXPECT_EQ(compareJUnit(r, o, req).find("<failure"), std::string::npos);
    EXPECT_EQ(nlohmann::json::parse(compareJson(r, o, req))["verdict"], "SAME");
}

}  // namespace
}  // namespace mcstat
