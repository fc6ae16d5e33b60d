// Renders whose channel, layer and attribute names hold a newline, a form feed and ANSI escape
// sequences (ESC [31m, a title-setting OSC): no command prints any of those bytes, every error is
// one line, and the names reach the outputs themselves unchanged (a drop-in replacement keeps its
// channels). Issue 31; core/untrusted_text.h.
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "cli_support.h"
#include "mcstat/core/untrusted_text.h"

namespace {

using mcstat::testing::Result;

// An AOV layer named with a colour escape and a newline, a channel with a form feed.
const std::string kEvilLayer = "\x1b[31mred\nline";
const std::string kEvilChannel = kEvilLayer + ".R";
const std::string kFormFeedChannel = std::string("data\f\x1b]0;pwned\x07") + ".Z";
const std::string kEvilAttribute = "\x1b[2Jwipe\nname";
const std::string kEvilValue = "value\r\x1b[1A\x1b[2Kmcstat: forged verdict";

/// The bytes a terminal acts on: below 0x20 other than the newline between lines, and DEL.
std::string controlBytesIn(const std::string& text) {
    std::string found;
    for (const char c : text) {
        const auto b = static_cast<unsigned char>(c);
        if ((b < 0x20 && b != '\n') || b == 0x7f) found += mcstat::printable(std::string(1, c));
    }
    return found;
}

class HostileNames : public mcstat::testing::CliFixture {
  protected:
    /// A render of 6 x 4 pixels: R, G, B, A, the evil AOV channel and the form-feed channel, a
    /// string attribute with an escape-laden name and value.
    void writeRender(const std::string& name, float level, bool rgb = true) {
        OIIO::ImageSpec spec(6, 4, rgb ? 6 : 2, OIIO::TypeFloat);
        spec.channelnames =
            rgb ? std::vector<std::string>{"R", "G", "B", "A", kEvilChannel, kFormFeedChannel}
                : std::vector<std::string>{kEvilChannel, kFormFeedChannel};
        spec.alpha_channel = rgb ? 3 : -1;
        spec.attribute(kEvilAttribute, kEvilValue);
        spec.attribute("Software", "\x1b[32mrenderer\n");
        OIIO::ImageBuf buf(spec);
        std::vector<float> px(size_t(spec.nchannels), level);
        for (int y = 0; y < 4; ++y)
            for (int x = 0; x < 6; ++x) buf.setpixel(x, y, px.data());
        ASSERT_TRUE(buf.write(path(name))) << buf.geterror();
    }

    /// Runs `args`, expects `code`, and checks that neither stream holds a control byte.
    Result run(const std::string& args, int code) {
        const Result r = mcstat(args);
        EXPECT_EQ(r.code, code) << args << "\n" << r.err;
        EXPECT_EQ(controlBytesIn(r.out), "") << args << ": stdout\n" << mcstat::oneLine(r.out);
        EXPECT_EQ(controlBytesIn(r.err), "") << args << ": stderr\n" << mcstat::oneLine(r.err);
        EXPECT_TRUE(mcstat::isPrintable(r.out, true)) << args;
        EXPECT_TRUE(mcstat::isPrintable(r.err, true)) << args;
        return r;
    }
};

TEST_F(HostileNames, NoCommandPrintsAControlByteAndErrorsStayOneLine) {
    for (int s = 1; s <= 3; ++s)
        writeRender("seed_" + std::to_string(s) + ".exr", 0.25f * float(s));
    writeRender("norgb.exr", 0.5f, false);
    const std::string seeds = "'" + path("seed_*.exr") + "'";

    // The finding's shape: no beauty, the channels listed in the error, escaped, on one line.
    Result r = run("--ingest:spp=4 " + path("norgb.exr") + " -o " + path("x.mcstat"), 1);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find("'\\x1b[31mred\\nline.R'"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("'data\\x0c\\x1b]0;pwned\\x07.Z'"), std::string::npos) << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("x.mcstat")));

    // A layer asked for that is not there: the layers are listed (escaped).
    r = run("--ingest:spp=4:layer=nothing " + seeds + " -o " + path("x.mcstat"), 1);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;

    // Accepted: the -v listing names every AOV, escaped.
    r = run("-v --ingest:spp=4 " + seeds + " -o " + path("s.mcstat"), 0);
    EXPECT_NE(r.err.find("\\x1b[31mred\\nline.R"), std::string::npos) << r.err;

    // --info and --info -v of the statistics file (AOV names, renderer, sources), --check.
    r = run(path("s.mcstat") + " --info -v", 0);
    EXPECT_NE(r.out.find("\\x1b[31mred\\nline"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("renderer \"\\x1b[32mrenderer\\n via mcstat --ingest\""),
              std::string::npos)
        << r.out;
    run(path("s.mcstat") + " --check", 0);

    // A robust image keeps every channel under its own name, byte for byte, and the render's
    // metadata as it was (a drop-in replacement); --info of it escapes them.
    run(path("s.mcstat") + " --gmon -o " + path("g.exr"), 0);
    OIIO::ImageBuf g(path("g.exr"));
    ASSERT_TRUE(g.read()) << g.geterror();
    EXPECT_GE(g.spec().channelindex(kEvilChannel), 0);
    EXPECT_GE(g.spec().channelindex(kFormFeedChannel), 0);
    EXPECT_EQ(g.spec().get_string_attribute(kEvilAttribute), kEvilValue);
    r = run(path("g.exr") + " --info", 0);
    EXPECT_NE(r.out.find(",\\x1b[31mred\\nline.R,"), std::string::npos) << r.out;

    // -d on a channel the image lacks lists the channels; --compare names AOVs in its evidence.
    run(path("s.mcstat") + " --gmon -d nothing=half -o " + path("h.exr"), 1);
    run(path("s.mcstat") + " " + path("s.mcstat") + " --compare:aovs=*", 0);
    r = run(path("s.mcstat") + " " + path("s.mcstat") + " --compare:aovs=nothing*", 1);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

// The fuzzing finding itself (tests/fuzz/regressions/ingest/channel-name-with-newline.exr): its
// channel names hold a newline, a form feed and other raw bytes; the refusal is one line with
// every one of them escaped.
TEST_F(HostileNames, TheFuzzFindingIsOneLineWithItsBytesEscaped) {
    const std::string finding = std::string(MCSTAT_SOURCE_DIR) +
                                "/tests/fuzz/regressions/ingest/channel-name-with-newline.exr";
    const Result r = run("--ingest:spp=4 " + finding + " -o " + path("y.mcstat"), 1);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_EQ(r.err.rfind("mcstat: --ingest: " + finding + ": no RGB channels", 0), 0) << r.err;
    EXPECT_NE(r.err.find("\\x12"), std::string::npos) << r.err;   // a control byte
    EXPECT_NE(r.err.find("\\x0c"), std::string::npos) << r.err;   // the form feed
    EXPECT_NE(r.err.find("\\n"), std::string::npos) << r.err;     // the newline
    EXPECT_NE(r.err.find("\\xc0p"), std::string::npos) << r.err;  // a byte that is not UTF-8
    EXPECT_FALSE(OIIO::Filesystem::exists(path("y.mcstat")));
}

}  // namespace
