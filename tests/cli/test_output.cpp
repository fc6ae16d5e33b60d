// oiiotool's output conventions on -o: -d TYPE and -d CH=TYPE, --compression NAME[:QUALITY],
// -o:type= and :compression= for one output, --no-clobber, and the warning when half cannot hold
// a value. Each refusal is one line naming what is wrong.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <gtest/gtest.h>

#include <cmath>
#include <ctime>

#include "cli_support.h"

namespace {

class OutputCli : public mcstat::testing::CliFixture {
  protected:
    void SetUp() override {
        CliFixture::SetUp();
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                                " --quiet --scene default --res 32 24 --spp 8 --M 4 --aovs -o " +
                                path("aov.mcstat");
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0);
    }
    OIIO::ImageSpec specOf(const std::string& name) {
        OIIO::ImageBuf b(path(name));
        EXPECT_TRUE(b.init_spec(path(name), 0, 0)) << b.geterror();
        return b.nativespec();
    }
};

TEST_F(OutputCli, DataTypesAndCompressionPerRunAndPerOutput) {
    const auto r = mcstat(path("aov.mcstat") + " --gmon -o " + path("f.exr") + " -d half -o " +
                          path("h.exr") + " -d A=float --compression dwaa:45 -o " + path("ha.exr") +
                          " -o:type=float:compression=piz " + path("p.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(specOf("f.exr").format, OIIO::TypeDesc::FLOAT);  // the default
    EXPECT_EQ(specOf("f.exr").get_string_attribute("compression"), "zip");
    const OIIO::ImageSpec h = specOf("h.exr");
    EXPECT_EQ(h.format, OIIO::TypeDesc::HALF);
    EXPECT_TRUE(h.channelformats.empty());
    const OIIO::ImageSpec ha = specOf("ha.exr");
    ASSERT_EQ(int(ha.channelformats.size()), ha.nchannels);
    for (int c = 0; c < ha.nchannels; ++c)
        EXPECT_EQ(ha.channelformat(c),
                  ha.channel_name(c) == "A" ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::HALF)
            << ha.channel_name(c);
    EXPECT_EQ(ha.get_string_attribute("compression"), "dwaa");
    EXPECT_EQ(ha.get_float_attribute("openexr:dwaCompressionLevel"), 45.f);
    // -o:type= replaces -d for this output only, :compression= --compression.
    const OIIO::ImageSpec p = specOf("p.exr");
    EXPECT_EQ(p.format, OIIO::TypeDesc::FLOAT);
    EXPECT_TRUE(p.channelformats.empty());
    EXPECT_EQ(p.get_string_attribute("compression"), "piz");
    // The AOVs are all there, whatever the type.
    EXPECT_EQ(h.nchannels, specOf("f.exr").nchannels);
}

TEST_F(OutputCli, HalfOverflowIsCountedAndSaid) {
    // 4 x 3 pixels of (70000, 1, -1e6): 24 values beyond 65504, written as +-Inf.
    OIIO::ImageBuf big(OIIO::ImageSpec(4, 3, 3, OIIO::TypeDesc::FLOAT));
    const float v[3] = {70000.f, 1.f, -1e6f};
    OIIO::ImageBufAlgo::fill(big, v);
    ASSERT_TRUE(big.write(path("big.exr")));
    auto r = mcstat(path("big.exr") + " -d half -o " + path("h.exr"));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("24 values exceed half's largest, 65504"), std::string::npos) << r.err;
    OIIO::ImageBuf h(path("h.exr"));
    float px[3];
    ASSERT_TRUE(h.read()) << h.geterror();
    h.getpixel(0, 0, px, 3);
    EXPECT_TRUE(std::isinf(px[0]) && px[0] > 0);
    EXPECT_EQ(px[1], 1.f);
    // -q (anywhere on the line): the same file, not a word; errors still speak.
    r = mcstat(path("big.exr") + " -d half -o " + path("hq.exr") + " -q");
    EXPECT_EQ(r.code, 0);
    EXPECT_EQ(r.err, "");
    EXPECT_EQ(mcstat::testing::slurp(path("hq.exr")), mcstat::testing::slurp(path("h.exr")));
    r = mcstat("-q " + path("big.exr") + " -d hlf -o " + path("hq.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("-d: TYPE must be half or float"), std::string::npos) << r.err;
    // Those channels as float: nothing to say.
    r = mcstat(path("big.exr") + " -d half -d R=float -d B=float -o " + path("h2.exr"));
    EXPECT_EQ(r.code, 0);
    EXPECT_EQ(r.err.find("exceed"), std::string::npos) << r.err;
}

TEST_F(OutputCli, NoClobberKeepsWhatExists) {
    ASSERT_EQ(mcstat(path("aov.mcstat") + " --mean -o " + path("m.exr")).code, 0);
    const std::time_t before = OIIO::Filesystem::last_write_time(path("m.exr"));
    const std::string bytes = mcstat::testing::slurp(path("m.exr"));
    const auto r = mcstat("--no-clobber " + path("aov.mcstat") + " --gmon -o " + path("m.exr") +
                          " -o " + path("new.exr"));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("exists; not overwritten (--no-clobber)"), std::string::npos) << r.err;
    EXPECT_EQ(mcstat::testing::slurp(path("m.exr")), bytes);
    EXPECT_EQ(OIIO::Filesystem::last_write_time(path("m.exr")), before);
    EXPECT_TRUE(OIIO::Filesystem::exists(path("new.exr")));  // the run went on
}

TEST_F(OutputCli, StreamedEstimateShowsProgressOnATerminalOnly) {
    // Not on a terminal (this test's stderr is a file): not a byte.
    auto r = mcstat(path("aov.mcstat") + " --gmon -o " + path("g.exr"));
    ASSERT_EQ(r.code, 0);
    EXPECT_EQ(r.err, "");
    // On a terminal (util-linux's script gives the command a pseudo-terminal): the progress line.
    const std::string cmd = "script -qec '" + std::string(MCSTAT_EXE) + " " + path("aov.mcstat") +
                            " --gmon -o " + path("g2.exr") + "' /dev/null > " + path("tty.txt");
    ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0);
    const std::string tty = mcstat::testing::slurp(path("tty.txt"));
    EXPECT_NE(tty.find("mcstat: --gmon 100.0%"), std::string::npos) << tty;
}

TEST_F(OutputCli, RefusalsNameWhatIsWrong) {
    const std::string in = path("aov.mcstat") + " --gmon ";
    auto r = mcstat(in + "-d hlf -o " + path("x.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("-d: TYPE must be half or float"), std::string::npos) << r.err;
    r = mcstat(in + "--compression foo -o " + path("x.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("compression 'foo' is not one of OpenEXR's"), std::string::npos) << r.err;
    r = mcstat(in + "-d Q=half -o " + path("x.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("no channel 'Q'"), std::string::npos) << r.err;
    r = mcstat(in + "-d half -o " + path("x.png"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("8-bit display values"), std::string::npos) << r.err;
    r = mcstat(in + "-o:type=int " + path("x.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_FALSE(OIIO::Filesystem::exists(path("x.exr")));
    // A statistics file keeps its format: refused for this output, a note for the run's options.
    r = mcstat(path("aov.mcstat") + " -o:type=half " + path("s.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("a statistics file is written as its format says"), std::string::npos);
    r = mcstat("-d half " + path("aov.mcstat") + " -o " + path("s.mcstat"));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("written as float32 ZIP"), std::string::npos) << r.err;
}

}  // namespace
