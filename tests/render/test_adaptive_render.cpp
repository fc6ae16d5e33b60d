// Adaptive buffer count in the renderer (Jung 2016, section 4.2.4, eq. 4.15; docs/adaptive-m.md):
// the rule, both strategies (pilot, and growing during the render), sigma_image, determinism for
// any thread count, the assignment rules, and fireflies getting more buffers than smooth pixels.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include "film.h"
#include "mcstat/render-fixture/render.h"
#include "mcstat/render-fixture/scene.h"

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
    o.strategy = AdaptiveStrategy::Pilot;
    o.pilotSpp = pilot;
    return o;
}

RenderOptions growing(int64_t spp, int threads = 0, int mMax = 17, int64_t checkpoint = 0) {
    RenderOptions o = adaptive(spp, 0, threads, mMax);
    o.strategy = AdaptiveStrategy::Grow;
    o.checkpoint = checkpoint;
    return o;
}

/// Every camera ray misses (the only shape is behind the camera): every sample is the background,
/// every sigma is 0.
Scene noiselessScene() {
    const char* json = R"({"image":{"width":6,"height":4},
      "camera":{"position":[0,0,0],"lookAt":[0,0,-1]},
      "background":[0.5,0.25,0.125],
      "materials":{"m":{"type":"diffuse"}},
      "shapes":[{"type":"sphere","material":"m","center":[0,0,10],"radius":1}]})";
    Scene s;
    std::string err;
    EXPECT_TRUE(parseScene(json, "empty.json", s, err)) << err;
    return s;
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
    const fs::path dir =
        fs::temp_directory_path() / ("mcstat_adaptive_test_" + std::to_string(::getpid()));
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
    const Scene s = noiselessScene();
    std::string err;
    AdaptivePlan plan;
    ASSERT_TRUE(planAdaptive(s, adaptive(8, 8, 2), plan, err)) << err;
    EXPECT_EQ(plan.sigmaImage, 0.0);
    for (uint32_t m : plan.buffers) EXPECT_EQ(m, 1u);
    const StatsImage img = mustRender(s, adaptive(8, 8, 2));
    EXPECT_EQ(img.bufferCount.size(), img.pixelCount());
    EXPECT_TRUE(sameBits(img.bufferMean, img.beauty));
}

