// Frame sequences with oiiotool's syntax (oiiotool-ext/frames.cpp): a 5-frame x 7-seed shot of
// plain EXRs (frames with gaps) into five statistics files with one command and five half-float
// G-MoN EXRs with another; --parallel-frames writes the same bytes; #, @, %0Nd, --frames,
// --framepadding, --skip-bad-frames; --ingest refuses a glob that mixes frames.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

#include "cli_support.h"

namespace {

using mcstat::testing::slurp;

class FramesCli : public mcstat::testing::CliFixture {
  protected:
    const std::vector<int> frames{1, 2, 4, 7, 8};  // gaps on purpose
    /// shot_s<seed>.<frame, 4 digits>.exr: plain EXRs of the fixture renderer, one per seed.
    void renderShot(int seeds = 7) {
        for (int f : frames)
            for (int s = 1; s <= seeds; ++s) {
                char name[64];
                std::snprintf(name, sizeof name, "shot_s%d.%04d.exr", s, f);
                const std::string cmd =
                    std::string(MCSTAT_RENDER_EXE) +
                    " --quiet --scene default --res 24 16 --spp 4 --reference --seed " +
                    std::to_string(100 * f + s) + " -o " + path(name);
                ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
            }
    }
    std::string frameFile(const std::string& stem, int f, const std::string& ext) {
        char name[64];
        std::snprintf(name, sizeof name, "%s.%04d.%s", stem.c_str(), f, ext.c_str());
        return path(name);
    }
};

TEST_F(FramesCli, AShotOfSeedRendersIntoStatisticsFilesThenHalfImagesPerFrame) {
    renderShot();
    auto r = mcstat("--ingest '" + path("shot_s*.#.exr") + "' -o '" + path("shot.#.mcstat") + "'");
    ASSERT_EQ(r.code, 0) << r.err;
    for (int f : frames) {
        OIIO::ImageBuf b(frameFile("shot", f, "mcstat"));
        ASSERT_TRUE(OIIO::Filesystem::exists(frameFile("shot", f, "mcstat"))) << f;
        // Seven seeds of this frame only: M = 7, spp 7 x 4.
        const auto info = mcstat(frameFile("shot", f, "mcstat") + " --info");
        EXPECT_NE(info.out.find("M = 7 sub-buffers, spp = 28"), std::string::npos) << info.out;
    }
    EXPECT_FALSE(OIIO::Filesystem::exists(frameFile("shot", 3, "mcstat")));  // a gap stays one

    r = mcstat("'" + path("shot.#.mcstat") + "' --gmon -d half -o '" + path("gmon.#.exr") + "'");
    ASSERT_EQ(r.code, 0) << r.err;
    OIIO::Filesystem::create_directory(path("par"));
    r = mcstat("'" + path("shot.#.mcstat") + "' --gmon -d half -o '" + path("par/gmon.#.exr") +
               "' --parallel-frames");
    ASSERT_EQ(r.code, 0) << r.err;
    for (int f : frames) {
        OIIO::ImageBuf b(frameFile("gmon", f, "exr"));
        ASSERT_TRUE(b.init_spec(frameFile("gmon", f, "exr"), 0, 0)) << f;
        EXPECT_EQ(b.nativespec().format, OIIO::TypeDesc::HALF);
        const std::string serial = slurp(frameFile("gmon", f, "exr"));
        EXPECT_FALSE(serial.empty());
        EXPECT_EQ(serial, slurp(frameFile("par/gmon", f, "exr"))) << "frame " << f;
    }
    // --frames picks frames (in the order given); @@@@ and %04d are the same pattern.
    r = mcstat("'" + path("shot.@@@@.mcstat") + "' --frames 8,2 --mean -o '" +
               path("mean.%04d.exr") + "'");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(OIIO::Filesystem::exists(frameFile("mean", 8, "exr")));
    EXPECT_TRUE(OIIO::Filesystem::exists(frameFile("mean", 2, "exr")));
    EXPECT_FALSE(OIIO::Filesystem::exists(frameFile("mean", 1, "exr")));
    // --framepadding 2: # is two digits.
    r = mcstat("--framepadding 2 --frames 1-3 '" + path("shot.00#.mcstat") + "' --mean -o '" +
               path("p.#.exr") + "'");
    EXPECT_EQ(r.code, 1);  // frame 3 does not exist: the run stops there
    EXPECT_TRUE(OIIO::Filesystem::exists(path("p.01.exr")));
    EXPECT_NE(r.err.find("frame 3: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("1 of 3 frames failed: 3"), std::string::npos) << r.err;
}

TEST_F(FramesCli, SkipBadFramesGoesOnAndStillFails) {
    renderShot(2);
    ASSERT_EQ(
        mcstat("--ingest '" + path("shot_s*.#.exr") + "' -o '" + path("shot.#.mcstat") + "'").code,
        0);
    auto r =
        mcstat("--frames 1-4 '" + path("shot.#.mcstat") + "' --mean -o '" + path("m.#.exr") + "'");
    EXPECT_EQ(r.code, 1);
    EXPECT_FALSE(OIIO::Filesystem::exists(frameFile("m", 4, "exr")));  // stopped at frame 3
    r = mcstat("--skip-bad-frames --frames 1-4 '" + path("shot.#.mcstat") + "' --mean -o '" +
               path("m.#.exr") + "'");
    EXPECT_EQ(r.code, 1);
    EXPECT_TRUE(OIIO::Filesystem::exists(frameFile("m", 4, "exr")));
    EXPECT_NE(r.err.find("1 of 4 frames failed: 3"), std::string::npos) << r.err;
}

TEST_F(FramesCli, IngestRefusesAGlobThatMixesFrames) {
    renderShot(2);
    auto r = mcstat("--ingest '" + path("shot_s1.*.exr") + "' -o " + path("x.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("renders of 5 frames (by their names: 1, 2, 4, 7, 8)"), std::string::npos)
        << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("x.mcstat")));
    // By metadata: Blender's Frame attribute, names without a frame number.
    for (int s = 1; s <= 2; ++s) {
        OIIO::ImageBuf b(frameFile("shot_s" + std::to_string(s), s, "exr"));
        ASSERT_TRUE(b.read()) << b.geterror();
        b.specmod().attribute("Frame", "00" + std::to_string(s));
        ASSERT_TRUE(b.write(path("meta_s" + std::to_string(s) + ".exr")));
    }
    r = mcstat("--ingest '" + path("meta_s*.exr") + "' -o " + path("y.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("2 frames (by their Frame metadata: 1, 2)"), std::string::npos) << r.err;
}

TEST_F(FramesCli, RefusalsSayWhatIsMissing) {
    auto r = mcstat("'" + path("none.#.mcstat") + "' --mean");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("no file of this frame sequence exists"), std::string::npos) << r.err;
    r = mcstat("--frames 1-3 " + path("a.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("need a frame pattern"), std::string::npos) << r.err;
    r = mcstat("--frames 1-x '" + path("a.#.mcstat") + "'");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("'1-x' is not a frame range"), std::string::npos) << r.err;
    r = mcstat("--frames 1-10000000 '" + path("a.#.mcstat") + "'");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("more than 1000000 frames"), std::string::npos) << r.err;
    r = mcstat("--skip-bad-frames " + path("a.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("no file name holds a frame pattern"), std::string::npos) << r.err;
}

// Issue 34, item 1: a frame that fails stops the run in both modes (as oiiotool), the parallel
// run's errors say which frame as the serial run's do, and the summary says what was not done.
TEST_F(FramesCli, AFailedFrameStopsBothModesAndTheSummarySaysWhatWasNotDone) {
    renderShot(2);
    ASSERT_EQ(mcstat("--frames 1,2,4 --ingest '" + path("shot_s*.#.exr") + "' -o '" +
                     path("shot.#.mcstat") + "'")
                  .code,
              0);
    // Frame 2 truncated: its headers stay, its chunks go.
    const std::string two = frameFile("shot", 2, "mcstat");
    const std::string bytes = slurp(two);
    std::ofstream(two, std::ios::binary | std::ios::trunc).write(bytes.data(), 2000);

    auto r = mcstat("'" + path("shot.#.mcstat") + "' --gmon -o '" + path("s.#.exr") + "'");
    EXPECT_EQ(r.code, 1);
    EXPECT_TRUE(OIIO::Filesystem::exists(frameFile("s", 1, "exr")));
    EXPECT_FALSE(OIIO::Filesystem::exists(frameFile("s", 4, "exr")));
    EXPECT_NE(r.err.find("mcstat: frame 2: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("1 of 3 frames failed: 2; not attempted: 4 (--skip-bad-frames"),
              std::string::npos)
        << r.err;

    r = mcstat("'" + path("shot.#.mcstat") + "' --gmon -o '" + path("p.#.exr") +
               "' --parallel-frames");
    EXPECT_EQ(r.code, 1);
    EXPECT_TRUE(OIIO::Filesystem::exists(frameFile("p", 1, "exr")));
    EXPECT_NE(r.err.find("mcstat: frame 2: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("1 of 3 frames failed: 2"), std::string::npos) << r.err;
    // Frame 4 runs beside frame 2 or after it: either it finished before frame 2 failed (and the
    // summary does not list it), or it was stopped or never started (and it has no output).
    const bool four = OIIO::Filesystem::exists(frameFile("p", 4, "exr"));
    const bool listed = r.err.find("stopped when it failed: 4") != std::string::npos ||
                        r.err.find("not attempted: 4") != std::string::npos;
    EXPECT_NE(four, listed) << r.err;

    // --skip-bad-frames: every frame tried in both modes, the summary without a "not attempted".
    for (const std::string mode : {"", " --parallel-frames"}) {
        r = mcstat("--skip-bad-frames '" + path("shot.#.mcstat") + "' --gmon -o '" +
                   path("k.#.exr") + "'" + mode);
        EXPECT_EQ(r.code, 1) << mode;
        EXPECT_TRUE(OIIO::Filesystem::exists(frameFile("k", 4, "exr"))) << mode;
        EXPECT_NE(r.err.find("1 of 3 frames failed: 2\n"), std::string::npos) << mode << r.err;
        OIIO::Filesystem::remove(frameFile("k", 4, "exr"));
    }
}

// Issue 34, item 2: every frame writing one file is refused before anything runs.
TEST_F(FramesCli, AnOutputWithoutAFramePatternIsRefusedForSeveralFrames) {
    renderShot(2);
    ASSERT_EQ(
        mcstat("--ingest '" + path("shot_s*.#.exr") + "' -o '" + path("shot.#.mcstat") + "'").code,
        0);
    for (const std::string mode : {"", " --parallel-frames"}) {
        auto r = mcstat("'" + path("shot.#.mcstat") + "' --mean -o " + path("one.exr") + mode);
        EXPECT_EQ(r.code, 1) << mode;
        EXPECT_NE(r.err.find("every one of the 5 frames of " + path("shot.#.mcstat") +
                             " would write this one file"),
                  std::string::npos)
            << r.err;
        EXPECT_NE(r.err.find("e.g. " + path("one.#.exr")), std::string::npos) << r.err;
        EXPECT_FALSE(OIIO::Filesystem::exists(path("one.exr"))) << mode;
    }
    // One frame writes one file: allowed.
    auto r = mcstat("--frames 2 '" + path("shot.#.mcstat") + "' --mean -o " + path("one.exr"));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(OIIO::Filesystem::exists(path("one.exr")));
}

}  // namespace
