// `mcstat` spatial and 3D filters end to end (Jung chapter 5): the binary's outputs against the
// library's pure functions, the hybrids as command chains, parameter errors, --diff's normalised
// error, and the 3D filters on a real adaptive-M render (every sample votes once).
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <iterator>
#include <string>
#include <tuple>
#include <vector>

#include "cli_support.h"
#include "mcstat/color/color.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/pixel/median.h"
#include "mcstat/filters/pixel/tmpe.h"
#include "mcstat/filters/window/filter3d.h"
#include "mcstat/filters/window/mif.h"
#include "mcstat/filters/window/window_rank.h"

using namespace mcstat;

namespace {

using mcstat::testing::Result;

class Spatial : public mcstat::testing::CliFixture {
  protected:
    StatsImage stats;
    void SetUp() override {
        CliFixture::SetUp();
        stats = makeStats();
        std::string err;
        ASSERT_TRUE(writeStatsFile(path("f.mcstat"), stats, err)) << err;
    }
    /// 12 x 9 pixels, M = 5 buffers of 3 samples with varied colours; pixel (4, 4) has a firefly
    /// buffer, pixel (8, 2) three.
    static StatsImage makeStats() {
        StatsImage s;
        s.header.width = 12;
        s.header.height = 9;
        s.header.M = 5;
        s.header.spp = 15;
        s.header.renderer = "test_spatial";
        s.header.seeds = "1";
        std::string err;
        EXPECT_TRUE(s.allocate(err)) << err;
        for (size_t p = 0; p < s.pixelCount(); ++p) {
            double sum[3] = {0, 0, 0};
            for (int j = 0; j < 5; ++j) {
                for (int c = 0; c < 3; ++c) {
                    float v = 0.1f + 0.013f * float((p * 7 + size_t(j) * 3 + size_t(c)) % 11);
                    if ((p == 4 * 12 + 4 && j == 1) || (p == 2 * 12 + 8 && j < 3)) v = 400.f;
                    s.bufferMean[(p * 5 + size_t(j)) * 3 + size_t(c)] = v;
                    sum[c] += 3.0 * v;
                }
                s.bufferCount[p * 5 + size_t(j)] = 3.f;
            }
            s.count[p] = 15.f;
            for (int c = 0; c < 3; ++c) {
                s.mean[p * 3 + size_t(c)] = s.beauty[p * 3 + size_t(c)] = float(sum[c] / 15.0);
                s.variance[p * 3 + size_t(c)] = 0.01f;
            }
            s.coverage[p] = 1.f;
        }
        return s;
    }

