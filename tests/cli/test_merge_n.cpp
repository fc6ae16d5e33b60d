// `--merge` of N files (issue 23): one command merges every statistics file on the stack by a
// fixed tree over the inputs sorted by seed, so any input order gives the same bytes, and the same
// tree run as separate commands (a farm's jobs) gives the same bytes too. Checked on renders of
// the fixture renderer against the library's one-pass merge and the FORMAT.md rounding bound.
#include <OpenImageIO/filesystem.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <random>

#include "cli_support.h"
#include "mcstat/exr-deep/stats_file.h"

namespace {

using mcstat::StatsImage;
using mcstat::testing::Result;
using mcstat::testing::slurp;

class MergeN : public mcstat::testing::CliFixture {
  protected:
    static constexpr int kSeeds = 7;
    void SetUp() override {
        CliFixture::SetUp();
        for (int s = 1; s <= kSeeds; ++s) {
            const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                                    " --quiet --scene default --res 24 16 --spp 6 --M 4 --seed " +
                                    std::to_string(s) + " -o " + seedFile(s);
            ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
        }
    }
    std::string seedFile(int s) { return path("s" + std::to_string(s) + ".mcstat"); }
    std::string files(const std::vector<int>& seeds) {
        std::string out;
        for (int s : seeds) out += seedFile(s) + " ";
        return out;
    }
    StatsImage read(const std::string& file) {
        StatsImage img;
        std::string err;
        EXPECT_TRUE(mcstat::readStatsFile(file, img, err)) << err;
        return img;
    }
};

TEST_F(MergeN, AnyInputOrderGivesTheSameBytes) {
    std::vector<int> order{1, 2, 3, 4, 5, 6, 7};
    ASSERT_EQ(mcstat(files(order) + "--merge -o " + path("ref.mcstat")).code, 0);
    const std::string ref = slurp(path("ref.mcstat"));
    std::mt19937 rng(5);
    for (int trial = 0; trial < 3; ++trial) {
        std::shuffle(order.begin(), order.end(), rng);
        const Result r = mcstat(files(order) + "--merge -o " + path("shuffled.mcstat"));
        ASSERT_EQ(r.code, 0) << r.err;
        EXPECT_TRUE(slurp(path("shuffled.mcstat")) == ref) << "order " << files(order);
    }
    // One node over all seven (fan-in 8): the library's one-pass merge of the sorted inputs.
    std::vector<StatsImage> in;
    for (int s = 1; s <= kSeeds; ++s) in.push_back(read(seedFile(s)));
    std::vector<const StatsImage*> ptrs;
    for (const StatsImage& i : in) ptrs.push_back(&i);
    StatsImage expected, got = read(path("ref.mcstat"));
    std::string err;
    ASSERT_TRUE(mcstat::mergeStats(ptrs, expected, err, 2)) << err;
    EXPECT_EQ(got.bufferMean, expected.bufferMean);
    EXPECT_EQ(got.bufferCount, expected.bufferCount);
    EXPECT_EQ(got.mean, expected.mean);
    EXPECT_EQ(got.variance, expected.variance);
    EXPECT_EQ(got.header.seeds, "1,2,3,4,5,6,7");
    EXPECT_EQ(got.header.spp, 7 * 6);
    // Hand-computed at one buffer: sum n_j m_j / sum n_j over the seven files, in double.
    const size_t k = (5 * 24 + 9) * 4 + 2;
    double sum = 0, n = 0;
    for (const StatsImage& i : in) {
        sum += double(i.bufferCount[k]) * double(i.bufferMean[k * 3 + 1]);
        n += i.bufferCount[k];
    }
    EXPECT_EQ(got.bufferCount[k], float(n));
    EXPECT_EQ(got.bufferMean[k * 3 + 1], float(sum / n));
}

TEST_F(MergeN, TheTreeRunAsSeparateCommandsGivesTheSameBytes) {
    // Fan-in 2 over 7 sorted inputs: {1,2} {3,4} {5,6} 7 -> {12,34} {56,7} -> one.
    Result r = mcstat(files({6, 3, 7, 1, 5, 2, 4}) + "--merge:fanin=2 -o " + path("one.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    const auto job = [&](const std::string& inputs, const std::string& out) {
        const Result j = mcstat(inputs + " --merge:fanin=2 -o " + path(out));
        ASSERT_EQ(j.code, 0) << j.err;
    };
    job(files({1, 2}), "g12.mcstat");
    job(files({4, 3}), "g34.mcstat");
    job(files({5, 6}), "g56.mcstat");
    job(path("g34.mcstat") + " " + path("g12.mcstat"), "g1234.mcstat");
    job(path("g56.mcstat") + " " + seedFile(7), "g567.mcstat");
    job(path("g567.mcstat") + " " + path("g1234.mcstat"), "jobs.mcstat");
    EXPECT_TRUE(slurp(path("jobs.mcstat")) == slurp(path("one.mcstat")));
    // Another fan-in is another tree: the same counts, means within FORMAT.md's rounding bound
    // ((k + 2) 2^-24 of the largest value after k = 3 levels), not the same bits.
    ASSERT_EQ(mcstat(files({1, 2, 3, 4, 5, 6, 7}) + "--merge -o " + path("flat.mcstat")).code, 0);
    const StatsImage tree = read(path("one.mcstat")), flat = read(path("flat.mcstat"));
    EXPECT_EQ(tree.bufferCount, flat.bufferCount);
    EXPECT_EQ(tree.count, flat.count);
    size_t differ = 0;
    for (size_t i = 0; i < flat.bufferMean.size(); ++i) {
        const double scale = std::max(std::fabs(double(flat.bufferMean[i])), 1e-30);
        EXPECT_LE(std::fabs(double(tree.bufferMean[i]) - flat.bufferMean[i]),
                  5 * FLT_EPSILON / 2 * scale)
            << i;
        differ += tree.bufferMean[i] != flat.bufferMean[i];
    }
    RecordProperty("buffer_means_differing_between_trees", std::to_string(differ));
}

TEST_F(MergeN, SixtyFourFilesGiveTheSameBytesInAnyOrder) {
    // Issue 23's case: 64 seeds (tiny renders), the default fan-in 8: a tree of depth 2.
    std::vector<std::string> names;
    for (int s = 101; s <= 164; ++s) {
        names.push_back(path("t" + std::to_string(s) + ".mcstat"));
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                                " --quiet --threads 1 --scene default --res 12 8 --spp 2 --M 2 "
                                "--seed " +
                                std::to_string(s) + " -o " + names.back();
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
    }
    const auto joined = [](const std::vector<std::string>& v) {
        std::string out;
        for (const std::string& n : v) out += n + " ";
        return out;
    };
    ASSERT_EQ(mcstat(joined(names) + "--merge -o " + path("sorted.mcstat")).code, 0);
    std::reverse(names.begin(), names.end());
    ASSERT_EQ(mcstat(joined(names) + "--merge -o " + path("reversed.mcstat")).code, 0);
    std::shuffle(names.begin(), names.end(), std::mt19937(64));
    ASSERT_EQ(mcstat(joined(names) + "--merge -o " + path("shuffled.mcstat")).code, 0);
    const std::string sorted = slurp(path("sorted.mcstat"));
    EXPECT_TRUE(slurp(path("reversed.mcstat")) == sorted);
    EXPECT_TRUE(slurp(path("shuffled.mcstat")) == sorted);
    const StatsImage m = read(path("sorted.mcstat"));
    EXPECT_EQ(m.header.spp, 128);
    EXPECT_EQ(m.header.seeds.substr(0, 8), "101,102,");
    for (float n : m.count) EXPECT_EQ(n, 128.f);
}

TEST_F(MergeN, RefusalsNameTheFiles) {
    // An image on the stack: merging "everything" would be a mistake; :n= merges the top n.
    std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                      " --quiet --scene default --res 24 16 --spp 4 --reference -o " +
                      path("ref.exr");
    ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0);
    Result r = mcstat(path("ref.exr") + " " + files({1, 2, 3}) + "--merge -o " + path("x.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("ref.exr is an image (merge only the top N with --merge:n=N)"),
              std::string::npos)
        << r.err;
    r = mcstat(path("ref.exr") + " " + files({1, 2, 3}) + "--merge:n=3 -o " + path("x.mcstat") +
               " --pop --info");
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(read(path("x.mcstat")).header.seeds, "1,2,3");
    // The same seed in two different files (a task rendered twice under two names).
    ASSERT_TRUE(OIIO::Filesystem::copy(seedFile(2), path("again.mcstat")));
    r = mcstat(files({1, 2, 3}) + path("again.mcstat") + " --merge");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("seed 2 is in both " + seedFile(2) + " and " + path("again.mcstat")),
              std::string::npos)
        << r.err;
    r = mcstat(files({1, 2, 1}) + "--merge");
    EXPECT_NE(r.err.find(seedFile(1) + " is given twice"), std::string::npos) << r.err;
    r = mcstat(files({1, 2}) + "--merge:fanin=1");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("fanin"), std::string::npos) << r.err;
    r = mcstat(files({1}) + "--merge");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("needs 2 images on the stack"), std::string::npos) << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("y.mcstat")));
}

}  // namespace
