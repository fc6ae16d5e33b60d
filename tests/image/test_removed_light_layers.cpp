// The removed-light layers (image/removed_light_layers.h) over a statistics image built by hand:
// a lone firefly is not significant, a region whose buffers all carry the removed light is; the
// attributes are the sums worked out below; the streamed file gives the same bits as memory.
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <string>

#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/pixel/detail/rank_keys.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/keep_light_image.h"
#include "mcstat/image/removed_light_layers.h"
#include "mcstat/image/removed_light_pass.h"

using namespace mcstat;

namespace {

const std::array<double, 3> kRed{1.0, 0.0, 0.0};  // Y = R

/// 12 x 12, M = 9, one sample per buffer, grey. Background buffers all 1; pixel (2, 2): 8
/// buffers at 1 and one at 100 (mean 12, se 11: d = 11 under the median, z = 1); the block x, y
/// in 6..11: 3 buffers at 10 and 6 at 1 (mean 4, se 1.5: d = 3, z = 2).
StatsImage handImage() {
    StatsImage s;
    s.header.width = s.header.height = 12;
    s.header.M = 9;
    s.header.spp = 9;
    std::string err;
    EXPECT_TRUE(s.allocate(err)) << err;
    for (int y = 0; y < 12; ++y)
        for (int x = 0; x < 12; ++x) {
            const size_t p = size_t(y * 12 + x);
            double sum = 0.0, sq = 0.0;
            for (int j = 0; j < 9; ++j) {
                float v = 1.f;
                if (x == 2 && y == 2 && j == 4) v = 100.f;
                if (x >= 6 && y >= 6 && j % 3 == 1) v = 10.f;
                const size_t k = s.bufferBegin(p) + size_t(j);
                s.bufferCount[k] = 1.f;
                for (int c = 0; c < 3; ++c) s.bufferMean[k * 3 + size_t(c)] = v;
                sum += v;
                sq += double(v) * v;
            }
            s.count[p] = 9.f;
            for (int c = 0; c < 3; ++c) {
                s.beauty[p * 3 + size_t(c)] = s.mean[p * 3 + size_t(c)] = float(sum / 9.0);
                s.variance[p * 3 + size_t(c)] = float((sq - sum * sum / 9.0) / 8.0);
            }
        }
    return s;
}

float at(const OIIO::ImageBuf& img, const std::string& channel, int x, int y) {
    const int c = img.spec().channelindex(channel);
    EXPECT_GE(c, 0) << channel;
    return img.getchannel(x, y, 0, c);
}

OIIO::ImageBuf medianOf(const StatsImage& s) {
    const Operation& op = *findOperation("median");
    ParamValues values;
    std::string err;
    EXPECT_TRUE(parseOperationParams(op, {}, values, err)) << err;
    OIIO::ImageBuf out;
    EXPECT_TRUE(applyOperation(out, s, op, values, kRed)) << out.geterror();
    return out;
}

TEST(RemovedLightLayers, FireflyIsNoiseAndTheRegionIsLight) {
    const StatsImage s = handImage();
    OIIO::ImageBuf img = medianOf(s);
    ASSERT_TRUE(appendRemovedLight(img, s, kRed)) << img.geterror();
    ASSERT_EQ(img.nchannels(), 3 + 5);
    EXPECT_EQ(img.spec().channelnames[3], "removed.Y");
    EXPECT_EQ(img.spec().channelnames[7], "removed.significant");
    // The firefly: d = 11, se = 11, z = 1; alone in its window (radius 2), zlocal = 1.
    EXPECT_FLOAT_EQ(at(img, "removed.Y", 2, 2), 11.f);
    EXPECT_FLOAT_EQ(at(img, "removed.se", 2, 2), 11.f);
    EXPECT_FLOAT_EQ(at(img, "removed.z", 2, 2), 1.f);
    EXPECT_FLOAT_EQ(at(img, "removed.zlocal", 2, 2), 1.f);
    EXPECT_EQ(at(img, "removed.significant", 2, 2), 0.f);
    // The block: d = 3, se = 1.5, z = 2; inside it 25 pixels: 75 / sqrt(25 * 2.25) = 10.
    EXPECT_FLOAT_EQ(at(img, "removed.Y", 8, 8), 3.f);
    EXPECT_FLOAT_EQ(at(img, "removed.z", 8, 8), 2.f);
    EXPECT_FLOAT_EQ(at(img, "removed.zlocal", 8, 8), 10.f);
    // Every block pixel has at least its 3 x 3 corner: 27 / 4.5 = 6 > 3.
    for (int y = 6; y < 12; ++y)
        for (int x = 6; x < 12; ++x) EXPECT_EQ(at(img, "removed.significant", x, y), 1.f);
    EXPECT_FLOAT_EQ(at(img, "removed.zlocal", 11, 11), 6.f);
    // Background: nothing removed, no spread.
    EXPECT_EQ(at(img, "removed.Y", 0, 11), 0.f);
    EXPECT_EQ(at(img, "removed.se", 0, 11), 0.f);
    // Sums: Y(mean) = 107 * 1 + 12 + 36 * 4 = 263; removed = 11 + 36 * 3 = 119; significant
    // removed = 108 (the block; the ring around it is flagged with d = 0).
    EXPECT_FLOAT_EQ(img.spec().get_float_attribute("mcstat:removed:energyFraction"),
                    float(119.0 / 263.0));
    EXPECT_FLOAT_EQ(img.spec().get_float_attribute("mcstat:removed:significantFraction"),
                    float(108.0 / 119.0));
    // The whole image: 119 / sqrt(121 + 36 * 2.25).
    EXPECT_FLOAT_EQ(img.spec().get_float_attribute("mcstat:removed:zImage"),
                    float(119.0 / std::sqrt(121.0 + 81.0)));
    // The operation's own channels are untouched.
    EXPECT_FLOAT_EQ(at(img, "R", 2, 2), 1.f);
}

TEST(RemovedLightLayers, RadiusAndLimitChangeTheMap) {
    const StatsImage s = handImage();
    OIIO::ImageBuf img = medianOf(s);
    RemovedLightOptions opt;
    opt.radius = 0;  // each pixel alone: the block's z = 2 is under a limit of 3
    ASSERT_TRUE(appendRemovedLight(img, s, kRed, opt)) << img.geterror();
    EXPECT_EQ(at(img, "removed.significant", 8, 8), 0.f);
    img = medianOf(s);
    opt.zLimit = 1.5;
    ASSERT_TRUE(appendRemovedLight(img, s, kRed, opt)) << img.geterror();
    EXPECT_EQ(at(img, "removed.significant", 8, 8), 1.f);
    EXPECT_EQ(at(img, "removed.significant", 2, 2), 0.f);  // z = 1 < 1.5
    img = medianOf(s);
    opt.radius = -1;
    EXPECT_FALSE(appendRemovedLight(img, s, kRed, opt));
    EXPECT_NE(img.geterror().find("radius"), std::string::npos);
}

TEST(RemovedLightLayers, NoiseAloneIsRarelyFlagged) {
    // 96 x 96 pixels of M = 9 Gaussian buffer means around 1 (sd 0.2): the median removes only
    // noise. Var(mean - median) = (pi/2 - 1) se^2 (Hausman's lemma, the mean efficient), so
    // zlocal has sd ~0.76 and exceeds 3 with probability ~4e-5 (a z of 3.97); the buffers' own
    // estimate of se (8 degrees of freedom per pixel, 200 per window) leaves it near that. A
    // standard error too small by sqrt(M) (the buffers' spread taken for the mean's) would flag
    // ~25 % of the pixels.
    StatsImage s;
    s.header.width = s.header.height = 96;
    s.header.M = 9;
    s.header.spp = 9;
    std::string err;
    ASSERT_TRUE(s.allocate(err)) << err;
    std::mt19937 rng(5);
    std::normal_distribution<float> noise(1.f, 0.2f);
    for (size_t p = 0; p < s.pixelCount(); ++p) {
        for (int j = 0; j < 9; ++j) {
            const size_t k = s.bufferBegin(p) + size_t(j);
            s.bufferCount[k] = 1.f;
            const float v = noise(rng);
            for (int c = 0; c < 3; ++c) s.bufferMean[k * 3 + size_t(c)] = v;
        }
        s.count[p] = 9.f;
    }
    OIIO::ImageBuf img = medianOf(s);
    ASSERT_TRUE(appendRemovedLight(img, s, kRed)) << img.geterror();
    const int c = img.spec().channelindex("removed.significant");
    const int zc = img.spec().channelindex("removed.z");
    int flagged = 0;
    double sumZ2 = 0.0;
    for (int y = 0; y < 96; ++y)
        for (int x = 0; x < 96; ++x) {
            flagged += img.getchannel(x, y, 0, c) > 0.f;
            sumZ2 += double(img.getchannel(x, y, 0, zc)) * img.getchannel(x, y, 0, zc);
        }
    EXPECT_LE(flagged, 9) << "of 9216 pixels (0.1 %)";
    // The pixels' own z: variance near (pi/2 - 1) = 0.57 with a t-like tail; below 1.
    EXPECT_GT(sumZ2 / 9216.0, 0.4);
    EXPECT_LT(sumZ2 / 9216.0, 1.0);
    // The whole image as one window stays inside the level too.
    EXPECT_LT(std::fabs(img.spec().get_float_attribute("mcstat:removed:zImage")), 3.f);
}

TEST(RemovedLightLayers, StreamedFileGivesTheSameBits) {
    const StatsImage s = handImage();
    const std::string path = (std::filesystem::temp_directory_path() /
                              ("mcstat-removed-" + std::to_string(::getpid()) + ".mcstat"))
                                 .string();
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, s, err)) << err;
    for (const int threads : {1, 2}) {
        OIIO::ImageBuf mem = medianOf(s), streamed = medianOf(s);
        ASSERT_TRUE(appendRemovedLight(mem, s, kRed, {}, threads)) << mem.geterror();
        StatsFileReader reader;
        ASSERT_TRUE(reader.open(path, err, ReadLimits(), threads)) << err;
        ASSERT_TRUE(appendRemovedLight(streamed, reader, kRed, {}, threads)) << streamed.geterror();
        ASSERT_EQ(mem.spec().channelnames, streamed.spec().channelnames);
        const size_t n = size_t(mem.spec().image_pixels()) * size_t(mem.nchannels());
        EXPECT_EQ(0, std::memcmp(mem.localpixels(), streamed.localpixels(), n * sizeof(float)));
    }
    std::filesystem::remove(path);
}

}  // namespace

