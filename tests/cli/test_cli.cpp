// `mcstat` end to end: the binary is run on statistics files made here, and its outputs are checked
// against the estimators called directly.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "cli_support.h"
#include "mcstat/color/color.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"

using namespace mcstat;

namespace {

using mcstat::testing::Result;
using mcstat::testing::slurp;

class Cli : public mcstat::testing::CliFixture {};

/// 16x12 grey image, M = 5 buffers of 4 samples each; pixel (5, 5) has one firefly buffer.
StatsImage makeStats(int M = 5, float firefly = 500.f) {
    StatsImage s;
    s.header.width = 16;
    s.header.height = 12;
    s.header.M = M;
    s.header.spp = 4 * M;
    s.header.renderer = "test_cli";
    s.header.seeds = "7";
    std::string err;
    EXPECT_TRUE(s.allocate(err)) << err;
    for (size_t p = 0; p < s.pixelCount(); ++p) {
        double sum[3] = {0, 0, 0}, n = 0;
        for (int j = 0; j < M; ++j) {
            for (int c = 0; c < 3; ++c) {
                float v = 0.18f + 0.01f * float(j) + 0.02f * float(c);
                if (p == 5 * 16 + 5 && j == 2) v = firefly;
                s.bufferMean[(p * M + j) * 3 + c] = v;
                sum[c] += 4.0 * v;
            }
            s.bufferCount[p * M + j] = 4.f;
            n += 4;
        }
        s.count[p] = float(n);
        for (int c = 0; c < 3; ++c) {
            s.mean[p * 3 + c] = s.beauty[p * 3 + c] = float(sum[c] / n);
            s.variance[p * 3 + c] = 0.01f;
        }
        s.coverage[p] = 1.f;
    }
    return s;
}

std::vector<float> readRGB(const std::string& file, int* nch = nullptr) {
    OIIO::ImageBuf b(file);
    EXPECT_TRUE(b.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << b.geterror();
    if (nch) *nch = b.nchannels();
    std::vector<float> px(size_t(b.spec().width) * b.spec().height * 3);
    b.get_pixels(OIIO::ROI(0, b.spec().width, 0, b.spec().height, 0, 1, 0, 3),
                 OIIO::TypeDesc::FLOAT, px.data());
    return px;
}

/// The estimator applied directly, for comparison with the binary's output.
std::vector<float> direct(const StatsImage& s, const std::string& name, EstimatorMode mode) {
    const Operation* e = findEstimator(name);
    PixelKernel k;
    std::string err;
    std::map<std::string, std::string> kv;
    if (e->param("mode")) kv["mode"] = mode == EstimatorMode::Luminance ? "lum" : "channel";
    EXPECT_TRUE(bindPixelKernel(*e, kv, lumaCoefficients(), k, err)) << err;
    EstimatorScratch scratch;
    PixelEstimate est;
    std::vector<float> out;
    for (size_t px = 0; px < s.pixelCount(); ++px) {
        k.estimate(
            {&s.bufferMean[px * s.header.M * 3], &s.bufferCount[px * s.header.M], s.header.M}, est,
            scratch);
        out.insert(out.end(), est.rgb.begin(), est.rgb.end());
    }
    return out;
}

}  // namespace

TEST_F(Cli, EveryEstimatorMatchesTheLibrary) {
    std::string err;
    StatsImage s = makeStats();
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), s, err)) << err;
    for (const Operation& e : estimatorRegistry()) {
        for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
            const bool hasMode = !e.params.empty();
            if (!hasMode && mode == EstimatorMode::PerChannel) continue;
            const std::string mod =
                hasMode ? (mode == EstimatorMode::PerChannel ? ":mode=channel" : ":mode=lum") : "";
            Result r = mcstat(path("f.mcstat") + " --" + e.name + mod + " -o " + path("o.exr"));
            ASSERT_EQ(r.code, 0) << r.err;
            EXPECT_EQ(readRGB(path("o.exr")), direct(s, e.name, mode)) << e.name << mod;
        }
    }
}

