// The compact file on disk (FORMAT.md "Version 6" to "Version 8"): round trip through the writer
// and the streaming reader, AOVs in the deep part, one-buffer pixels' means in part beauty, older
// versions, the header check's refusals.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
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
    // Version 8: part moments holds the count and the spread, not the mean (part beauty's) nor
    // the per-sample variance (version 7), and a one-buffer pixel's mean is beauty's.
    ASSERT_EQ(small.header.formatVersion, kStatsFormatVersionMeansInBeauty);
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

/// The bytes of `path` with every part's mcstat:formatVersion changed from `from` to `to`.
std::vector<unsigned char> withVersion(const std::string& path, int from, int to) {
    std::vector<unsigned char> bytes = test::readBytes(path);
    const std::string key = std::string("mcstat:formatVersion") + '\0' + "int" + '\0';
    const std::string value = std::string("\x04\0\0\0", 4) + char(from) + std::string(3, '\0');
    std::string text(bytes.begin(), bytes.end());
    int changed = 0;
    for (size_t at = text.find(key + value); at != std::string::npos;
         at = text.find(key + value, at + 1)) {
        bytes[at + key.size() + 4] = static_cast<unsigned char>(to);
        ++changed;
    }
    EXPECT_EQ(changed, 4) << "one attribute per part";
    return bytes;
}

TEST(CompactFile, AOneBufferPixelsMeanIsStoredOnceInPartBeauty) {
    test::ScratchDir dir;
    const StatsImage small = compacted(sample(13, 9, 9));
    size_t one = 0;
    for (size_t p = 0; p < small.pixelCount(); ++p) {
        if (small.buffersOf(p) != 1) continue;
        ++one;
        // What stock tools show there is G-MoN's value, the buffer's mean, to the bit.
        const float* m = small.bufferMean.data() + 3 * small.bufferBegin(p);
        EXPECT_EQ(0, std::memcmp(m, small.beauty.data() + 3 * p, 3 * sizeof(float))) << p;
    }
    ASSERT_GT(one, 0u);
    std::string err;
    const std::string path = dir.file("v8.mcstat");
    ASSERT_TRUE(writeStatsFile(path, small, err)) << err;
    // The deep sample of such a pixel holds 0: read as version 7, which takes it as it is.
    test::writeBytes(dir.file("as7.mcstat"), withVersion(path, 8, 7));
    StatsImage raw;
    ASSERT_TRUE(readStatsFile(dir.file("as7.mcstat"), raw, err)) << err;
    for (size_t p = 0; p < raw.pixelCount(); ++p) {
        const float* m = raw.bufferMean.data() + 3 * raw.bufferBegin(p);
        if (raw.buffersOf(p) == 1)
            EXPECT_TRUE(m[0] == 0.f && m[1] == 0.f && m[2] == 0.f) << p;
        else
            EXPECT_EQ(0, std::memcmp(m, small.bufferMean.data() + 3 * small.bufferBegin(p),
                                     9 * 3 * sizeof(float)))
                << p;
    }
    EXPECT_EQ(raw.bufferCount, small.bufferCount);
    EXPECT_EQ(raw.aov, small.aov);
    // The buffers alone, by blocks: beauty comes along, the means are the image's.
    StatsFileReader reader;
    ASSERT_TRUE(reader.open(path, err)) << err;
    StatsImage block;
    ASSERT_TRUE(reader.read(3, 4, kStatsPartBuffers, block, err)) << err;
    const size_t first = 3 * size_t(small.header.width);
    for (size_t p = 0; p < block.pixelCount(); ++p)
        EXPECT_EQ(0, std::memcmp(block.bufferMean.data() + 3 * block.bufferBegin(p),
                                 small.bufferMean.data() + 3 * small.bufferBegin(first + p),
                                 size_t(block.buffersOf(p)) * 3 * sizeof(float)))
            << p;
}

TEST(CompactFile, Version7FilesWithTheMeansInTheDeepPartStillRead) {
    // What --compact wrote before version 8: a one-buffer pixel's mean in its deep sample, part
    // beauty the full file's plain mean. It reads, and writes back, as it is.
    test::ScratchDir dir;
    StatsImage v7 = compacted(sample(13, 9, 9));
    v7.header.formatVersion = kStatsFormatVersionSlimMoments;
    for (size_t p = 0; p < v7.pixelCount(); ++p)
        if (v7.buffersOf(p) == 1) v7.beauty[3 * p] = 0.25f;  // not the buffer's: beauty is not read
    std::string err;
    const std::string path = dir.file("v7.mcstat");
    ASSERT_TRUE(writeStatsFile(path, v7, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    EXPECT_EQ(back.header.formatVersion, kStatsFormatVersionSlimMoments);
    expectSame(v7, back);
    // Version 8 is smaller: the means of the 100 pixels of 117 without buffers are stored once.
    StatsImage v8 = compacted(sample(13, 9, 9));
    ASSERT_TRUE(writeStatsFile(dir.file("v8.mcstat"), v8, err)) << err;
    EXPECT_LT(test::readBytes(dir.file("v8.mcstat")).size(), test::readBytes(path).size());
}

TEST(CompactFile, Version8MeansInTwoPlacesAreRefused) {
    test::ScratchDir dir;
    StatsImage small = compacted(sample(13, 9, 9));
    size_t p = 0;
    while (small.buffersOf(p) != 1) ++p;
    // Written: a beauty that is not the one buffer's mean.
    StatsImage bad = small;
    bad.beauty[3 * p + 1] = std::nextafter(bad.beauty[3 * p + 1], 2.f);
    std::string err;
    EXPECT_FALSE(writeStatsFile(dir.file("bad.mcstat"), bad, err));
    EXPECT_TRUE(test::contains(err, "stores in part 'beauty', but that part holds")) << err;
    EXPECT_FALSE(std::filesystem::exists(dir.file("bad.mcstat")));
    // Read: a deep sample that holds a mean where version 8 keeps 0 (a version-7 file whose
    // version attribute says 8).
    small.header.formatVersion = kStatsFormatVersionSlimMoments;
    ASSERT_TRUE(writeStatsFile(dir.file("v7.mcstat"), small, err)) << err;
    test::writeBytes(dir.file("as8.mcstat"), withVersion(dir.file("v7.mcstat"), 7, 8));
    StatsImage back;
    EXPECT_FALSE(readStatsFile(dir.file("as8.mcstat"), back, err));
    EXPECT_TRUE(test::contains(err, "as8.mcstat: pixel (")) << err;
    EXPECT_TRUE(test::contains(err, "which a compact file of format 8 keeps in part 'beauty'"))
        << err;
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
