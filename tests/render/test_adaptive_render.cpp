// Adaptive buffer count in the renderer (Jung 2016, section 4.2.4, eq. 4.15; docs/adaptive-m.md):
// the rule, the pilot's sigma_image, determinism for any thread count, the round-robin rule with
// M_p, and fireflies getting more buffers than smooth pixels.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include "mcstat/render/render.h"
#include "mcstat/render/scene.h"

namespace {

using mcstat::StatsImage;
using namespace mcstat::render;
using mcstat::render::render;

Scene mustLoad(const std::string& name) {
    Scene s;
    std::string err;
    EXPECT_TRUE(loadScene(name, s, err)) << err;
    return s;
}

StatsImage mustRender(const Scene& scene, const RenderOptions& opt) {
    StatsImage img;
    std::string err;
    EXPECT_TRUE(render(scene, opt, img, err)) << err;
    return img;
}

RenderOptions adaptive(int64_t spp, int64_t pilot, int threads = 0, int mMax = 17) {
    RenderOptions o;
    o.spp = spp;
    o.seed = 5;
    o.threads = threads;
    o.adaptiveM = true;
    o.mMax = mMax;
    o.pilotSpp = pilot;
    return o;
}

bool sameBits(const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() &&
           (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

TEST(AdaptiveRule, Eq415OnHandComputedRatios) {
    // ratio < 1: one buffer
    EXPECT_EQ(adaptiveBufferCount(0.999, 1.0, 17), 1);
    EXPECT_EQ(adaptiveBufferCount(0.0, 1.0, 17), 1);
    // ratio exactly 1: floor(log2 1) = 0 -> 2 (0 + 1) + 1 = 3
    EXPECT_EQ(adaptiveBufferCount(1.0, 1.0, 17), 3);
    EXPECT_EQ(adaptiveBufferCount(0.25, 0.25, 17), 3);
    EXPECT_EQ(adaptiveBufferCount(1.999, 1.0, 17), 3);
    // ratio exactly 2: floor(log2 2) = 1 -> 5; 4 -> 7; 8 -> 9; 128 -> 17
    EXPECT_EQ(adaptiveBufferCount(2.0, 1.0, 17), 5);
    EXPECT_EQ(adaptiveBufferCount(3.0, 1.5, 17), 5);
    EXPECT_EQ(adaptiveBufferCount(3.999, 1.0, 17), 5);
    EXPECT_EQ(adaptiveBufferCount(4.0, 1.0, 17), 7);
    EXPECT_EQ(adaptiveBufferCount(8.0, 1.0, 17), 9);
    EXPECT_EQ(adaptiveBufferCount(127.9, 1.0, 17), 15);
    EXPECT_EQ(adaptiveBufferCount(128.0, 1.0, 17), 17);
    // capped at M_max: 256 -> 19 -> 17; 1e6: floor(log2 1e6) = 19 -> 41 -> 17 (41 when allowed)
    EXPECT_EQ(adaptiveBufferCount(256.0, 1.0, 17), 17);
    EXPECT_EQ(adaptiveBufferCount(1e6, 1.0, 17), 17);
    EXPECT_EQ(adaptiveBufferCount(1e6, 1.0, 999), 41);
    EXPECT_EQ(adaptiveBufferCount(1e6, 1.0, 7), 7);
    EXPECT_EQ(adaptiveBufferCount(1e6, 1.0, 1), 1);
    // sigma_image = 0: a noiseless pixel gets 1, a noisy one (infinite ratio) M_max
    EXPECT_EQ(adaptiveBufferCount(0.0, 0.0, 17), 1);
    EXPECT_EQ(adaptiveBufferCount(1e-300, 0.0, 17), 17);
    // ratio overflowing to infinity
    EXPECT_EQ(adaptiveBufferCount(1e300, 1e-300, 17), 17);
}

TEST(AdaptiveRule, PilotSamplesDefaultAndOptions) {
    RenderOptions o = adaptive(1000, 0);
    EXPECT_EQ(pilotSamples(o), 125);  // spp / 8
    o.spp = 100;
    EXPECT_EQ(pilotSamples(o), 64);  // at least 64 ...
    o.spp = 10;
    EXPECT_EQ(pilotSamples(o), 10);  // ... but never more than spp
    o.pilotSpp = 3;
    EXPECT_EQ(pilotSamples(o), 3);

    std::string err;
    o.mMax = 16;
    EXPECT_FALSE(validateOptions(o, err));
    EXPECT_NE(err.find("m-max must be odd"), std::string::npos) << err;
    o.mMax = 1001;
    EXPECT_FALSE(validateOptions(o, err));
    o.mMax = 17;
    o.pilotSpp = -1;
    EXPECT_FALSE(validateOptions(o, err));
    o.adaptiveM = false;  // ignored without adaptive M
    o.mMax = 16;
    EXPECT_TRUE(validateOptions(o, err)) << err;
}

TEST(AdaptiveRender, DeterministicForAnyThreadCountAndByteIdenticalFiles) {
    namespace fs = std::filesystem;
    const Scene s = mustLoad("tiny");
    const StatsImage one = mustRender(s, adaptive(20, 12, 1));
    ASSERT_TRUE(one.header.adaptiveM);
    const fs::path dir = fs::temp_directory_path() /
                         ("mcstat_adaptive_test_" +
                          std::to_string(::testing::UnitTest::GetInstance()->random_seed()));
    fs::create_directories(dir);
    std::vector<std::string> bytes;
    std::string err;
    for (int threads : {1, 2, 3}) {
        SCOPED_TRACE("threads = " + std::to_string(threads));
        const StatsImage img = threads == 1 ? one : mustRender(s, adaptive(20, 12, threads));
        EXPECT_EQ(img.bufferOffset, one.bufferOffset);
        EXPECT_TRUE(sameBits(img.bufferMean, one.bufferMean));
        EXPECT_TRUE(sameBits(img.bufferCount, one.bufferCount));
        EXPECT_TRUE(sameBits(img.beauty, one.beauty));
        EXPECT_TRUE(sameBits(img.variance, one.variance));
        const std::string path = (dir / ("t" + std::to_string(threads) + ".mcstat")).string();
        ASSERT_TRUE(mcstat::writeStatsFile(path, img, err)) << err;
        std::ifstream in(path, std::ios::binary);
        bytes.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    EXPECT_FALSE(bytes[0].empty());
    EXPECT_TRUE(bytes[0] == bytes[1]);
    EXPECT_TRUE(bytes[0] == bytes[2]);
    // And it reads back as written.
    StatsImage back;
    ASSERT_TRUE(mcstat::readStatsFile((dir / "t1.mcstat").string(), back, err)) << err;
    EXPECT_EQ(back.bufferOffset, one.bufferOffset);
    EXPECT_TRUE(sameBits(back.bufferMean, one.bufferMean));
    fs::remove_all(dir);
}

TEST(AdaptiveRender, PlanIsThreadIndependentAndFollowsEq415) {
    const Scene s = mustLoad("tiny");
    AdaptivePlan p1, p3;
    std::string err;
    ASSERT_TRUE(planAdaptive(s, adaptive(20, 12, 1), p1, err)) << err;
    ASSERT_TRUE(planAdaptive(s, adaptive(20, 12, 3), p3, err)) << err;
    EXPECT_EQ(p1.pilotSamples, 12);
    EXPECT_EQ(std::memcmp(&p1.sigmaImage, &p3.sigmaImage, sizeof(double)), 0);
    EXPECT_EQ(p1.buffers, p3.buffers);
    ASSERT_EQ(p1.sigmaPixel.size(), size_t(s.width) * size_t(s.height));
    // sigma_image is the mean pixel standard deviation, summed in pixel order.
    double sum = 0;
    for (double v : p1.sigmaPixel) sum += v;
    EXPECT_EQ(p1.sigmaImage, sum / double(p1.sigmaPixel.size()));
    EXPECT_GT(p1.sigmaImage, 0.0);
    std::map<uint32_t, int> histogram;
    for (size_t p = 0; p < p1.buffers.size(); ++p) {
        EXPECT_EQ(p1.buffers[p],
                  uint32_t(adaptiveBufferCount(p1.sigmaPixel[p], p1.sigmaImage, 17)));
        ++histogram[p1.buffers[p]];
    }
    EXPECT_GE(histogram.size(), 3u) << "tiny should need several buffer counts";
    EXPECT_GT(histogram[1], 0);
    // The render uses the plan.
    const StatsImage img = mustRender(s, adaptive(20, 12, 2));
    for (size_t p = 0; p < p1.buffers.size(); ++p)
        ASSERT_EQ(uint32_t(img.buffersOf(p)), p1.buffers[p]);
}

TEST(AdaptiveRender, EachPixelEqualsAFixedRenderWithMp) {
    // Sample i -> buffer i mod M_p: pixel p's buffers are bit for bit those of a fixed-M render
    // with M = M_p, and counts follow the round-robin rule.
    const Scene s = mustLoad("tiny");
    const int64_t spp = 20;
    const StatsImage img = mustRender(s, adaptive(spp, 12, 2));
    std::string err;
    ASSERT_TRUE(mcstat::validateStats(img, "adaptive", err)) << err;
    EXPECT_EQ(img.header.M, 17);
    EXPECT_EQ(img.header.formatVersion, 2);
    std::map<int, StatsImage> fixed;
    for (size_t p = 0; p < img.pixelCount(); ++p) {
        const int m = img.buffersOf(p);
        if (!fixed.count(m)) {
            RenderOptions o = adaptive(spp, 12, 2);
            o.adaptiveM = false;
            o.M = m;
            fixed[m] = mustRender(s, o);
        }
        const StatsImage& f = fixed[m];
        const mcstat::PixelBuffers a = img.pixelBuffers(p), b = f.pixelBuffers(p);
        ASSERT_EQ(a.M, b.M);
        ASSERT_EQ(std::memcmp(a.mean, b.mean, sizeof(float) * 3 * size_t(m)), 0) << "pixel " << p;
        ASSERT_EQ(std::memcmp(a.count, b.count, sizeof(float) * size_t(m)), 0) << "pixel " << p;
        const int64_t n = int64_t(img.count[p]);
        ASSERT_EQ(n, spp);  // tiny has no NaN samples
        for (int j = 0; j < m; ++j)
            EXPECT_EQ(a.count[j], float(n / m + (j < n % m ? 1 : 0))) << "pixel " << p;
        // Everything but the buffers is independent of M.
        EXPECT_EQ(img.beauty[p * 3], f.beauty[p * 3]);
        EXPECT_EQ(img.variance[p * 3 + 1], f.variance[p * 3 + 1]);
    }
    EXPECT_GE(fixed.size(), 3u);
}

TEST(AdaptiveRender, NoiselessImageHasSigmaImageZeroAndOneBufferEverywhere) {
    // Every camera ray misses (the only shape is behind the camera): every sample is the
    // background, every sigma is 0.
    const char* json = R"({"image":{"width":6,"height":4},
      "camera":{"position":[0,0,0],"lookAt":[0,0,-1]},
      "background":[0.5,0.25,0.125],
      "materials":{"m":{"type":"diffuse"}},
      "shapes":[{"type":"sphere","material":"m","center":[0,0,10],"radius":1}]})";
    Scene s;
    std::string err;
    ASSERT_TRUE(parseScene(json, "empty.json", s, err)) << err;
    AdaptivePlan plan;
    ASSERT_TRUE(planAdaptive(s, adaptive(8, 8, 2), plan, err)) << err;
    EXPECT_EQ(plan.sigmaImage, 0.0);
    for (uint32_t m : plan.buffers) EXPECT_EQ(m, 1u);
    const StatsImage img = mustRender(s, adaptive(8, 8, 2));
    EXPECT_EQ(img.bufferCount.size(), img.pixelCount());
    EXPECT_TRUE(sameBits(img.bufferMean, img.beauty));
}

TEST(AdaptiveRender, FireflyPixelsGetMoreBuffersThanSmoothOnes) {
    // Firefly pixels found in an independent fixed-M render (a buffer mean > 20x the median, as in
    // test_render.cpp), smooth pixels (every buffer within 2x of the median); the pilot (its own
    // seed) must give the first far more buffers.
    Scene s = mustLoad("default");
    s.width = 80;
    s.height = 60;
    RenderOptions fixedOpt;
    fixedOpt.spp = 64;
    fixedOpt.M = 8;
    const StatsImage fixed = mustRender(s, fixedOpt);
    AdaptivePlan plan;
    std::string err;
    ASSERT_TRUE(planAdaptive(s, adaptive(512, 64), plan, err)) << err;
    double mFirefly = 0, mSmooth = 0;
    size_t nFirefly = 0, nSmooth = 0, moreThanOne = 0;
    for (size_t p = 0; p < fixed.pixelCount(); ++p) {
        std::vector<double> lum(8);
        for (size_t j = 0; j < 8; ++j) {
            const float* c = &fixed.bufferMean[(p * 8 + j) * 3];
            lum[j] = kPilotLuma[0] * c[0] + kPilotLuma[1] * c[1] + kPilotLuma[2] * c[2];
        }
        std::vector<double> sorted = lum;
        std::sort(sorted.begin(), sorted.end());
        const double median = 0.5 * (sorted[3] + sorted[4]), mx = sorted[7], mn = sorted[0];
        if (median <= 0) continue;
        if (mx > 20 * median) {
            mFirefly += plan.buffers[p];
            ++nFirefly;
        } else if (mx < 2 * median && mn > 0.5 * median) {
            mSmooth += plan.buffers[p];
            ++nSmooth;
        }
        moreThanOne += plan.buffers[p] > 1;
    }
    ASSERT_GE(nFirefly, 5u);
    ASSERT_GE(nSmooth, 100u);
    mFirefly /= double(nFirefly);
    mSmooth /= double(nSmooth);
    EXPECT_GT(mFirefly, 2.0 * mSmooth) << "firefly pixels " << nFirefly << " mean M_p " << mFirefly
                                       << ", smooth pixels " << nSmooth << " mean M_p " << mSmooth;
    // Most of the image needs no robust estimate (the thesis: 93.7% of its scene).
    EXPECT_LT(moreThanOne, fixed.pixelCount() / 4);
}

}  // namespace
