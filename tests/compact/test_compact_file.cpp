// The compact file on disk (FORMAT.md "Version 6"): round trip through the writer and the
// streaming reader, AOVs in the deep part, the header check's refusals.
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "mcstat/compact/compact.h"
#include "test_support.h"

namespace mcstat {
namespace {

/// A full file's image: W x H, M buffers, two AOVs, a firefly every 7th pixel.
StatsImage sample(int W, int H, int M) {
    StatsImage img;
    img.header.width = W;
    img.header.height = H;
    img.header.M = M;
    img.header.aovs = {{"A", AovClass::Alpha, ""}, {"IndexOB", AovClass::Id, "extra"}};
    img.header.formatVersion = requiredFormatVersion(img.header);
    std::string err;
    EXPECT_TRUE(img.allocate(err)) << err;
    std::mt19937 rng(1);
    std::normal_distribution<float> noise(0.5f, 0.01f);
    for (size_t p = 0; p < img.pixelCount(); ++p) {
        double n = 0, s[3] = {0, 0, 0};
        for (int j = 0; j < M; ++j) {
            const size_t k = p * size_t(M) + size_t(j);
            for (int c = 0; c < 3; ++c)
                img.bufferMean[k * 3 + c] = p % 7 == 0 && j == 1 ? 100.f : noise(rng);
            img.bufferCount[k] = 4;
            img.aov[k * 2] = 1.f;
            img.aov[k * 2 + 1] = float(p % 3);
            n += 4;
            for (int c = 0; c < 3; ++c) s[c] += 4.0 * img.bufferMean[k * 3 + c];
        }
        img.count[p] = float(n);
        for (int c = 0; c < 3; ++c) img.beauty[p * 3 + c] = img.mean[p * 3 + c] = float(s[c] / n);
    }
    return img;
}

StatsImage compacted(const StatsImage& full) {
    CompactRule rule;
    rule.luma = {0.2126, 0.7152, 0.0722};
    StatsImage small;
    std::string err;
    EXPECT_TRUE(compactStats(full, rule, small, err, 2)) << err;
    return small;
}

void expectSame(const StatsImage& a, const StatsImage& b) {
    EXPECT_EQ(a.header.compact, b.header.compact);
    EXPECT_EQ(a.header.compactRule, b.header.compactRule);
    EXPECT_EQ(a.header.aovs, b.header.aovs);
    EXPECT_EQ(a.bufferOffset, b.bufferOffset);
    EXPECT_EQ(a.bufferMean, b.bufferMean);
    EXPECT_EQ(a.bufferCount, b.bufferCount);
    EXPECT_EQ(a.aov, b.aov);
    ASSERT_EQ(a.spread.size(), b.spread.size());
    EXPECT_EQ(0, std::memcmp(a.spread.data(), b.spread.data(), a.spread.size() * sizeof(float)));
    EXPECT_EQ(a.mean, b.mean);
    EXPECT_EQ(a.variance, b.variance);
    EXPECT_EQ(a.count, b.count);
    EXPECT_EQ(a.beauty, b.beauty);
}

TEST(CompactFile, RoundTripsWithAovsInTheDeepPart) {
    test::ScratchDir dir;
    const StatsImage small = compacted(sample(13, 9, 9));
    // Version 7: part moments holds the count and the spread, not the mean (part beauty's) nor
    // the per-sample variance.
    ASSERT_EQ(small.header.formatVersion, kStatsFormatVersionSlimMoments);
    EXPECT_TRUE(small.mean.empty());
    EXPECT_TRUE(small.variance.empty());
    EXPECT_EQ(small.count.size(), small.pixelCount());
    size_t kept = 0;
    for (size_t p = 0; p < small.pixelCount(); ++p) kept += small.buffersOf(p) == 9;
    EXPECT_EQ(kept, (small.pixelCount() + 6) / 7) << "exactly the firefly pixels keep buffers";
    std::string err;
    const std::string path = dir.file("small.mcstat");
    ASSERT_TRUE(writeStatsFile(path, small, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    expectSame(small, back);
    // By blocks of 2 rows, AOVs asked for without the buffers (they live in the deep part).
    StatsFileReader reader;
    ASSERT_TRUE(reader.open(path, err)) << err;
    StatsImage block;
    ASSERT_TRUE(reader.read(4, 2, kStatsPartAovs, block, err)) << err;
    EXPECT_EQ(block.aov.size(), block.bufferCount.size() * 2);
    StatsImage check;
    StatsCheckReport report;
    EXPECT_TRUE(checkStatsFile(path, report, err)) << err;
    EXPECT_EQ(report.subBuffers, int64_t(small.bufferCount.size()));
}

TEST(CompactFile, Version6FilesWithTheMomentsMeanAndVarianceStillRead) {
    // What --compact wrote before version 7: part moments with count, mean.*, variance.* and the
    // spread. It reads, and writes back, as it is.
    test::ScratchDir dir;
    StatsImage v6 = compacted(sample(7, 5, 5));
    v6.header.formatVersion = kStatsFormatVersionCompact;
    v6.mean = v6.beauty;
    v6.variance.assign(v6.pixelCount() * 3, 0.f);
    for (size_t i = 0; i < v6.variance.size(); ++i) v6.variance[i] = 0.125f * float(i % 11);
    std::string err;
    const std::string path = dir.file("v6.mcstat");
    ASSERT_TRUE(writeStatsFile(path, v6, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    EXPECT_EQ(back.header.formatVersion, kStatsFormatVersionCompact);
    expectSame(v6, back);
    EXPECT_FALSE(back.variance.empty());
    // The same image as version 7 is smaller by those six channels and reads without them.
    StatsImage v7 = v6;
    v7.header.formatVersion = kStatsFormatVersionSlimMoments;
    ASSERT_TRUE(writeStatsFile(dir.file("v7.mcstat"), v7, err)) << err;
    ASSERT_TRUE(readStatsFile(dir.file("v7.mcstat"), back, err)) << err;
    EXPECT_TRUE(back.mean.empty());
    EXPECT_TRUE(back.variance.empty());
    EXPECT_EQ(back.bufferMean, v6.bufferMean);
    EXPECT_LT(test::readBytes(dir.file("v7.mcstat")).size(), test::readBytes(path).size());
}

TEST(CompactFile, WrittenByBlocksGivesTheSameBytes) {
    test::ScratchDir dir;
    const StatsImage small = compacted(sample(11, 20, 5));
    std::string err;
    ASSERT_TRUE(writeStatsFile(dir.file("whole.mcstat"), small, err)) << err;
    test::writeByBlocks(dir.file("blocks.mcstat"), small, 3, 2);
    EXPECT_EQ(test::readBytes(dir.file("whole.mcstat")),
              test::readBytes(dir.file("blocks.mcstat")));
}

TEST(CompactFile, AnImageThatBreaksTheLayoutIsNotWritten) {
    test::ScratchDir dir;
    StatsImage small = compacted(sample(4, 2, 5));
    std::string err;
    // A pixel with 3 of M = 5 buffers: adaptive M may, a compact file may not.
    std::vector<uint32_t> m(small.pixelCount(), 1);
    m[0] = 3;
    StatsImage bad;
    bad.header = small.header;
    ASSERT_TRUE(bad.allocateAdaptive(m, err)) << err;
    bad.bufferCount[0] = bad.bufferCount[1] = bad.bufferCount[2] = 0;
    EXPECT_FALSE(writeStatsFile(dir.file("bad.mcstat"), bad, err));
    EXPECT_TRUE(test::contains(err, "neither 1 nor M = 5")) << err;
    EXPECT_FALSE(std::filesystem::exists(dir.file("bad.mcstat")));
    // A compact header without the adaptive layout.
    StatsImage flat = sample(4, 2, 5);
    flat.header.compact = true;
    flat.header.compactRule = "gmon";
    flat.header.formatVersion = kStatsFormatVersionCompact;
    EXPECT_FALSE(writeStatsFile(dir.file("flat.mcstat"), flat, err));
    EXPECT_TRUE(test::contains(err, "adaptive layout")) << err;
}

TEST(CompactFile, TheRuleIsInTheHeaderAndInfo) {
    const StatsImage small = compacted(sample(3, 3, 5));
    EXPECT_TRUE(test::contains(small.header.compactRule, "gmon luma=0.2126,0.7152,0.0722 "))
        << small.header.compactRule;
    bool said = false;
    for (const std::string& line : describeStatsHeader(small.header))
        said = said || test::contains(line, "compact");
    EXPECT_TRUE(said);
}

}  // namespace
}  // namespace mcstat
