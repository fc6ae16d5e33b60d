// mcstat-render end to end: the file it writes is byte-identical for any --threads, although the
// thread count also sizes OpenEXR's compression pool; --timings reports the render and the writing;
// --online NAME:key=value writes what the deprecated --pajot* / --reweight* options write, and
// refuses a bad parameter in one line.
#include <algorithm>
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

/// Lines of `text` (each ends with a newline).
long lineCount(const std::string& text) { return long(std::count(text.begin(), text.end(), '\n')); }

TEST_F(RenderTool, OnlineFormWritesTheBytesOfTheDeprecatedFlags) {
    const std::string base = "--scene tiny --res 12 8 --spp 9 --M 3 --keep-samples ";
    const std::pair<std::string, std::string> forms[] = {
        {"--pajot hybrid --pajot-n 4 --pajot-delayed 8 --pajot-t 3 --pajot-delta 0.5",
         "--online pajot:method=hybrid:n=4:delayed=8:t=3:delta=0.5"},
        {"--pajot rot --pajot-n 5", "--online pajot:method=rot:n=5"},
        {"--reweight", "--online reweight"},
        {"--reweight --reweight-params base=4:count=5", "--online reweight:count=5:base=4"}};
    for (const auto& [old, online] : forms) {
        SCOPED_TRACE(old + " / " + online);
        const std::string a = path("old.mcstat"), b = path("new.mcstat");
        testing::ToolRun r = render(base + old + " -o " + a);
        ASSERT_EQ(r.code, 0) << r.err;
        // One line names the new form; nothing else is said.
        EXPECT_EQ(lineCount(r.err), 1) << r.err;
        EXPECT_NE(r.err.find("mcstat-render: note: --"), std::string::npos) << r.err;
        EXPECT_NE(r.err.find("deprecated: use --online "), std::string::npos) << r.err;
        r = render(base + online + " -o " + b);
        ASSERT_EQ(r.code, 0) << r.err;
        EXPECT_EQ(r.err, "");
        const std::string bytes = slurp(a);
        ASSERT_FALSE(bytes.empty());
        EXPECT_TRUE(bytes == slurp(b)) << "the two forms wrote different files";
    }
}

TEST_F(RenderTool, OnlineRefusesABadParameterInOneLine) {
    const std::string out = " -o " + path("x.mcstat");
    const std::pair<std::string, std::string> bad[] = {
        {"--online pajot:method=adr:n=0",
         "--online pajot: n must be an integer in [1, 1000000], not '0'"},
        // Without a method: the default ("stored") reads a result; rendering needs an estimator.
        {"--online pajot",
         "--online pajot: choose the online estimator, method=adr, rot or hybrid (e.g. --online "
         "pajot:method=hybrid)"},
        {"--online pajot:method=fast",
         "--online pajot: method must be 'stored', 'adr', 'rot' or 'hybrid'"},
        {"--online pajot:method=adr:mdoe=1", "--online pajot has no modifier 'mdoe'"},
        {"--online pajot:method=adr:n", "--online pajot: 'n' is not name=value"},
        {"--online reweight:base=0.5", "--online reweight: base must be"},
        {"--online reweight:kappa=2", "--online reweight: kappa is chosen when reweighting"},
        {"--online gmon", "--online: 'gmon' is no operation this renderer runs online"},
        {"--online pajot:method=adr --online reweight",
         "--online pajot and --online reweight cannot be combined"},
        {"--online pajot:method=adr --reweight",
         "--reweight and --online pajot cannot be combined"}};
    for (const auto& [args, message] : bad) {
        SCOPED_TRACE(args);
        const testing::ToolRun r = render("--scene tiny --spp 2 " + args + out);
        EXPECT_NE(r.code, 0);
        const size_t at = r.err.find("mcstat-render: " + message);
        EXPECT_NE(at, std::string::npos) << r.err;
        // The error is one line (after the deprecation note, when an old flag was given).
        EXPECT_EQ(lineCount(r.err.substr(at)), 1) << r.err;
        EXPECT_FALSE(OIIO::Filesystem::exists(path("x.mcstat")));
    }
}

}  // namespace
}  // namespace mcstat