/// Mean M_p of firefly pixels and of smooth pixels of the default scene at 80 x 60, found in a
/// fixed M = 8 render of `spp` samples with `seed` (a buffer mean > 20x the median, as in
/// test_render.cpp; smooth: every buffer within 2x of it); `mp(p)` gives a pixel's M_p.
template <typename Mp>
void expectFirefliesGetMoreBuffers(const Scene& s, int64_t spp, uint64_t seed, Mp&& mp) {
    RenderOptions fixedOpt;
    fixedOpt.spp = spp;
    fixedOpt.M = 8;
    fixedOpt.seed = seed;
    const StatsImage fixed = mustRender(s, fixedOpt);
    double mFirefly = 0, mSmooth = 0;
    size_t nFirefly = 0, nSmooth = 0, moreThanOne = 0;
    for (size_t p = 0; p < fixed.pixelCount(); ++p) {
        std::vector<double> lum(8);
        for (size_t j = 0; j < 8; ++j) {
            const float* c = &fixed.bufferMean[(p * 8 + j) * 3];
            lum[j] = kSigmaLuma[0] * c[0] + kSigmaLuma[1] * c[1] + kSigmaLuma[2] * c[2];
        }
        std::vector<double> sorted = lum;
        std::sort(sorted.begin(), sorted.end());
        const double median = 0.5 * (sorted[3] + sorted[4]), mx = sorted[7], mn = sorted[0];
        if (median <= 0) continue;
        if (mx > 20 * median) {
            mFirefly += mp(p);
            ++nFirefly;
        } else if (mx < 2 * median && mn > 0.5 * median) {
            mSmooth += mp(p);
            ++nSmooth;
        }
        moreThanOne += mp(p) > 1;
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

TEST(AdaptiveRender, FireflyPixelsGetMoreBuffersThanSmoothOnes) {
    // The pilot (its own seed) finds firefly-prone pixels: fireflies of an independent render.
    Scene s = mustLoad("default");
    s.width = 80;
    s.height = 60;
    AdaptivePlan plan;
    std::string err;
    ASSERT_TRUE(planAdaptive(s, adaptive(512, 64), plan, err)) << err;
    expectFirefliesGetMoreBuffers(s, 64, 1, [&](size_t p) { return double(plan.buffers[p]); });
}

// ---------------------------------------------------------------------------------------------
// Growing during the render

TEST(GrowRule, CapKeepsEqualCountsReachable) {
    // floor(spp / fullest buffer), made odd, at most M_max: the first checkpoint of a 1000-spp
    // render (58 samples in one buffer) may still reach 17, later ones less.
    EXPECT_EQ(growCap(1000, 58, 17), 17);  // 1000 / 58 = 17.2
    EXPECT_EQ(growCap(1000, 116, 17), 7);  // 8.6 -> 8 -> odd 7
    EXPECT_EQ(growCap(1000, 232, 17), 3);  // 4.3 -> 4 -> 3
    EXPECT_EQ(growCap(1000, 464, 17), 1);  // 2.2 -> 2 -> 1: too late to grow
    EXPECT_EQ(growCap(1000, 0, 17), 17);   // nothing taken yet
    EXPECT_EQ(growCap(100, 10, 5), 5);     // M_max binds
    EXPECT_EQ(growCap(10, 20, 17), 1);     // already over-full: never below 1
    EXPECT_EQ(growCap(int64_t(1) << 40, 1, 999), 999);
    // Grown counts: eq. 4.15 within the cap, never shrinking.
    EXPECT_EQ(grownBufferCount(1, 0.5, 1.0, 17, 1000, 58), 1);     // ratio < 1
    EXPECT_EQ(grownBufferCount(1, 128.0, 1.0, 17, 1000, 58), 17);  // eq. 4.15: 17, cap 17
    EXPECT_EQ(grownBufferCount(1, 128.0, 1.0, 17, 1000, 116), 7);  // capped
    EXPECT_EQ(grownBufferCount(9, 4.0, 1.0, 17, 1000, 58), 9);     // eq. 4.15 says 7: keep 9
    EXPECT_EQ(grownBufferCount(3, 0.0, 1.0, 17, 1000, 300), 3);    // noiseless now: keep 3
    EXPECT_EQ(grownBufferCount(1, 1.0, 0.0, 17, 1000, 58), 17);    // sigma_image 0: M_max
}

TEST(GrowRule, CheckpointsDoubleFromTheFirst) {
    EXPECT_EQ(growCheckpoints(growing(1000)), (std::vector<int64_t>{58, 116, 232, 464, 928}));
    EXPECT_EQ(growCheckpoints(growing(1000, 0, 17, 100)),
              (std::vector<int64_t>{100, 200, 400, 800}));
    EXPECT_EQ(growCheckpoints(growing(10)), (std::vector<int64_t>{2, 4, 8}));  // at least 2
    EXPECT_EQ(growCheckpoints(growing(3)), (std::vector<int64_t>{2}));
    EXPECT_TRUE(growCheckpoints(growing(2)).empty());
    EXPECT_TRUE(growCheckpoints(growing(1)).empty());
    EXPECT_TRUE(growCheckpoints(growing(1000, 0, 1)).empty());  // M_max 1: nothing can grow
    EXPECT_TRUE(growCheckpoints(growing(1000, 0, 17, 1000)).empty());
    // Doubling never overflows near the top of the range.
    const std::vector<int64_t> big = growCheckpoints(growing(int64_t(1) << 40, 0, 3));
    ASSERT_FALSE(big.empty());
    EXPECT_LT(big.back(), int64_t(1) << 40);
    EXPECT_LE(big.size(), 3u);

    std::string err;
    RenderOptions o = growing(100);
    o.checkpoint = 1;
    EXPECT_FALSE(validateOptions(o, err));
    EXPECT_NE(err.find("checkpoint must be at least 2"), std::string::npos) << err;
    o.checkpoint = -5;
    EXPECT_FALSE(validateOptions(o, err));
    o.checkpoint = 2;
    EXPECT_TRUE(validateOptions(o, err)) << err;
}

TEST(GrowAccumulator, LeastCountFillsNewBuffersFirst) {
    // Samples 1, 2, 3, 4 in one buffer; grow to 3: the following samples fill the two new, empty
    // buffers alternately (fewest samples first, lowest index on ties) until they catch up with
    // buffer 0's four.
    GrowingPixel acc;
    EXPECT_EQ(acc.buffers(), 1);
    EXPECT_EQ(acc.maxBufferCount(), 0);
    PathSample s;
    auto add = [&](double v) {
        s.L = Vec3(v, 2 * v, 0);
        EXPECT_TRUE(acc.add(s));
    };
    for (double v : {1.0, 2.0, 3.0, 4.0}) add(v);
    EXPECT_EQ(acc.maxBufferCount(), 4);
    acc.grow(3);
    acc.grow(2);  // never shrinks
    EXPECT_EQ(acc.buffers(), 3);
    for (double v : {10.0, 20.0, 30.0, 40.0, 100.0, 200.0, 300.0}) add(v);
    PathSample nan = s;
    nan.L.x = std::numeric_limits<double>::quiet_NaN();
    EXPECT_FALSE(acc.add(nan));  // dropped, no buffer touched
    StatsImage img;
    img.header.width = 1, img.header.height = 1, img.header.M = 3;
    img.header.formatVersion = mcstat::kStatsFormatVersionAdaptive;
    std::string err;
    ASSERT_TRUE(img.allocateAdaptive({3}, err)) << err;
    acc.store(img, 0);
    EXPECT_EQ(img.count[0], 11.0f);
    EXPECT_EQ(img.bufferCount[0], 4.0f);               // 1, 2, 3, 4
    EXPECT_EQ(img.bufferCount[1], 4.0f);               // 10, 30, 100, 300
    EXPECT_EQ(img.bufferCount[2], 3.0f);               // 20, 40, 200
    EXPECT_EQ(img.bufferMean[0], 2.5f);                // 10 / 4
    EXPECT_EQ(img.bufferMean[3], 110.0f);              // 440 / 4
    EXPECT_EQ(img.bufferMean[6], float(260.0 / 3.0));  // 260 / 3
    EXPECT_EQ(img.bufferMean[7], float(520.0 / 3.0));  // G = 2 R
    // The luminance statistics of eq. 4.15 over the 11 kept samples: (0.2126 + 2 * 0.7152) v.
    const double k = kSigmaLuma[0] + 2 * kSigmaLuma[1];
    double mean = 0, ss = 0;
    const double values[] = {1, 2, 3, 4, 10, 20, 30, 40, 100, 200, 300};
    for (double v : values) mean += k * v / 11;
    for (double v : values) ss += (k * v - mean) * (k * v - mean);
    EXPECT_NEAR(acc.luminance().sigma(), std::sqrt(ss / 10), 1e-12 * std::sqrt(ss / 10));
}

TEST(GrowRender, DeterministicForAnyThreadCountAndByteIdenticalFiles) {
    namespace fs = std::filesystem;
    const Scene s = mustLoad("tiny");
    RenderStats st1;
    StatsImage one;
    std::string err;
    ASSERT_TRUE(render(s, growing(40, 1), one, err, &st1)) << err;
    ASSERT_TRUE(one.header.adaptiveM);
    EXPECT_EQ(one.header.assignment, "leastcount");
    const fs::path dir =
        fs::temp_directory_path() / ("mcstat_grow_test_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::vector<std::string> bytes;
    for (int threads : {1, 2, 3}) {
        SCOPED_TRACE("threads = " + std::to_string(threads));
        RenderStats st;
        StatsImage img;
        if (threads == 1) {
            img = one, st = st1;
        } else {
            ASSERT_TRUE(render(s, growing(40, threads), img, err, &st)) << err;
        }
        EXPECT_EQ(img.bufferOffset, one.bufferOffset);
        EXPECT_TRUE(sameBits(img.bufferMean, one.bufferMean));
        EXPECT_TRUE(sameBits(img.bufferCount, one.bufferCount));
        ASSERT_EQ(st.checkpoints.size(), st1.checkpoints.size());
        for (size_t k = 0; k < st.checkpoints.size(); ++k) {
            EXPECT_EQ(std::memcmp(&st.checkpoints[k].sigmaImage, &st1.checkpoints[k].sigmaImage,
                                  sizeof(double)),
                      0);
            EXPECT_EQ(st.checkpoints[k].grownPixels, st1.checkpoints[k].grownPixels);
        }
        const std::string path = (dir / ("t" + std::to_string(threads) + ".mcstat")).string();
        ASSERT_TRUE(mcstat::writeStatsFile(path, img, err)) << err;
        std::ifstream in(path, std::ios::binary);
        bytes.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    EXPECT_TRUE(bytes[0] == bytes[1]);
    EXPECT_TRUE(bytes[0] == bytes[2]);
    StatsImage back;
    ASSERT_TRUE(mcstat::readStatsFile((dir / "t1.mcstat").string(), back, err)) << err;
    EXPECT_EQ(back.header.assignment, "leastcount");
    EXPECT_EQ(back.bufferOffset, one.bufferOffset);
    EXPECT_TRUE(sameBits(back.bufferMean, one.bufferMean));
    fs::remove_all(dir);
}

TEST(GrowRender, FirstCheckpointIsThePilotOfTheRendersOwnSamples) {
    // The first checkpoint sees samples 0 .. n0-1 of every pixel: exactly what a pilot of n0
    // samples with the render's seed sees, so sigma_image agrees bit for bit and every pixel grew
    // to at least eq. 4.15's count under the first cap. Later checkpoints only add buffers.
    const Scene s = mustLoad("tiny");
    const int64_t spp = 60;
    RenderStats st;
    StatsImage img;
    std::string err;
    ASSERT_TRUE(render(s, growing(spp, 2), img, err, &st)) << err;
    ASSERT_TRUE(mcstat::validateStats(img, "grow", err)) << err;
    const std::vector<int64_t> cps = growCheckpoints(growing(spp));
    ASSERT_EQ(st.checkpoints.size(), cps.size());
    ASSERT_FALSE(cps.empty());
    const int64_t n0 = cps[0];
    EXPECT_EQ(n0, 3);  // 60 / 17
    RenderOptions pilot = adaptive(spp, n0, 2);
    pilot.pilotSeed = pilot.seed;
    AdaptivePlan plan;
    ASSERT_TRUE(planAdaptive(s, pilot, plan, err)) << err;
    EXPECT_EQ(std::memcmp(&st.checkpoints[0].sigmaImage, &plan.sigmaImage, sizeof(double)), 0);
    const int cap0 = growCap(spp, n0, 17);
    int64_t grew = 0;
    double prevMean = 1.0;
    for (const GrowCheckpoint& cp : st.checkpoints) {
        EXPECT_GE(cp.meanBuffers, prevMean);
        prevMean = cp.meanBuffers;
        grew += cp.grownPixels;
    }
    EXPECT_EQ(st.meanBuffers, prevMean);
    EXPECT_GT(grew, 0);
    std::map<int, int> histogram;
    for (size_t p = 0; p < img.pixelCount(); ++p) {
        const int m = img.buffersOf(p);
        ++histogram[m];
        EXPECT_GE(m, std::min<int>(int(plan.buffers[p]), cap0)) << "pixel " << p;
        EXPECT_EQ(m % 2, 1);
        EXPECT_LE(m, 17);
    }
    EXPECT_GE(histogram.size(), 3u);
    EXPECT_GT(histogram[1], 0);
}

TEST(GrowRender, EqualCountsAndTheSameSamplesAsAFixedRender) {
    // Buffers end within one sample of each other (the thesis' equal-size means), hold every kept
    // sample once, and everything but the buffers is bit for bit the fixed-M render with the same
    // seed: the same samples, accumulated in the same order.
    const Scene s = mustLoad("tiny");
    for (const int64_t spp : {int64_t(1), int64_t(2), int64_t(3), int64_t(17), int64_t(100)}) {
        SCOPED_TRACE("spp = " + std::to_string(spp));
        const StatsImage img = mustRender(s, growing(spp, 2));
        RenderOptions fixedOpt = growing(spp, 2);
        fixedOpt.adaptiveM = false;
        fixedOpt.M = 1;
        const StatsImage fixed = mustRender(s, fixedOpt);
        EXPECT_TRUE(sameBits(img.beauty, fixed.beauty));
        EXPECT_TRUE(sameBits(img.mean, fixed.mean));
        EXPECT_TRUE(sameBits(img.variance, fixed.variance));
        EXPECT_TRUE(sameBits(img.count, fixed.count));
        EXPECT_TRUE(sameBits(img.normal, fixed.normal));
        EXPECT_TRUE(sameBits(img.depth, fixed.depth));
        EXPECT_TRUE(sameBits(img.albedo, fixed.albedo));
        int grown = 0;
        for (size_t p = 0; p < img.pixelCount(); ++p) {
            const mcstat::PixelBuffers b = img.pixelBuffers(p);
            grown += b.M > 1;
            const int64_t n = int64_t(img.count[p]);
            double total = 0, sum[3] = {0, 0, 0};
            for (int j = 0; j < b.M; ++j) {
                EXPECT_TRUE(b.count[j] == float(n / b.M) || b.count[j] == float(n / b.M + 1))
                    << "pixel " << p << " buffer " << j << " of " << b.M << ": " << b.count[j]
                    << " of " << n;
                total += b.count[j];
                for (int c = 0; c < 3; ++c) sum[c] += double(b.count[j]) * b.mean[j * 3 + c];
            }
            EXPECT_EQ(total, double(n));
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(sum[c] / double(n), img.beauty[p * 3 + c],
                            1e-6 * std::abs(img.beauty[p * 3 + c]) + 1e-30);
        }
        if (spp <= 3) {
            EXPECT_EQ(grown, 0);  // no checkpoint (spp <= 2) or too late (cap 1)
        }
        if (spp == 100) {
            EXPECT_GT(grown, 0);
        }
    }
}

TEST(GrowRender, NoiselessImageKeepsOneBufferEverywhere) {
    const Scene s = noiselessScene();
    std::string err;
    RenderStats st;
    StatsImage img;
    ASSERT_TRUE(render(s, growing(64, 2), img, err, &st)) << err;
    ASSERT_FALSE(st.checkpoints.empty());
    for (const GrowCheckpoint& cp : st.checkpoints) {
        EXPECT_EQ(cp.sigmaImage, 0.0);
        EXPECT_EQ(cp.grownPixels, 0);
    }
    EXPECT_EQ(img.bufferCount.size(), img.pixelCount());
    EXPECT_TRUE(sameBits(img.bufferMean, img.beauty));
}

TEST(GrowRender, FireflyPixelsGetMoreBuffersThanSmoothOnes) {
    // Growing sees the render's own samples: pixels whose fireflies arrive early enough grow.
    // Fireflies are found in a fixed-M render with the same seed and spp (the same samples).
    Scene s = mustLoad("default");
    s.width = 80;
    s.height = 60;
    const StatsImage img = mustRender(s, growing(256, 0));
    expectFirefliesGetMoreBuffers(s, 256, 5, [&](size_t p) { return double(img.buffersOf(p)); });
}

}  // namespace
