// Cascade reweighting end to end: mcstat-render --reweight stores the cascades as state parts
// owned by "reweight"; `mcstat --reweight` reweights them, or the cascades it builds from the
// per-sample records of a --keep-samples render of the same samples, and both give the same
// image bit for bit; --info describes the parts; the refusals are one-line errors; a resumed render
// continues the cascades exactly.
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/filters/samples/cascade_reweighting_operation.h"
#include "tool_test.h"

namespace mcstat {
namespace {

using testing::ToolRun;

class ReweightFile : public testing::ToolTest {
  protected:
    ReweightFile() : ToolTest("filters/samples") {}
};

std::vector<float> pixelsOf(const std::string& file, int& nch) {
    OIIO::ImageBuf b(file);
    EXPECT_TRUE(b.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << b.geterror();
    nch = b.nchannels();
    std::vector<float> v(size_t(b.spec().image_pixels()) * size_t(nch));
    b.get_pixels(b.roi(), OIIO::TypeDesc::FLOAT, v.data());
    return v;
}

TEST_F(ReweightFile, OnlineCascadesAndOfflineRecordsGiveTheSameImageBitForBit) {
    const std::string on = path("on.mcstat"), off = path("off.mcstat");
    // The default scene (its caustic makes fireflies), small, the same seed: the same samples.
    ASSERT_EQ(render("--res 32 24 --spp 32 --M 4 --reweight -o " + on).code, 0);
    ASSERT_EQ(render("--res 32 24 --spp 32 --M 4 --threads 1 --keep-samples -o " + off).code, 0);
    StatsImage img;
    std::string err;
    ASSERT_TRUE(readStatsFile(on, img, err)) << err;
    EXPECT_EQ(img.header.state.operation, "reweight");
    EXPECT_EQ(img.header.state.flatPart, "cascades");
    EXPECT_EQ(img.header.state.deepPart, "cascades.deep");
    EXPECT_FALSE(img.header.hasRecords);
    for (const std::string& mods : {std::string(""), std::string(":kappa=4")}) {
        const std::string a = path("a.exr"), b = path("b.exr");
        ToolRun r = mcstat(on + " --reweight" + mods + " -o " + a);
        ASSERT_EQ(r.code, 0) << r.err;
        r = mcstat(off + " --threads 2 --reweight" + mods + " -o " + b);
        ASSERT_EQ(r.code, 0) << r.err;
        int na = 0, nb = 0;
        const std::vector<float> pa = pixelsOf(a, na), pb = pixelsOf(b, nb);
        ASSERT_EQ(na, 3);
        ASSERT_EQ(nb, 3);
        ASSERT_EQ(pa.size(), pb.size());
        EXPECT_EQ(std::memcmp(pa.data(), pb.data(), pa.size() * sizeof(float)), 0) << mods;
        // The reweighted image holds less light than the mean (fireflies removed), not none; at
        // 32 spp kappa 32 (the default) trusts little even of the base cascade.
        double sumRw = 0, sumMean = 0;
        for (float v : pa) sumRw += v;
        for (size_t q = 0; q < img.beauty.size(); ++q) sumMean += img.beauty[q];
        EXPECT_GT(sumRw, (mods.empty() ? 0.05 : 0.5) * sumMean) << mods;
        EXPECT_LE(sumRw, sumMean * (1 + 1e-6)) << mods;
    }
}

TEST_F(ReweightFile, OfflineGivesTheSameBytesOnOneThreadAndFour) {
    // From the records: the cascades (pixels in chunks), the reweighting, the AOVs' weights and
    // the spread (gathered) on threads; the records decoded on threads too. Every channel (the
    // beauty and the AOVs) must be the bytes of one thread.
    const std::string f = path("aovs.mcstat");
    ASSERT_EQ(render("--res 32 24 --spp 16 --M 1 --aovs --keep-samples -o " + f).code, 0);
    for (const std::string& mods : {std::string(""), std::string(":kappa=4:spread=2")}) {
        const std::string a = path("t1.exr"), b = path("t4.exr");
        ToolRun r = mcstat(f + " --threads 1 --reweight" + mods + " -o " + a);
        ASSERT_EQ(r.code, 0) << r.err;
        r = mcstat(f + " --threads 4 --reweight" + mods + " -o " + b);
        ASSERT_EQ(r.code, 0) << r.err;
        int na = 0, nb = 0;
        const std::vector<float> pa = pixelsOf(a, na), pb = pixelsOf(b, nb);
        EXPECT_GT(na, 3) << "the AOVs";
        ASSERT_EQ(na, nb);
        ASSERT_EQ(pa.size(), pb.size());
        EXPECT_EQ(std::memcmp(pa.data(), pb.data(), pa.size() * sizeof(float)), 0) << mods;
    }
}

TEST_F(ReweightFile, InfoAndCheckDescribeTheParts) {
    const std::string s = path("s.mcstat");
    ASSERT_EQ(
        render("--scene tiny --spp 8 --reweight --reweight-params base=4:count=5 -o " + s).code, 0);
    ToolRun r = mcstat(s + " --info");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("reweight (online, base=4:count=5:luma="), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("share of the luminance per cascade"), std::string::npos) << r.out;
    r = mcstat(s + " --check");
    EXPECT_EQ(r.code, 0) << r.err << r.out;
    r = render("--scene tiny --spp 4 --reweight --pajot rot -o " + path("x.mcstat"));
    EXPECT_NE(r.err.find("cannot be combined"), std::string::npos) << r.err;
}

TEST_F(ReweightFile, RefusalsAreOneLineErrors) {
    const std::string s = path("s.mcstat");
    ASSERT_EQ(
        render("--scene tiny --spp 8 --reweight --reweight-params base=4:count=5 -o " + s).code, 0);
    // The stored shape is used when asked for; another shape needs the records.
    ToolRun r;
    r = mcstat(s + " --reweight -o " + path("o.exr"));
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find("needs per-sample records"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    r = mcstat(s + " --reweight:base=4:count=5:kappa=2 -o " + path("o.exr"));
    EXPECT_EQ(r.code, 0) << r.err;
    // Bad values, named.
    r = mcstat(s + " --reweight:kappa=0 -o " + path("o.exr"));
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find("kappa must be"), std::string::npos) << r.err;
    r = render("--scene tiny --spp 4 --reweight --reweight-params base=0.5 -o " + path("x.mcstat"));
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find("base must be"), std::string::npos) << r.err;
    // A file with neither cascades nor records.
    ASSERT_EQ(render("--scene tiny --spp 4 -o " + path("plain.mcstat")).code, 0);
    r = mcstat(path("plain.mcstat") + " --reweight -o " + path("o.exr"));
    EXPECT_NE(r.err.find("neither per-sample records nor reweighting cascades"), std::string::npos)
        << r.err;
    EXPECT_NE(r.err.find("--online reweight"), std::string::npos) << r.err;
}

TEST_F(ReweightFile, AResumedRenderEqualsTheStraightOne) {
    const std::string half = path("half.mcstat"), resumed = path("resumed.mcstat"),
                      straight = path("straight.mcstat");
    ASSERT_EQ(render("--scene tiny --spp 8 --M 4 --reweight -o " + half).code, 0);
    ASSERT_EQ(render("--scene tiny --spp 16 --M 4 --resume " + half + " -o " + resumed).code, 0);
    ASSERT_EQ(render("--scene tiny --spp 16 --M 4 --reweight -o " + straight).code, 0);
    PixelStateParts a, b;
    std::string err;
    ASSERT_TRUE(readPixelStateParts(resumed, a, err)) << err;
    ASSERT_TRUE(readPixelStateParts(straight, b, err)) << err;
    EXPECT_EQ(a.owner, b.owner);
    EXPECT_EQ(a.words, b.words);
    EXPECT_EQ(a.floats, b.floats);
}

}  // namespace
}  // namespace mcstat
