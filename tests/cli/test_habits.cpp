// Habits from oiiotool and values a new user types (issue 34, items 3, 4 and 6): every compression
// level checked, a per-output DWA level, modifiers given twice, -v wherever it stands, the hints
// of "nothing on the stack", --check of a plain image, suggestions without case or dashes, and
// the exit status of a bare `mcstat`.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <gtest/gtest.h>

#include <string>

#include "cli_support.h"

namespace {

using mcstat::testing::Result;

class HabitsCli : public mcstat::testing::CliFixture {
  protected:
    void SetUp() override {
        CliFixture::SetUp();
        stats = path("s.mcstat");
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                                " --quiet --scene default --res 24 16 --spp 8 --M 4 -o " + stats;
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
    }
    std::string stats;
};

TEST_F(HabitsCli, EveryCompressionLevelIsChecked) {
    // Each of these wrote level 45 (or level 1 for 1e9) with exit status 0.
    for (const std::string bad : {"dwaa:abc", "dwaa:-5", "dwaa:nan", "dwaa:", "dwaa:1e9", "dwaa:0",
                                  "zip:abc", "zip:10", "zip:0", ":5"}) {
        const Result r = mcstat(stats + " --mean --compression " + bad + " -o " + path("a.exr"));
        EXPECT_EQ(r.code, 1) << bad;
        EXPECT_NE(r.err.find("compression"), std::string::npos) << bad << ": " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_FALSE(OIIO::Filesystem::exists(path("a.exr"))) << bad;
    }
    // OpenEXR's codecs without a level refuse one; a name OpenEXR does not know is refused at -o.
    Result r = mcstat(stats + " --mean -o:compression=piz:3 " + path("a.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("piz takes no level"), std::string::npos) << r.err;
    r = mcstat(stats + " --mean --compression lzw -o " + path("a.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("'lzw' is not one of OpenEXR's"), std::string::npos) << r.err;

    // A per-output DWA level (":" inside a modifier's value) and a zip level reach the file.
    r = mcstat(stats + " --mean -o:compression=dwaa:200 " + path("d.exr") +
               " --compression zip:9 -o " + path("z.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    OIIO::ImageBuf d(path("d.exr")), z(path("z.exr"));
    ASSERT_TRUE(d.init_spec(path("d.exr"), 0, 0) && z.init_spec(path("z.exr"), 0, 0));
    EXPECT_EQ(d.spec().get_string_attribute("compression"), "dwaa");
    EXPECT_FLOAT_EQ(d.spec().get_float_attribute("openexr:dwaCompressionLevel"), 200.f);
    EXPECT_EQ(z.spec().get_string_attribute("compression"), "zip");
}

TEST_F(HabitsCli, AModifierGivenTwiceIsRefused) {
    const Result r = mcstat(stats + " --gmon:mode=lum:mode=channel -o " + path("g.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("modifier 'mode' given twice ('lum' and 'channel')"), std::string::npos)
        << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("g.exr")));
    // A part that starts a name is still a modifier, and one without '=' is refused as before.
    const Result s = mcstat(stats + " --gmon:mode=lum:diag -o " + path("g.exr"));
    EXPECT_EQ(s.code, 1);
    EXPECT_NE(s.err.find("modifier 'diag' is not name=value"), std::string::npos) << s.err;
}

TEST_F(HabitsCli, VerboseHoldsWhereverItStandsAndHintsSayWhereTheFileGoes) {
    Result r = mcstat(stats + " --info -v");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("samples per pixel: min 8, max 8"), std::string::npos) << r.out;
    EXPECT_EQ(r.err.find("-v done"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("--info done in"), std::string::npos) << r.err;

    r = mcstat("--info " + stats);
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("put the file first, mcstat FILE --info"), std::string::npos) << r.err;
    r = mcstat("-o " + path("x.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("arguments run left to right"), std::string::npos) << r.err;

    r = mcstat("--help");
    EXPECT_NE(r.out.find("prints that command's modifiers with their ranges and defaults"),
              std::string::npos);
    EXPECT_NE(r.out.find("every later -o skips"), std::string::npos);
}

TEST_F(HabitsCli, MessagesSayWhatAUserNeeds) {
    // --check of a plain EXR says what --check checks.
    ASSERT_EQ(mcstat(stats + " --mean -o " + path("plain.exr")).code, 0);
    Result r = mcstat(path("plain.exr") + " --check");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("is an image, not a statistics file: --check validates"),
              std::string::npos)
        << r.err;
    // Suggestions ignore case and dashes.
    r = mcstat(stats + " -gmon");
    EXPECT_NE(r.err.find("(did you mean --gmon?)"), std::string::npos) << r.err;
    r = mcstat(stats + " --GMON");
    EXPECT_NE(r.err.find("(did you mean --gmon?)"), std::string::npos) << r.err;
    // A bare mcstat is an error (1), not --compare's DIFFERENT (2).
    r = mcstat("");
    EXPECT_EQ(r.code, 1);
}

// Against an image, a pixel the statistics file holds without noise is exact whatever :refspp=
// says (the reference's noise is the file's, scaled): the evidence says so, not "either side".
TEST_F(HabitsCli, CompareSaysWhereAnExactFindingsNoiseWouldComeFrom) {
    for (int s = 1; s <= 3; ++s) {
        OIIO::ImageBuf b(OIIO::ImageSpec(4, 4, 3, OIIO::TypeFloat));
        for (int y = 0; y < 4; ++y)
            for (int x = 0; x < 4; ++x) {
                const float v = x == 0 && y == 0 ? 0.5f : 0.25f + 0.01f * float(s * (x + y));
                const float px[3] = {v, v, v};
                b.setpixel(x, y, px);
            }
        ASSERT_TRUE(b.write(path("seed_" + std::to_string(s) + ".exr")));
    }
    OIIO::ImageBuf ref(OIIO::ImageSpec(4, 4, 3, OIIO::TypeFloat));
    const float quarter[3] = {0.25f, 0.25f, 0.25f};
    OIIO::ImageBufAlgo::fill(ref, quarter);
    ASSERT_TRUE(ref.write(path("ref.exr")));
    const std::string seeds = "--ingest:spp=8 '" + path("seed_*.exr") + "' ";
    Result r = mcstat(seeds + path("ref.exr") + " --compare:refspp=100");
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_NE(r.out.find("pixel (0, 0) luminance"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("exact (no noise in the statistics file here, so none in the reference "
                         "either: refspp scales the file's own)"),
              std::string::npos)
        << r.out;
    r = mcstat(seeds + path("ref.exr") + " --compare");
    EXPECT_NE(r.out.find("and the reference is taken as exact; :refspp= gives it noise"),
              std::string::npos)
        << r.out;
    EXPECT_EQ(r.out.find("either side"), std::string::npos) << r.out;
}

// mcstat-render: --version, and an output name that says what the file is (issue 34, item 5).
TEST_F(HabitsCli, TheRendererSaysItsVersionAndNamesWhatItWrites) {
    const auto render = [&](const std::string& args, Result& r) {
        const std::string o = path("render.out"), e = path("render.err");
        const int status = mcstat::testing::runCommand(
            (std::string(MCSTAT_RENDER_EXE) + " " + args + " >" + o + " 2>" + e).c_str());
        r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        r.out = mcstat::testing::slurp(o);
        r.err = mcstat::testing::slurp(e);
    };
    Result r;
    render("--version", r);
    EXPECT_EQ(r.code, 0);
    EXPECT_EQ(r.out, std::string("mcstat-render ") + MCSTAT_VERSION_TEXT + "\n");
    // A plain EXR named .mcstat is refused before rendering; a statistics file named .exr warns.
    render("--scene tiny --spp 4 --reference -o " + path("ref.mcstat"), r);
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("--reference writes a plain EXR image, not a statistics file"),
              std::string::npos)
        << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("ref.mcstat")));
    render("--scene tiny --spp 4 -o " + path("stats.exr"), r);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("warning: " + path("stats.exr") + ": a statistics file named .exr"),
              std::string::npos)
        << r.err;
    EXPECT_TRUE(OIIO::Filesystem::exists(path("stats.exr")));
}

// Renders of different scenes do not merge unless forced; the scene is recorded and shown
// (issue 34, item 7).
TEST_F(HabitsCli, RendersOfDifferentScenesDoNotMergeUnlessForced) {
    const auto render = [&](const std::string& scene, int seed, const std::string& out) {
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) + " --quiet --scene " + scene +
                                " --res 24 16 --spp 8 --M 4 --seed " + std::to_string(seed) +
                                " -o " + path(out);
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
    };
    render("default", 2, "d2.mcstat");
    render("caustic", 3, "c3.mcstat");
    Result r = mcstat(stats + " --info");
    EXPECT_NE(r.out.find("  scene default h"), std::string::npos) << r.out;
    r = mcstat(stats + " " + path("c3.mcstat") + " --merge -o " + path("m.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("are renders of different scenes ('default h"), std::string::npos)
        << r.err;
    EXPECT_NE(r.err.find("give --merge:force=1"), std::string::npos) << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("m.mcstat")));
    // The same scene, another seed: merges. Forced: the result names both scenes.
    r = mcstat(stats + " " + path("d2.mcstat") + " --merge -o " + path("m.mcstat"));
    EXPECT_EQ(r.code, 0) << r.err;
    r = mcstat(stats + " " + path("c3.mcstat") + " --merge:force=1 -o " + path("f.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    r = mcstat(path("f.mcstat") + " --info");
    EXPECT_NE(r.out.find(" + caustic h"), std::string::npos) << r.out;
    // One scene merged with itself is recorded once.
    r = mcstat(path("m.mcstat") + " --info");
    EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '+'), 0) << r.out;
}

}  // namespace