namespace {

/// W x H, M buffers of random values: each pixel's buffers mostly noise around a level, some
/// fireflies, and in some pixels an invalid buffer (NaN or Inf mean, zero, negative or infinite
/// count) or extreme values (3e38, denormals).
StatsImage randomImage(int W, int H, int M, unsigned seed) {
    StatsImage s;
    s.header.width = W;
    s.header.height = H;
    s.header.M = M;
    s.header.spp = M * 4;
    std::string err;
    EXPECT_TRUE(s.allocate(err)) << err;
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (size_t p = 0; p < size_t(W) * size_t(H); ++p) {
        const float level = u(rng) * 2.f;
        for (int j = 0; j < M; ++j) {
            const size_t k = s.bufferBegin(p) + size_t(j);
            s.bufferCount[k] = 4.f;
            for (int c = 0; c < 3; ++c) {
                float v = level * (0.5f + u(rng));
                if (u(rng) < 0.02f) v *= 1000.f;  // a firefly
                s.bufferMean[k * 3 + size_t(c)] = v;
            }
            const float r = u(rng);
            if (r < 0.004f)
                s.bufferMean[k * 3 + 1] = std::numeric_limits<float>::quiet_NaN();
            else if (r < 0.008f)
                s.bufferMean[k * 3] = std::numeric_limits<float>::infinity();
            else if (r < 0.012f)
                s.bufferCount[k] = 0.f;
            else if (r < 0.016f)
                s.bufferCount[k] = -1.f;
            else if (r < 0.020f)
                s.bufferCount[k] = std::numeric_limits<float>::infinity();
            else if (r < 0.024f)
                s.bufferMean[k * 3 + 2] = 3e38f;
            else if (r < 0.028f)
                s.bufferMean[k * 3 + 1] = 1e-40f;
        }
        s.count[p] = float(4 * M);
    }
    return s;
}

}  // namespace