TEST_F(Cli, GMoNRemovesTheFireflyTheMeanKeeps) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    ASSERT_TRUE(writeStatsFile(path("clean.mcstat"), makeStats(5, 0.2f), err)) << err;
    Result ref = mcstat(path("clean.mcstat") + " --mean -o " + path("ref.exr"));
    ASSERT_EQ(ref.code, 0) << ref.err;
    Result r = mcstat(path("f.mcstat") + " --dup --mean --diff " + path("ref.exr") +
                      " --pop --gmon --diff " + path("ref.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    // the mean keeps the firefly pixel (500/5 = 100 over a 0.2 background): one firefly pixel
    EXPECT_NE(r.out.find("mean(" + path("f.mcstat") + ")"), std::string::npos) << r.out;
    const size_t second = r.out.find('\n');
    ASSERT_NE(second, std::string::npos);
    EXPECT_NE(r.out.substr(0, second).find("fireflies 1 / 192"), std::string::npos) << r.out;
    EXPECT_NE(r.out.substr(second).find("fireflies 0 / 192"), std::string::npos) << r.out;
}

TEST_F(Cli, PngGoesThroughTheDisplayView) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    Result r = mcstat(path("f.mcstat") + " --mean -o " + path("m.png"));
    ASSERT_EQ(r.code, 0) << r.err;
    OIIO::ImageBuf png(path("m.png"));
    ASSERT_TRUE(png.read());
    EXPECT_EQ(png.spec().format, OIIO::TypeDesc::UINT8);
    float v[3];
    png.getpixel(0, 0, v, 3);
    // pixel (0,0) R = mean of 0.18..0.22 = 0.2 linear -> sRGB 0.4845
    const double srgb = 1.055 * std::pow(0.2, 1 / 2.4) - 0.055;
    EXPECT_NEAR(v[0], srgb, 1.0 / 255.0);
}