    SpatialParams params(int k, int l, int64_t w, double alpha, EstimatorMode mode) const {
        SpatialParams p;
        p.luma = lumaCoefficients();
        p.windowWidth = k;
        p.windowHeight = l;
        p.centreWeight = w;
        p.alpha = alpha;
        p.mode = mode;
        return p;
    }
    std::vector<float> direct3D(const SpatialParams& p) const {
        const FixedBufferGrid g{stats.bufferMean.data(), stats.bufferCount.data(), 12, 9, 5};
        std::vector<float> out(12 * 9 * 3);
        filter3DImage(g.view(), p, out.data());
        return out;
    }
    /// A registry estimator per pixel, then WMIF: the hybrid computed by the library.
    std::vector<float> directHybrid(const char* est, double estAlpha,
                                    const SpatialParams& p) const {
        TmpeParams ep;  // MPE takes its PixelParams part
        ep.luma = p.luma;
        ep.mode = p.mode;
        ep.alpha = estAlpha;
        EstimatorScratch s;
        PixelEstimate e;
        std::vector<float> img;
        for (size_t px = 0; px < stats.pixelCount(); ++px) {
            const PixelBuffers buffers{&stats.bufferMean[px * 15], &stats.bufferCount[px * 5], 5};
            if (std::string(est) == "tmpe")
                estimateTMPE(buffers, ep, e, s);
            else
                estimateMoN(buffers, ep, e, s);
            img.insert(img.end(), e.rgb.begin(), e.rgb.end());
        }
        std::vector<float> out(img.size());
        wmifImage({img.data(), 12, 9}, p, out.data());
        return out;
    }
};

std::vector<float> readRGB(const std::string& file) {
    OIIO::ImageBuf b(file);
    EXPECT_TRUE(b.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << b.geterror();
    std::vector<float> px(size_t(b.spec().width) * b.spec().height * 3);
    b.get_pixels(OIIO::ROI(0, b.spec().width, 0, b.spec().height, 0, 1, 0, 3),
                 OIIO::TypeDesc::FLOAT, px.data());
    return px;
}

}  // namespace

TEST_F(Spatial, Filters3DMatchTheLibrary) {
    const auto lum = EstimatorMode::Luminance, ch = EstimatorMode::PerChannel;
    struct Case {
        std::string args;
        SpatialParams p;
    } cases[] = {
        {"--3dmf", params(3, 3, 1, 0.5, lum)},
        {"--3dmf:size=5x3:mode=channel", params(5, 3, 1, 0.5, ch)},
        {"--3dwmf", params(3, 3, 3, 0.5, lum)},
        {"--3dwmf:w=7:size=3", params(3, 3, 7, 0.5, lum)},
        {"--3dwtmf", params(3, 3, 3, 0.25, lum)},
        {"--3dwtmf:alpha=0.1:w=2:size=1x5:mode=channel", params(1, 5, 2, 0.1, ch)},
    };
    for (const Case& c : cases) {
        Result r = mcstat(path("f.mcstat") + " " + c.args + " -o " + path("o.exr"));
        ASSERT_EQ(r.code, 0) << c.args << ": " << r.err;
        EXPECT_EQ(readRGB(path("o.exr")), direct3D(c.p)) << c.args;
    }
}

TEST_F(Spatial, HybridsAreCommandChains) {
    const auto lum = EstimatorMode::Luminance, ch = EstimatorMode::PerChannel;
    // MPE+MIF (eq. 5.15)
    Result r = mcstat(path("f.mcstat") + " --median --mif -o " + path("a.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(readRGB(path("a.exr")), directHybrid("median", 0.0, params(3, 3, 1, 0.5, lum)));
    // TMPE+WMIF (eq. 5.14)
    r = mcstat(path("f.mcstat") + " --tmpe:alpha=0.2 --wmif:w=5:size=3x5 -o " + path("b.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(readRGB(path("b.exr")), directHybrid("tmpe", 0.2, params(3, 5, 5, 0.5, lum)));
    r = mcstat(path("f.mcstat") + " --median:mode=channel --mif:mode=channel -o " + path("c.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(readRGB(path("c.exr")), directHybrid("median", 0.0, params(3, 3, 1, 0.5, ch)));
}

TEST_F(Spatial, OneByOneWindowsAreThePixelEstimators) {
    Result r =
        mcstat(path("f.mcstat") + " --dup --3dmf:size=1x1 -o " + path("a.exr") +
               " --pop --median -o " + path("b.exr") + " --mif:size=1x1 -o " + path("c.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    const std::vector<float> mpe = readRGB(path("b.exr"));
    EXPECT_EQ(readRGB(path("a.exr")), mpe);
    EXPECT_EQ(readRGB(path("c.exr")), mpe);
}

TEST_F(Spatial, FirefliesAreRemoved) {
    // MPE keeps pixel (8, 2) (3 of 5 buffers are fireflies); MPE+MIF and 3DMF do not
    Result r = mcstat(path("f.mcstat") + " --dup --median -o " + path("mpe.exr") + " --mif -o " +
                      path("mif.exr") + " --pop --3dmf -o " + path("3d.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    const size_t i = (2 * 12 + 8) * 3;
    EXPECT_EQ(readRGB(path("mpe.exr"))[i], 400.f);
    EXPECT_LT(readRGB(path("mif.exr"))[i], 1.f);
    EXPECT_LT(readRGB(path("3d.exr"))[i], 1.f);
}

TEST_F(Spatial, ThreadCountDoesNotChangeOutput) {
    for (const char* cmd : {"--3dwmf:w=3", "--median --wmif:w=3"}) {
        ASSERT_EQ(
            mcstat("--threads 1 " + path("f.mcstat") + " " + cmd + " -o " + path("1.exr")).code, 0);
        ASSERT_EQ(
            mcstat("--threads 3 " + path("f.mcstat") + " " + cmd + " -o " + path("3.exr")).code, 0);
        EXPECT_EQ(readRGB(path("1.exr")), readRGB(path("3.exr"))) << cmd;
    }
}

TEST_F(Spatial, ErrorsAreOneLine) {
    struct Case {
        std::string args, message;
    } cases[] = {
        {"--mif", "is a statistics file; apply an estimator first"},
        {"--median --3dmf", "is an image, not a statistics file"},
        {"--3dmf:size=2x3", "size must be KxL with odd K, L in [1, 255]"},
        {"--3dmf:size=3y3", "size must be KxL"},
        {"--3dmf:size=0", "size must be KxL"},
        {"--median --mif:size=301x3", "size must be KxL"},
        {"--3dwmf:w=0", "w must be an integer in [1, 1000000]"},
        {"--3dwmf:w=1.5", "w must be an integer"},
        {"--3dwtmf:alpha=0.7", "alpha must be a number in [0, 0.5]"},
        {"--3dwtmf:alpha=x", "alpha must be a number in [0, 0.5]"},
        {"--3dmf:mode=hue", "mode must be 'lum' or 'channel'"},
        {"--median --mif:w=3", "--mif has no modifier 'w' (accepted: size, mode)"},
        {"--3dmf:alpha=0.1", "--3dmf has no modifier 'alpha'"},
    };
    for (const Case& c : cases) {
        Result r = mcstat(path("f.mcstat") + " " + c.args);
        EXPECT_EQ(r.code, 1) << c.args;
        EXPECT_NE(r.err.find(c.message), std::string::npos) << c.args << ": " << r.err;
        EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << c.args << ": " << r.err;
    }
    Result r = mcstat("--mif");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("--mif needs an image on the stack"), std::string::npos) << r.err;
}

TEST_F(Spatial, DiffPrintsNormalisedBiasAndNoise) {
    // the image against itself: 0 and 0; the mean against MPE+MIF: the firefly pixels' positive
    // error makes the bias positive
    Result r = mcstat(path("f.mcstat") + " --median --mif -o " + path("ref.exr") + " --diff " +
                      path("ref.exr") + " --pop " + path("f.mcstat") + " --mean --diff " +
                      path("ref.exr") + " --diff:neps=0.5 " + path("ref.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("nbias 0  nnoise 0"), std::string::npos) << r.out;
    const size_t second = r.out.find('\n') + 1;
    const size_t b = r.out.find("nbias ", second);
    ASSERT_NE(b, std::string::npos) << r.out;
    EXPECT_GT(std::stod(r.out.substr(b + 6)), 0.1) << r.out;
    EXPECT_NE(mcstat(path("f.mcstat") + " --mean --diff:neps=0 " + path("f.mcstat"))
                  .err.find("neps must be a finite number > 0, not '0'"),
              std::string::npos);
}

TEST_F(Spatial, HelpListsTheFilters) {
    Result h = mcstat("--help");
    ASSERT_EQ(h.code, 0);
    for (const char* c : {"--mif ", "--wmif ", "--3dmf ", "--3dwmf ", "--3dwtmf ", ":size=3x3",
                          ":w=3", ":alpha=0.25", ":neps=0.01", "eq. 5.25-5.27"})
        EXPECT_NE(h.out.find(c), std::string::npos) << c;
}

TEST_F(Spatial, Filters3DOnARenderedAdaptiveFileVotePerSample) {
    // the tiny scene with adaptive M (a fraction of a second): one-buffer pixels next to pixels
    // with up to M_max = 17
    const std::string f = path("adaptive.mcstat");
    const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                            " --scene tiny --spp 96 --adaptive-m --threads 2 --quiet -o " + f;
    ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
    StatsImage s;
    std::string err;
    ASSERT_TRUE(readStatsFile(f, s, err)) << err;
    ASSERT_TRUE(s.header.adaptiveM);
    int many = 0;
    for (size_t p = 0; p < s.pixelCount(); ++p) many += s.buffersOf(p) > 1 ? 1 : 0;
    ASSERT_GT(many, 0);
    ASSERT_LT(many, int(s.pixelCount()));
    const int w = s.header.width, h = s.header.height;
    auto view = [&s](BufferVotes votes) {
        return BufferView{
            s.header.width, s.header.height, &s,
            [](const void* ctx, int x, int y) {
                const auto* img = static_cast<const StatsImage*>(ctx);
                return img->pixelBuffers(size_t(y) * size_t(img->header.width) + size_t(x));
            },
            votes};
    };
    const auto lum = EstimatorMode::Luminance, ch = EstimatorMode::PerChannel;
    struct Case {
        std::string args;
        SpatialParams p;
    } cases[] = {
        {"--3dmf", params(3, 3, 1, 0.5, lum)},
        {"--3dwmf:w=3", params(3, 3, 3, 0.5, lum)},
        {"--3dwtmf:alpha=0.2:w=2:size=5x3:mode=channel", params(5, 3, 2, 0.2, ch)},
    };
    // one run per thread count: each filter of the same file, then 3DMF 1x1
    for (const char* threads : {"1", "2"}) {
        std::string args = std::string("--threads ") + threads + " " + f;
        for (size_t i = 0; i < std::size(cases); ++i)
            args +=
                " --dup " + cases[i].args + " -o " + path(std::to_string(i) + ".exr") + " --pop";
        Result r = mcstat(args + " --3dmf:size=1x1 -o " + path("m.exr"));
        ASSERT_EQ(r.code, 0) << r.err;
        for (size_t i = 0; i < std::size(cases); ++i) {
            const Case& c = cases[i];
            std::vector<float> lib(size_t(w) * size_t(h) * 3), old(lib.size());
            filter3DImage(view(BufferVotes::PerSample), c.p, lib.data());
            EXPECT_EQ(readRGB(path(std::to_string(i) + ".exr")), lib)
                << c.args << " threads " << threads;
            // and not what one vote per buffer gives
            filter3DImage(view(BufferVotes::PerBuffer), c.p, old.data());
            EXPECT_NE(lib, old) << c.args;
        }
    }
    // 3DMF 1x1: each pixel's count-weighted median, computed here sample by sample
    const std::vector<float> got = readRGB(path("m.exr"));
    const std::array<double, 3> luma = lumaCoefficients();
    for (size_t p = 0; p < s.pixelCount(); ++p) {
        const PixelBuffers px = s.pixelBuffers(p);
        std::vector<std::tuple<double, int>> samples;  // (luminance, buffer) per sample
        for (int j = 0; j < px.M; ++j) {
            const float* m = px.mean + 3 * j;
            for (int i = 0; i < int(px.count[j]); ++i)
                samples.emplace_back(luma[0] * m[0] + luma[1] * m[1] + luma[2] * m[2], j);
        }
        ASSERT_FALSE(samples.empty());
        std::sort(samples.begin(), samples.end());
        const size_t n = samples.size();
        // odd: the middle sample's buffer; even: the two middle samples' buffers by count
        const int a = std::get<1>(samples[(n - 1) / 2]), b = std::get<1>(samples[n / 2]);
        for (int c = 0; c < 3; ++c) {
            const double na = px.count[a], nb = px.count[b];
            const double v = a == b
                                 ? double(px.mean[3 * a + c])
                                 : (na * px.mean[3 * a + c] + nb * px.mean[3 * b + c]) / (na + nb);
            EXPECT_FLOAT_EQ(got[p * 3 + size_t(c)], float(v)) << "pixel " << p;
        }
    }
}