// The removed-light layers that an estimate computes in its own pass, from the buffers'
// luminances its ranking computed (four pixels at a time, EstimatorScratch::LumaKeys) or from
// the buffers where it has none, equal bit for bit those that appendRemovedLight computes from
// the buffers afterwards: every per-pixel estimator, M = 9 and 21 (the rank estimators' fast
// path) and 65 (past it), a width that leaves groups of fewer than four pixels, invalid buffers
// and extreme values, luminance coefficients with three nonzero weights, the AVX2 and the portable
// ranking, one and two threads.
TEST(RemovedLightLayers, InPassEqualsAppendedBitForBit) {
    const std::array<double, 3> luma{0.2126, 0.7152, 0.0722};
    for (const int M : {9, 21, 65}) {
        const StatsImage s = randomImage(37, 9, M, 7u + unsigned(M));
        for (const char* name : {"mean", "median", "mon", "gmon", "gmonb", "tmpe"}) {
            const Operation& op = *findOperation(name);
            ParamValues plain, removed;
            std::string err;
            ASSERT_TRUE(parseOperationParams(op, {}, plain, err)) << err;
            removed = plain;
            setRemovedLightValues(removed, RemovedLightOptions{});
            for (const bool avx2 : {true, false})
                for (const int threads : {1, 2}) {
                    const bool before = detail::setUseAvx2(avx2);
                    OIIO::ImageBuf inPass, appended;
                    ASSERT_TRUE(applyOperation(inPass, s, op, removed, luma, false, {}, threads))
                        << inPass.geterror();
                    ASSERT_TRUE(applyOperation(appended, s, op, plain, luma, false, {}, threads))
                        << appended.geterror();
                    ASSERT_TRUE(appendRemovedLight(appended, s, luma, {}, threads))
                        << appended.geterror();
                    detail::setUseAvx2(before);
                    ASSERT_EQ(inPass.spec().channelnames, appended.spec().channelnames);
                    const size_t n =
                        size_t(inPass.spec().image_pixels()) * size_t(inPass.nchannels());
                    EXPECT_EQ(0, std::memcmp(inPass.localpixels(), appended.localpixels(),
                                             n * sizeof(float)))
                        << name << " M " << M << " avx2 " << avx2 << " threads " << threads;
                    for (const char* a : {"mcstat:removed:energyFraction", "mcstat:removed:zImage",
                                          "mcstat:removed:significantFraction"})
                        EXPECT_EQ(inPass.spec().get_float_attribute(a),
                                  appended.spec().get_float_attribute(a))
                            << name << " " << a;
                }
        }
    }
}

