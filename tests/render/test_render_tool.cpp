// mcstat-render end to end: the file it writes is byte-identical for any --threads, although the
// thread count also sizes OpenEXR's compression pool; --timings reports the render and the writing;
// --online NAME:key=value writes what the deprecated --pajot* / --reweight* options write, and
// refuses a bad parameter in one line; --reference writes a labelled float EXR of the mean through
// OpenEXR, and the program never loads libOpenImageIO.
#include <OpenImageIO/imagebuf.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "mcstat/core/color_space.h"
#include "mcstat/exr-deep/stats_file.h"
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

TEST_F(RenderTool, ReferenceIsALabelledFloatExrOfTheMean) {
    // --reference and a one-buffer statistics file draw the same samples (the same seed, pixel and
    // index); the reference keeps only their mean, through OpenEXR's own writer.
    const std::string ref = path("ref.exr"), stats = path("one.mcstat");
    const std::string scene = "--scene caustic --res 12 9 --spp 16 --seed 5 ";
    ASSERT_EQ(render(scene + "--reference -o " + ref).code, 0);
    ASSERT_EQ(render(scene + "--M 1 -o " + stats).code, 0);
    OIIO::ImageBuf img(ref);
    ASSERT_TRUE(img.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << img.geterror();
    const OIIO::ImageSpec& s = img.spec();
    ASSERT_EQ(s.width, 12);
    ASSERT_EQ(s.height, 9);
    ASSERT_EQ(s.nchannels, 3);
    EXPECT_EQ(s.channelnames, (std::vector<std::string>{"R", "G", "B"}));
    EXPECT_EQ(s.format, OIIO::TypeDesc::FLOAT);
    EXPECT_EQ(s.get_string_attribute("compression"), "zip");
    EXPECT_EQ(s.get_string_attribute("Software"), "mcstat-render 0.1");
    EXPECT_EQ(s.get_string_attribute("mcstat:seeds"), "5");
    EXPECT_EQ(s.get_string_attribute("mcstat:spp"), "16");
    EXPECT_FALSE(s.get_string_attribute("DateTime").empty());
    const WorkingSpace* rec709 = findWorkingSpace("lin_rec709");
    ASSERT_NE(rec709, nullptr);
    EXPECT_EQ(s.get_string_attribute("colorInteropID"), rec709->interopID);
    const OIIO::ParamValue* xy =
        s.find_attribute("chromaticities", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8));
    ASSERT_NE(xy, nullptr);
    EXPECT_FLOAT_EQ(xy->get<float>(0), float(rec709->xy.rx));
    EXPECT_FLOAT_EQ(xy->get<float>(7), float(rec709->xy.wy));

    StatsImage one;
    std::string err;
    ASSERT_TRUE(readStatsFile(stats, one, err)) << err;
    ASSERT_EQ(one.header.M, 1);
    ASSERT_EQ(one.mean.size(), size_t(12 * 9 * 3));
    double sum = 0;
    for (int y = 0; y < 9; ++y)
        for (int x = 0; x < 12; ++x)
            for (int c = 0; c < 3; ++c) {
                const float want = one.mean[(size_t(y) * 12 + size_t(x)) * 3 + size_t(c)];
                EXPECT_NEAR(img.getchannel(x, y, 0, c), want, 1e-6f * std::max(1.f, std::abs(want)))
                    << x << "," << y << " channel " << c;
                sum += want;
            }
    EXPECT_GT(sum, 0.0);  // the caustic is lit: a zero image would pass the comparison
}

TEST_F(RenderTool, NeverLoadsLibOpenImageIO) {
    // Debian's libOpenImageIO brings some 260 shared libraries whose symbols took 0.2 s of every
    // start; the renderer needs only OIIO's utility library (render-fixture/src/reference_exr.h).
    const testing::ToolRun r = run("ldd", MCSTAT_RENDER_EXE);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("libOpenImageIO_Util.so"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("libOpenImageIO.so"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace mcstat
