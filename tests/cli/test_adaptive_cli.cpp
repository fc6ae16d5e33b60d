// `mcstat` on adaptive-M statistics files (format 2): every registry estimator run by the binary
// equals the estimator applied per pixel through StatsImage::pixelBuffers, --info reports the
// buffer counts, --merge keeps them.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "cli_support.h"
#include "mcstat/color/color.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"

using namespace mcstat;

namespace {

using mcstat::testing::Result;

class AdaptiveCli : public mcstat::testing::CliFixture {};

/// 16x12, M_max = 9, m_p in {1, 3, 5, 9} by position, 4 samples per buffer; buffer values vary by
/// buffer, channel and pixel; pixel (5, 5) (9 buffers) has a firefly buffer, pixel (6, 5) (1
/// buffer) is a lone firefly, and one buffer of pixel (7, 7) is empty.
StatsImage makeAdaptive(const std::string& seeds = "7") {
    StatsImage s;
    s.header.width = 16;
    s.header.height = 12;
    s.header.M = 9;
    s.header.formatVersion = kStatsFormatVersionAdaptive;
    s.header.spp = 36;
    s.header.renderer = "test_adaptive_cli";
    s.header.seeds = seeds;
    const int ms[4] = {1, 3, 5, 9};
    std::vector<uint32_t> m(s.pixelCount());
    for (int y = 0; y < 12; ++y)
        for (int x = 0; x < 16; ++x) m[size_t(y * 16 + x)] = uint32_t(ms[(x + 2 * y) % 4]);
    std::string err;
    EXPECT_TRUE(s.allocateAdaptive(m, err)) << err;
    for (size_t p = 0; p < s.pixelCount(); ++p) {
        const size_t k0 = s.bufferBegin(p);
        const int mp = s.buffersOf(p);
        double sum[3] = {0, 0, 0}, n = 0;
        for (int j = 0; j < mp; ++j) {
            const float cnt = p == 7 * 16 + 7 && j == 1 ? 0.f : 4.f;
            for (int c = 0; c < 3; ++c) {
                float v = cnt == 0.f ? 0.f
                                     : 0.1f + 0.013f * float(j) + 0.02f * float(c) +
                                           0.001f * float(p % 17);
                if ((p == 5 * 16 + 5 && j == 2) || p == 5 * 16 + 6) v = 300.f;
                s.bufferMean[(k0 + size_t(j)) * 3 + size_t(c)] = v;
                sum[c] += double(cnt) * v;
            }
            s.bufferCount[k0 + size_t(j)] = cnt;
            n += cnt;
        }
        s.count[p] = float(n);
        for (int c = 0; c < 3; ++c) {
            s.mean[p * 3 + size_t(c)] = s.beauty[p * 3 + size_t(c)] = float(sum[c] / n);
            s.variance[p * 3 + size_t(c)] = 0.01f;
        }
        s.coverage[p] = 1.f;
    }
    EXPECT_TRUE(validateStats(s, "adaptive", err)) << err;
    return s;
}

std::vector<float> readRGB(const std::string& file) {
    OIIO::ImageBuf b(file);
    EXPECT_TRUE(b.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << b.geterror();
    std::vector<float> px(size_t(b.spec().width) * size_t(b.spec().height) * 3);
    b.get_pixels(OIIO::ROI(0, b.spec().width, 0, b.spec().height, 0, 1, 0, 3),
                 OIIO::TypeDesc::FLOAT, px.data());
    return px;
}

/// The estimator applied pixel by pixel through the library's one view of the buffers.
std::vector<float> direct(const StatsImage& s, const Operation& e, EstimatorMode mode) {
    PixelKernel k;
    std::string err;
    std::map<std::string, std::string> kv;
    if (e.param("mode")) kv["mode"] = mode == EstimatorMode::Luminance ? "lum" : "channel";
    EXPECT_TRUE(bindPixelKernel(e, kv, lumaCoefficients(), k, err)) << err;
    EstimatorScratch scratch;
    PixelEstimate est;
    std::vector<float> out;
    for (size_t px = 0; px < s.pixelCount(); ++px) {
        k.estimate(s.pixelBuffers(px), est, scratch);
        out.insert(out.end(), est.rgb.begin(), est.rgb.end());
    }
    return out;
}

}  // namespace

TEST_F(AdaptiveCli, EveryEstimatorMatchesTheLibraryPerPixel) {
    std::string err;
    const StatsImage s = makeAdaptive();
    ASSERT_TRUE(writeStatsFile(path("a.mcstat"), s, err)) << err;
    for (const Operation& e : estimatorRegistry()) {
        for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
            const bool hasMode = !e.params.empty();
            if (!hasMode && mode == EstimatorMode::PerChannel) continue;
            const std::string mod =
                hasMode ? (mode == EstimatorMode::PerChannel ? ":mode=channel" : ":mode=lum") : "";
            const Result r =
                mcstat(path("a.mcstat") + " --" + e.name + mod + " -o " + path("o.exr"));
            ASSERT_EQ(r.code, 0) << e.name << mod << ": " << r.err;
            const std::vector<float> got = readRGB(path("o.exr")), want = direct(s, e, mode);
            EXPECT_EQ(got, want) << e.name << mod;
            // A one-buffer pixel is its buffer: every estimator returns it (the lone firefly).
            EXPECT_EQ(got[(5 * 16 + 6) * 3], 300.f) << e.name << mod;
        }
    }
    // And the robust ones remove the firefly of the nine-buffer pixel, which the mean keeps.
    ASSERT_EQ(mcstat(path("a.mcstat") + " --mean -o " + path("mean.exr")).code, 0);
    ASSERT_EQ(mcstat(path("a.mcstat") + " --mon -o " + path("mon.exr")).code, 0);
    const size_t i = (5 * 16 + 5) * 3;
    EXPECT_GT(readRGB(path("mean.exr"))[i], 30.f);
    EXPECT_LT(readRGB(path("mon.exr"))[i], 1.f);
}

TEST_F(AdaptiveCli, InfoShowsTheBufferCounts) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("a.mcstat"), makeAdaptive(), err)) << err;
    const Result r = mcstat(path("a.mcstat") + " --info");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("format 2"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("adaptive M, M_max = 9"), std::string::npos) << r.out;
    // 192 pixels, 48 of each of 1, 3, 5, 9 buffers: 864 sub-buffers, mean 4.5
    EXPECT_NE(r.out.find("m_p min 1, mean 4.5000, max 9 (M_max 9); 864 sub-buffers"),
              std::string::npos)
        << r.out;
}

TEST_F(AdaptiveCli, MergeKeepsTheBufferCounts) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("a.mcstat"), makeAdaptive("1"), err)) << err;
    ASSERT_TRUE(writeStatsFile(path("b.mcstat"), makeAdaptive("2"), err)) << err;
    Result r =
        mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --merge -o " + path("m.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    StatsImage m;
    ASSERT_TRUE(readStatsFile(path("m.mcstat"), m, err)) << err;
    EXPECT_TRUE(m.header.adaptiveM);
    EXPECT_EQ(m.bufferOffset, makeAdaptive().bufferOffset);
    EXPECT_EQ(m.count[0], 8.f);
    EXPECT_EQ(m.pixelBuffers(5 * 16 + 5).count[2], 8.f);
}