// keeplight over a per-pixel estimator reads the buffers once: the estimate's own pass gives the
// plain mean (R, G, B and the AOVs) and the buffers' luminance spread as layers keeplight takes
// off (PixelKernel::plainMeanLayers). The result equals, bit for bit and channel for channel,
// keeplight after the plain estimate, which computes the two in a pass of their own: every
// per-pixel estimator, M = 9 and 21, invalid buffers and extreme values, AOVs of every class (a
// light group that sums with the beauty, alpha, a data pass, a label), one and two threads. A
// tall image goes by several bands of rows (keep_light_stream.h): both ways read each band's
// rows where they lie, so every channel's light is the plain mean's.
TEST(KeepLightLayers, InPassEqualsASeparatePassBitForBit) {
    const std::array<double, 3> luma{0.2126, 0.7152, 0.0722};
    for (const auto& [M, w, h] : {std::array<int, 3>{9, 37, 9}, std::array<int, 3>{21, 37, 9},
                                  std::array<int, 3>{9, 5, 300}}) {
        StatsImage s = randomImage(w, h, M, 11u + unsigned(M) + unsigned(h));
        s.header.aovs = {{"A", AovClass::Alpha, ""},
                         {"key.R", AovClass::Light, ""},
                         {"N.X", AovClass::Data, ""},
                         {"IndexOB", AovClass::Id, ""}};
        s.header.formatVersion = requiredFormatVersion(s.header);
        s.aov.resize(s.bufferMean.size() / 3 * s.header.aovs.size());
        for (size_t k = 0; k < s.bufferCount.size(); ++k) {
            s.aov[k * 4] = 1.f;
            s.aov[k * 4 + 1] = 0.5f * s.bufferMean[k * 3];
            s.aov[k * 4 + 2] = float(k % 7) / 7.f;
            s.aov[k * 4 + 3] = float(k % 3);
        }
        for (const char* name : {"mean", "median", "mon", "gmon", "gmonb", "tmpe"}) {
            const Operation& op = *findOperation(name);
            ParamValues plain, keep;
            std::string err;
            ASSERT_TRUE(parseOperationParams(op, {}, plain, err)) << err;
            keep = plain;
            keep["keeplight"].integer = 1;
            for (const int threads : {1, 2}) {
                OIIO::ImageBuf inPass, separate;
                ASSERT_TRUE(applyOperation(inPass, s, op, keep, luma, false, {}, threads))
                    << inPass.geterror();
                ASSERT_TRUE(applyOperation(separate, s, op, plain, luma, false, {}, threads))
                    << separate.geterror();
                ASSERT_TRUE(keepLight(separate, s, luma, KeepLightParams(), threads))
                    << separate.geterror();
                ASSERT_EQ(inPass.spec().channelnames, separate.spec().channelnames) << name;
                EXPECT_EQ(inPass.spec().alpha_channel, separate.spec().alpha_channel) << name;
                const size_t n = size_t(inPass.spec().image_pixels()) * size_t(inPass.nchannels());
                EXPECT_EQ(
                    0, std::memcmp(inPass.localpixels(), separate.localpixels(), n * sizeof(float)))
                    << name << " M " << M << " threads " << threads;
                EXPECT_EQ(inPass.spec().get_float_attribute("mcstat:keeplight:returned"),
                          separate.spec().get_float_attribute("mcstat:keeplight:returned"))
                    << name;
                // Every returned channel's sum is the plain mean's (the "mean" estimator's).
                OIIO::ImageBuf mean;
                ASSERT_TRUE(
                    applyOperation(mean, s, *findOperation("mean"), {}, luma, false, {}, threads));
                for (const char* c : {"R", "G", "B", "key.R"}) {
                    const int a = inPass.spec().channelindex(c), b = mean.spec().channelindex(c);
                    ASSERT_GE(a, 0) << c;
                    ASSERT_GE(b, 0) << c;
                    double got = 0.0, want = 0.0, size = 0.0;
                    const float* gp = static_cast<const float*>(inPass.localpixels());
                    const float* mp = static_cast<const float*>(mean.localpixels());
                    for (size_t p = 0; p < size_t(w) * size_t(h); ++p) {
                        const float g = gp[p * size_t(inPass.nchannels()) + size_t(a)];
                        const float m = mp[p * size_t(mean.nchannels()) + size_t(b)];
                        if (!std::isfinite(m)) continue;  // an invalid pixel's mean: not light
                        got += g;
                        want += m;
                        size += std::fabs(g);
                    }
                    EXPECT_NEAR(got, want, 1e-6 * size) << name << " " << c << " " << w << "x" << h;
                }
            }
        }
    }
}
