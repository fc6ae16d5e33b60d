// mcstat-render end to end: the file it writes is byte-identical for any --threads, although the
// thread count also sizes OpenEXR's compression pool; --timings reports the render and the writing.
#include <string>

#include "tool_test.h"

namespace mcstat {
namespace {

using testing::slurp;

class RenderTool : public testing::ToolTest {
  protected:
    RenderTool() : ToolTest("render") {}

    /// Renders `args` with 1, 2 and 6 threads (no pool, a pool of 2, the pool's cap) and expects
    /// three equal, non-empty files.
    void expectSameBytesForAnyThreads(const std::string& args) {
        std::string first;
        for (const char* threads : {"1", "2", "6"}) {
            SCOPED_TRACE(args + " --threads " + threads);
            const std::string f = path(std::string("t") + threads + ".mcstat");
            const testing::ToolRun r = render(args + " --threads " + threads + " -o " + f);
            ASSERT_EQ(r.code, 0) << r.err;
            const std::string bytes = slurp(f);
            ASSERT_FALSE(bytes.empty());
            if (first.empty())
                first = bytes;
            else
                EXPECT_TRUE(bytes == first) << f << " differs from the one-thread file";
        }
    }
};

TEST_F(RenderTool, FixedMFileIsByteIdenticalForAnyThreadCount) {
    // Tall enough for several 16-line compression blocks per part, so the pool has work to split.
    expectSameBytesForAnyThreads("--scene default --res 24 70 --spp 24 --M 21");
}

TEST_F(RenderTool, AdaptiveGrowFileIsByteIdenticalForAnyThreadCount) {
    expectSameBytesForAnyThreads("--scene caustic --res 24 40 --spp 32 --adaptive-m");
}

TEST_F(RenderTool, PilotWithRecordsAndPajotIsByteIdenticalForAnyThreadCount) {
    // Deep parts (vbuffers, records) and the Pajot parts go through the same pool.
    expectSameBytesForAnyThreads(
        "--scene dof --res 16 40 --spp 6 --adaptive-m --m-strategy pilot --pilot 4 "
        "--keep-samples --pajot hybrid --pajot-n 3");
}

TEST_F(RenderTool, TimingsReportTheRenderAndTheWriting) {
    const std::string f = path("a.mcstat");
    testing::ToolRun r = render("--scene tiny --res 8 6 --spp 2 --M 3 --timings -o " + f);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("mcstat-render: timings: render wall "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(", write wall "), std::string::npos) << r.err;
    r = render("--scene tiny --res 8 6 --spp 2 --M 3 -o " + f);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.err.find("timings"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace mcstat
