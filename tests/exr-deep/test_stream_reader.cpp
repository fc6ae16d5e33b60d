// StatsFileReader on damaged files: a block is validated when it is read, so a bad value in a late
// block fails that block's read with a message naming the file and the pixel, after earlier blocks
// read fine. (Blocks equal to the whole read, block heights and the streamed operations:
// tests/image/test_stream.cpp.)
#include <gtest/gtest.h>

#include "mcstat/exr-deep/stats_file.h"
#include "raw_exr.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

TEST(StreamReader, ADamagedCountInALateBlockNamesItsPixel) {
    ScratchDir dir;
    StatsImage img = renderImage(6, 40, 3, 9, [](int x, int y) { return 2 + (x + y) % 4; });
    std::vector<RawPart> parts = rawPartsFrom(img);
    // Pixel (2, 33): its moments count no longer matches its buffers' sum.
    for (RawPart& p : parts)
        if (p.header.name() == std::string("moments")) p.values["count"][33 * 6 + 2] += 1.f;
    const std::string path = dir.file("bad.mcstat");
    writeRaw(path, parts);
    StatsFileReader reader;
    std::string err;
    ASSERT_TRUE(reader.open(path, err)) << err;
    StatsImage block;
    ASSERT_TRUE(reader.read(0, 32, kStatsAllParts, block, err)) << err;
    EXPECT_FALSE(reader.read(32, 8, kStatsAllParts, block, err));
    EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
    EXPECT_NE(err.find("pixel (2, 33)"), std::string::npos) << err;
    // The sum is a cross-part check: each part alone is fine.
    EXPECT_TRUE(reader.read(32, 8, kStatsPartBuffers, block, err)) << err;
    EXPECT_TRUE(reader.read(32, 8, kStatsPartMoments, block, err)) << err;
    // A count that is bad on its own is refused with the buffers alone.
    for (RawPart& p : parts)
        if (p.header.name() == std::string("buffers")) p.values["b001.count"][35 * 6 + 4] = -2.f;
    writeRaw(path, parts);
    ASSERT_TRUE(reader.open(path, err)) << err;
    EXPECT_FALSE(reader.read(32, 8, kStatsPartBuffers, block, err));
    EXPECT_NE(err.find("pixel (4, 35): buffer 1 count is negative"), std::string::npos) << err;
    // Whole-file reads still see everything.
    StatsImage whole;
    EXPECT_FALSE(readStatsFile(path, whole, err));
}

}  // namespace
}  // namespace mcstat::test
