// Seeds of renders (docs/ingest.md, "Seeds"): a file's Note stamp (`seed=N`, as Blender writes
// its metadata note and mcstat-blender fills it) and its name through --ingest:seed=PATTERN give
// its seed, recorded in mcstat:seeds instead of the content hash; the two must agree, and two
// files of one seed are refused. Blender itself: tests/aovs/test_mcstat_blender.sh.
#include <OpenImageIO/filesystem.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "../cli/cli_support.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/ingest/ingest.h"
#include "render_files.h"

namespace mcstat::testing {
namespace {

class IngestSeeds : public CliFixture {
  protected:
    /// A plain RGB render, its pixels those of render `k` (a seed's noise), 16 spp, with `note` as
    /// its Note attribute when not empty.
    std::string write(const std::string& name, int k, const std::string& note = "") {
        ExrSpec e;
        e.channels = {"R", "G", "B"};
        e.stringAttrs["mcstat:spp"] = "16";
        if (!note.empty()) e.stringAttrs["Note"] = note;
        const std::string p = path(name);
        writeExr(p, e, [&](const std::string& n, int x, int y) {
            return 0.1f * float(x) + 0.05f * float(y) + 0.2f * float(n[0] - 'B') +
                   0.125f * float(k * k % 11);
        });
        return p;
    }
    std::string seedsOf(const std::string& file) {
        StatsHeader h;
        std::string err;
        EXPECT_TRUE(readStatsHeader(file, h, err)) << err;
        return h.seeds;
    }
    static size_t lines(const std::string& s) {
        return size_t(std::count(s.begin(), s.end(), '\n'));
    }
};

TEST_F(IngestSeeds, TheNoteStampGivesEachFilesSeed) {
    // Blender's metadata note as mcstat-blender writes it, another text around a seed, and a file
    // that says none: that one keeps its content hash.
    write("a_1.exr", 1, "seed=1 frame=1 cycles_seed=1001");
    write("a_2.exr", 2, "take 3, seed=12; lit by the key only");
    write("a_3.exr", 3, "no seed here: cycles_seed=7 seed=x8 reseed=9");
    write("a_4.exr", 4, "Seed=0040");
    const Result r = mcstat("--ingest '" + path("a_*.exr") + "' -o " + path("a.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    const std::string seeds = seedsOf(path("a.mcstat"));
    ASSERT_EQ(seeds.size(), std::string("1,12,h0123456789abcdef,40").size()) << seeds;
    EXPECT_EQ(seeds.substr(0, 6), "1,12,h") << seeds;
    EXPECT_EQ(seeds.substr(seeds.size() - 3), ",40") << seeds;
    // In memory (ingestRenders and --info) as in the file.
    StatsImage img;
    IngestReport rep;
    std::string err;
    std::vector<std::string> paths;
    ASSERT_TRUE(expandInputs(path("a_*.exr"), paths, err)) << err;
    ASSERT_TRUE(ingestRenders(paths, IngestOptions(), img, rep, err)) << err;
    EXPECT_EQ(img.header.seeds, seeds);
    const Result info = mcstat("--ingest '" + path("a_*.exr") + "' --info");
    EXPECT_NE(info.out.find("seeds " + seeds), std::string::npos) << info.out;
}

TEST_F(IngestSeeds, TwoFilesOfOneSeedAreRefused) {
    // Other pixels (other sample counts, another scene version), one seed: the first samples of
    // the two are the same, and the content hash cannot see it.
    write("b_1.exr", 1, "seed=5");
    write("b_2.exr", 2, "seed=6");
    write("b_3.exr", 3, "seed=05 frame=1");
    Result r = mcstat("--ingest '" + path("b_*.exr") + "' -o " + path("b.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --ingest: " + path("b_1.exr") + " and " + path("b_3.exr") +
                         " are both renders of seed 5 (by their Note stamps): renders of one seed "
                         "share their samples, so they are not independent; ingest one of them, "
                         "or render another seed\n");
    EXPECT_FALSE(OIIO::Filesystem::exists(path("b.mcstat")));
    // A note naming two seeds says nothing it can be held to.
    write("c_1.exr", 1, "seed=1 seed=2");
    r = mcstat("--ingest '" + path("c_1.exr") + "' -o " + path("c.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --ingest: " + path("c_1.exr") +
                         ": its Note names two seeds (1 and 2): which one rendered it?\n");
    // Python and the library refuse the same.
    StatsImage img;
    IngestReport rep;
    std::string err;
    EXPECT_FALSE(ingestRenders({path("b_1.exr"), path("b_3.exr")}, IngestOptions(), img, rep, err));
    EXPECT_NE(err.find("are both renders of seed 5"), std::string::npos) << err;
}

TEST_F(IngestSeeds, ASeedPatternReadsTheNamesAndMustAgreeWithTheNote) {
    write("shot_s007_v2.exr", 1);
    write("shot_s008_v2.exr", 2);
    Result r = mcstat("--ingest:seed=shot_s{seed}_v2.exr '" + path("shot_s*.exr") + "' -o " +
                      path("s.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(seedsOf(path("s.mcstat")), "7,8");
    // A name the pattern does not fit is refused: the user said where every seed is.
    write("shot_final.exr", 3);
    r = mcstat("--ingest:seed=shot_s{seed}_v2.exr '" + path("shot_*.exr") + "' -o " +
               path("s2.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --ingest: " + path("shot_final.exr") +
                         ": its name 'shot_final.exr' does not match the seed pattern "
                         "'shot_s{seed}_v2.exr' ({seed}: the seed's digits)\n");
    // A renamed file lies about itself: its name and its Note disagree.
    write("n_3.exr", 3, "seed=3");
    write("n_9.exr", 4, "seed=4");
    r = mcstat("--ingest:seed=n_{seed}.exr '" + path("n_*.exr") + "' -o " + path("n.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --ingest: " + path("n_9.exr") +
                         ": its name says seed 9 (seed=n_{seed}.exr) but its Note says seed 4: "
                         "the file lies about itself (renamed, or stamped by hand?); fix the name "
                         "or the note\n");
    // Two names of one seed (leading zeros are not another seed).
    write("d_2.exr", 1);
    write("d_002.exr", 2);
    r = mcstat("--ingest:seed=d_{seed}.exr '" + path("d_*.exr") + "' -o " + path("d.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("are both renders of seed 2 (by their names)"), std::string::npos)
        << r.err;
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    // A pattern without {seed} is refused before any file is read.
    r = mcstat("--ingest:seed=d_N.exr '" + path("d_2.exr") + "' --info");
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err,
              "mcstat: --ingest: seed pattern 'd_N.exr' must hold {seed} once, where the file name "
              "has the seed's digits (e.g. seed=shot_s{seed}.exr)\n");
}

TEST_F(IngestSeeds, SeedPatternsWithFramesRunPerFrame) {
    // Renders of two frames with the seed in the name; {seed} is not a frame pattern, and the
    // frame's '#' in the seed pattern is the frame's number as in the other arguments.
    for (int f = 1; f <= 2; ++f)
        for (int s = 1; s <= 2; ++s)
            write(OIIO::Strutil::fmt::format("shot_s{}.{:04d}.exr", s + 10 * f, f), s + 3 * f);
    const Result r = mcstat("--ingest:seed='" + std::string("shot_s{seed}.#.exr") + "' '" +
                            path("shot_s*.#.exr") + "' -o '" + path("shot.#.mcstat") + "'");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(seedsOf(path("shot.0001.mcstat")), "11,12");
    EXPECT_EQ(seedsOf(path("shot.0002.mcstat")), "21,22");
}

TEST(SeedFromName, WhereTheDigitsAreAndWhatIsRefused) {
    std::string seed, problem;
    EXPECT_TRUE(seedFromName("renders/seed_007.exr", "seed_{seed}.exr", seed, problem));
    EXPECT_EQ(seed, "7");
    EXPECT_TRUE(seedFromName("/a/b/s12/beauty.0001.exr", "s{seed}/beauty.*.exr", seed, problem));
    EXPECT_EQ(seed, "12");
    EXPECT_TRUE(seedFromName("x/shot_v3_s44.exr", "*_s{seed}.exr", seed, problem));
    EXPECT_EQ(seed, "44");
    // The whole run of digits: '*' cannot take some of them.
    EXPECT_TRUE(seedFromName("r123.exr", "*{seed}.exr", seed, problem));
    EXPECT_EQ(seed, "123");
    // Two readings, no match, digits that overflow.
    EXPECT_FALSE(seedFromName("a1_b2.exr", "*{seed}*.exr", seed, problem));
    EXPECT_NE(problem.find("reads its name 'a1_b2.exr' two ways (seeds 1 or 2)"), std::string::npos)
        << problem;
    EXPECT_FALSE(seedFromName("seed_.exr", "seed_{seed}.exr", seed, problem));
    EXPECT_NE(problem.find("does not match the seed pattern"), std::string::npos) << problem;
    EXPECT_FALSE(seedFromName("s/b.exr", "s{seed}/b.exr", seed, problem));
    EXPECT_FALSE(
        seedFromName("seed_99999999999999999999999.exr", "seed_{seed}.exr", seed, problem));
    EXPECT_NE(problem.find("does not fit 64 bits"), std::string::npos) << problem;
    // The pattern itself.
    EXPECT_TRUE(checkSeedPattern("seed_{seed}.exr", problem));
    EXPECT_FALSE(checkSeedPattern("seed_#.exr", problem));
    EXPECT_FALSE(checkSeedPattern("{seed}_{seed}.exr", problem));
    EXPECT_FALSE(checkSeedPattern("/abs/{seed}.exr", problem));
}

}  // namespace
}  // namespace mcstat::testing
