// mcstat-render --clamp end to end: every kept sample obeys the limit with its AOVs still summing
// to it, the file says it was clamped, such a file never merges with an unclamped render, and
// bad limits are one-line refusals.
#include <cmath>
#include <string>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "tool_test.h"

namespace mcstat {
namespace {

class RenderClampTool : public testing::ToolTest {
  protected:
    RenderClampTool() : ToolTest("render") {}
};

TEST_F(RenderClampTool, EveryKeptSampleIsWithinTheLimitAndItsAovsStillSumToIt) {
    const std::string f = path("c.mcstat");
    const testing::ToolRun r = render(
        "--scene caustic --res 32 24 --spp 16 --M 4 --aovs --keep-samples --clamp 0.5 -o " + f);
    ASSERT_EQ(r.code, 0) << r.err;
    StatsImage img;
    std::string err;
    ASSERT_TRUE(readStatsFile(f, img, err)) << err;
    EXPECT_NE(img.header.scene.find("caustic"), std::string::npos);
    EXPECT_NE(img.header.scene.find(" clamp 0.5"), std::string::npos) << img.header.scene;
    SampleRecordsReader rec;
    ASSERT_TRUE(rec.open(f, err)) << err;
    SampleBlock block;
    ASSERT_TRUE(rec.read(0, img.header.height, block, err)) << err;
    const size_t A = img.header.aovs.size();
    std::vector<int> at(A);
    for (size_t a = 0; a < A; ++a)
        at[a] = block.channel(kRecordAovPrefix + img.header.aovs[a].name);
    size_t clamped = 0;
    for (size_t i = 0; i < block.samples.size() / block.stride(); ++i) {
        const float* s = &block.samples[i * block.stride()];
        const double sum = std::abs(s[0]) + std::abs(s[1]) + std::abs(s[2]);
        ASSERT_LE(sum, 0.5 * (1 + 1e-6)) << "sample " << i;
        if (sum > 0.5 * (1 - 1e-6)) ++clamped;
        for (int c = 0; c < 3; ++c) {
            double split = 0;
            for (size_t a = 1; a < A; a += 3) split += s[at[a + size_t(c)]];
            ASSERT_NEAR(split, s[c], 1e-6) << "sample " << i << " channel " << c;
        }
    }
    EXPECT_GT(clamped, 0u);  // the light and the caustic are above 0.5
}

TEST_F(RenderClampTool, AClampedRenderDoesNotMergeWithAnUnclampedOne) {
    const std::string a = path("a.mcstat"), b = path("b.mcstat"), c = path("c.mcstat");
    ASSERT_EQ(render("--scene tiny --spp 4 --M 2 --seed 1 --clamp 2 -o " + a).code, 0);
    ASSERT_EQ(render("--scene tiny --spp 4 --M 2 --seed 2 -o " + b).code, 0);
    ASSERT_EQ(render("--scene tiny --spp 4 --M 2 --seed 3 --clamp 2 -o " + c).code, 0);
    const testing::ToolRun refused = mcstat(a + " " + b + " --merge -o " + path("ab.mcstat"));
    EXPECT_NE(refused.code, 0);
    EXPECT_NE(refused.err.find("clamp 2"), std::string::npos) << refused.err;
    // Two renders with the same clamp are the same estimate: they merge.
    const testing::ToolRun merged = mcstat(a + " " + c + " --merge -o " + path("ac.mcstat"));
    EXPECT_EQ(merged.code, 0) << merged.err;
}

TEST_F(RenderClampTool, LimitsThatAreNotPositiveNumbersAreOneLineRefusals) {
    for (const char* bad : {"0", "-1", "x", "nan", "inf", "1e999"}) {
        SCOPED_TRACE(bad);
        const testing::ToolRun r =
            render(std::string("--scene tiny --spp 2 --clamp ") + bad + " -o " + path("x.mcstat"));
        EXPECT_NE(r.code, 0);
        EXPECT_NE(r.err.find("--clamp"), std::string::npos) << r.err;
        EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << r.err;
        EXPECT_TRUE(testing::slurp(path("x.mcstat")).empty());
    }
}

}  // namespace
}  // namespace mcstat