TEST_F(Cli, DiagnosticsAndParameters) {
    std::string err;
    StatsImage s = makeStats();
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), s, err)) << err;
    Result r = mcstat(path("f.mcstat") + " --gmon:diag=1 -o " + path("d.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    OIIO::ImageBuf d(path("d.exr"));
    ASSERT_TRUE(d.read());
    // EXR stores channels alphabetically after R, G, B: look them up by name
    const int gini = d.spec().channelindex("gini"), kept = d.spec().channelindex("kept");
    const int excluded = d.spec().channelindex("excluded");
    ASSERT_EQ(d.nchannels(), 6);
    ASSERT_TRUE(gini >= 3 && kept >= 3 && excluded >= 3);
    EXPECT_GT(d.getchannel(5, 5, 0, gini), 0.5f);  // the firefly pixel is very unequal
    EXPECT_LT(d.getchannel(5, 5, 0, kept), 5.f);   // and loses buffers
    EXPECT_EQ(d.getchannel(0, 0, 0, kept), 5.f);   // smooth pixels keep all five
    EXPECT_EQ(d.getchannel(0, 0, 0, excluded), 0.f);
    // threshold 1: G-MoN_b never leaves the mean
    r = mcstat(path("f.mcstat") + " --gmonb:threshold=1 -o " + path("b.exr") + " --pop " +
               path("f.mcstat") + " --mean -o " + path("m.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(readRGB(path("b.exr")), readRGB(path("m.exr")));
}

TEST_F(Cli, RemovedLightLayersSayTheFireflyIsNoise) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    Result r = mcstat(path("f.mcstat") + " --median:removed=1:residual=1 -o " + path("r.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    OIIO::ImageBuf d(path("r.exr"));
    ASSERT_TRUE(d.read());
    ASSERT_EQ(d.nchannels(), 3 + 5 + 3);  // R, G, B; removed.*; residual.R, G, B
    const auto ch = [&](const char* n) {
        const int c = d.spec().channelindex(n);
        EXPECT_GE(c, 3) << n;
        return c;
    };
    // The firefly's buffer is one of five: z close to 1 (the other buffers differ a little),
    // alone in its window, so not significant; what it removed is what residual says.
    EXPECT_NEAR(d.getchannel(5, 5, 0, ch("removed.z")), 1.0, 0.01);
    EXPECT_NEAR(d.getchannel(5, 5, 0, ch("removed.zlocal")), 1.0, 0.01);
    EXPECT_EQ(d.getchannel(5, 5, 0, ch("removed.significant")), 0.f);
    const float y = 0.2126f * d.getchannel(5, 5, 0, ch("residual.R")) +
                    0.7152f * d.getchannel(5, 5, 0, ch("residual.G")) +
                    0.0722f * d.getchannel(5, 5, 0, ch("residual.B"));
    EXPECT_NEAR(d.getchannel(5, 5, 0, ch("removed.Y")), y, 1e-3 * y);
    EXPECT_EQ(d.spec().get_int_attribute("mcstat:removed:radius"), 2);
    // A limit or radius out of range is refused by name, and nothing is written.
    r = mcstat(path("f.mcstat") + " --median:removed=1:removedz=0 -o " + path("z.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("removedz"), std::string::npos) << r.err;
    r = mcstat(path("f.mcstat") + " --median:removed=1:removedradius=17 -o " + path("z.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("removedradius"), std::string::npos) << r.err;
    // Without removed=1 they would be ignored: refused in one line, as ciaovs without ci is.
    for (const char* k : {"removedradius=3", "removedz=2", "removed=0:removedradius=3"}) {
        r = mcstat(path("f.mcstat") + " --median:" + k + " -o " + path("z.exr"));
        EXPECT_EQ(r.code, 1) << k;
        EXPECT_NE(r.err.find("needs removed=1"), std::string::npos) << r.err;
    }
    EXPECT_FALSE(OIIO::Filesystem::exists(path("z.exr")));
}

TEST_F(Cli, ThreadCountDoesNotChangeOutput) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(9), err)) << err;
    ASSERT_EQ(mcstat("--threads 1 " + path("f.mcstat") + " --gmon -o " + path("1.exr")).code, 0);
    ASSERT_EQ(mcstat("--threads 3 " + path("f.mcstat") + " --gmon -o " + path("3.exr")).code, 0);
    // pixels, not bytes: OIIO stamps the EXR header with the time of writing
    EXPECT_EQ(readRGB(path("1.exr")), readRGB(path("3.exr")));
}

TEST_F(Cli, InfoAndHelp) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(7), err)) << err;
    Result r = mcstat(path("f.mcstat") + " -v --info");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("16 x 12"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("M = 7"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("min 28, max 28"), std::string::npos) << r.out;
    Result h = mcstat("--help");
    ASSERT_EQ(h.code, 0);
    // every registry operation, each settable parameter with its default, type and range
    for (const Operation& op : operationRegistry()) {
        EXPECT_NE(h.out.find("  --" + op.name + " "), std::string::npos) << op.name;
        for (const ParamSpec* p : op.settable())
            EXPECT_NE(h.out.find(":" + p->name + "=" + p->defaultValue + " (" +
                                 (p->type == ParamType::Text ? "" : describeParam(*p) + "; ") +
                                 p->help + ")"),
                      std::string::npos)
                << op.name << " " << p->name;
    }
    for (const char* c : {"--diff REF", "-o FILE", "--info", "--threads N", "--merge", "-v "})
        EXPECT_NE(h.out.find(c), std::string::npos) << c;
}

TEST_F(Cli, MergeAddsCounts) {
    std::string err;
    StatsImage a = makeStats(), b = makeStats();
    b.header.seeds = "8";
    ASSERT_TRUE(writeStatsFile(path("a.mcstat"), a, err)) << err;
    ASSERT_TRUE(writeStatsFile(path("b.mcstat"), b, err)) << err;
    Result r =
        mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --merge -o " + path("m.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    StatsImage m;
    ASSERT_TRUE(readStatsFile(path("m.mcstat"), m, err)) << err;
    EXPECT_EQ(m.count[0], 40.f);
    EXPECT_EQ(m.bufferCount[3], 8.f);
    EXPECT_EQ(m.header.spp, 40);
    // merging a file with itself counts the same samples twice: refused
    r = mcstat(path("a.mcstat") + " " + path("a.mcstat") + " --merge -o " + path("x.mcstat"));
    EXPECT_NE(r.code, 0);
    EXPECT_FALSE(OIIO::Filesystem::exists(path("x.mcstat")));
    // The merge is streamed into whatever uses it: an estimator over `--merge` equals the same
    // estimator over the merged file written first, and a merge of a merge equals the merge of
    // the in-memory images.
    r = mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --merge --gmon -o " +
               path("direct.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    r = mcstat(path("m.mcstat") + " --gmon -o " + path("via.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(readRGB(path("direct.exr")), readRGB(path("via.exr")));
    StatsImage c = makeStats();
    c.header.seeds = "9";
    ASSERT_TRUE(writeStatsFile(path("c.mcstat"), c, err)) << err;
    r = mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --merge " + path("c.mcstat") +
               " --merge -o " + path("abc.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    StatsImage ab, abc, got;
    ASSERT_TRUE(mergeStats(a, b, ab, err) && mergeStats(ab, c, abc, err)) << err;
    ASSERT_TRUE(readStatsFile(path("abc.mcstat"), got, err)) << err;
    EXPECT_EQ(got.bufferMean, abc.bufferMean);
    EXPECT_EQ(got.variance, abc.variance);
    EXPECT_EQ(got.header.seeds, abc.header.seeds);
}

TEST_F(Cli, ErrorsAreOneLineAndNonZero) {
    std::string err;
    StatsImage s = makeStats();
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), s, err)) << err;
    const std::string good = slurp(path("f.mcstat"));
    {
        std::ofstream t(path("cut.mcstat"), std::ios::binary);
        t << good.substr(0, good.size() / 2);
    }
    struct Case {
        std::string args, needle;
    } cases[] = {
        {path("missing.mcstat") + " --gmon -o " + path("o.exr"), "missing.mcstat"},
        {path("cut.mcstat") + " --gmon -o " + path("o.exr"), "cut.mcstat"},
        {path("f.mcstat") + " --frobnicate", "unknown command '--frobnicate'"},
        {path("f.mcstat") + " --gmon:bogus=1", "no modifier 'bogus'"},
        {path("f.mcstat") + " --gmon:mode=hsv", "mode must be"},
        {path("f.mcstat") + " --gmonb:threshold=2", "threshold"},
        {path("f.mcstat") + " --mean --gmon", "is an image, not a statistics file"},
        {path("f.mcstat") + " -o " + path("f.exr"), "apply an estimator first"},
        {"--gmon", "needs a statistics file on the stack"},
        {"--threads many", "thread count"},
        {path("f.mcstat") + " --mean -o", "needs 1 argument"},
        {path("f.mcstat") + " --mean -o " + path("nodir/o.exr"), "nodir/o.exr"},
        {path("f.mcstat") + " --mean --diff " + path("missing.exr"), "missing.exr"},
    };
    for (const Case& c : cases) {
        Result r = mcstat(c.args);
        EXPECT_NE(r.code, 0) << c.args;
        EXPECT_NE(r.err.find(c.needle), std::string::npos) << c.args << " -> " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_TRUE(r.out.empty()) << r.out;
    }
    EXPECT_FALSE(OIIO::Filesystem::exists(path("o.exr")));
    EXPECT_FALSE(OIIO::Filesystem::exists(path("f.exr")));
}
