// Write -> read gives back every array bit for bit and the same header; header-only reads;
// deterministic bytes, independent of OpenEXR's thread count.
#include <OpenEXR/ImfThreading.h>
#include <gtest/gtest.h>

#include <cstring>

#include "mcstat/exr-deep/stats_file.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

void expectHeaderEq(const StatsHeader& a, const StatsHeader& b) {
    EXPECT_EQ(a.formatVersion, b.formatVersion);
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.height, b.height);
    EXPECT_EQ(a.originX, b.originX);
    EXPECT_EQ(a.originY, b.originY);
    EXPECT_EQ(a.M, b.M);
    EXPECT_EQ(a.spp, b.spp);
    EXPECT_EQ(a.assignment, b.assignment);
    EXPECT_EQ(a.renderer, b.renderer);
    EXPECT_EQ(a.colorSpace, b.colorSpace);
    EXPECT_EQ(a.seeds, b.seeds);
}

void expectBitEqual(const std::vector<float>& a, const std::vector<float>& b, const char* what) {
    ASSERT_EQ(a.size(), b.size()) << what;
    EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(float))) << what;
}

void expectImagesBitEqual(const StatsImage& a, const StatsImage& b) {
    expectHeaderEq(a.header, b.header);
    expectBitEqual(a.beauty, b.beauty, "beauty");
    expectBitEqual(a.bufferMean, b.bufferMean, "bufferMean");
    expectBitEqual(a.bufferCount, b.bufferCount, "bufferCount");
    expectBitEqual(a.count, b.count, "count");
    expectBitEqual(a.mean, b.mean, "mean");
    expectBitEqual(a.variance, b.variance, "variance");
    expectBitEqual(a.normal, b.normal, "normal");
    expectBitEqual(a.position, b.position, "position");
    expectBitEqual(a.albedo, b.albedo, "albedo");
    expectBitEqual(a.depth, b.depth, "depth");
    expectBitEqual(a.coverage, b.coverage, "coverage");
}

/// Restores OpenEXR's global thread count.
struct ThreadCountGuard {
    int saved = Imf::globalThreadCount();
    ~ThreadCountGuard() { Imf::setGlobalThreadCount(saved); }
};

struct Shape {
    int width, height, M, originX, originY;
};

class RoundTrip : public testing::TestWithParam<Shape> {};

TEST_P(RoundTrip, EveryArrayBitEqualAndHeaderEqual) {
    const Shape s = GetParam();
    // spp varies per pixel, including 0 (empty buffers, depth +inf) and fewer samples than M.
    StatsImage img = renderImage(
        s.width, s.height, s.M, 11, [](int x, int y) { return (x * 7 + y * 3) % 11; }, s.originX,
        s.originY);
    img.header.colorSpace = "ACEScg";
    img.header.renderer = "unit test \"renderer\" ü";
    ScratchDir dir;
    const std::string path = dir.file("a.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    expectImagesBitEqual(img, back);

    StatsHeader hdr;
    ASSERT_TRUE(readStatsHeader(path, hdr, err)) << err;
    expectHeaderEq(img.header, hdr);
}

std::string shapeName(const testing::TestParamInfo<Shape>& info) {
    const Shape& s = info.param;
    const auto num = [](int v) { return v < 0 ? "m" + std::to_string(-v) : std::to_string(v); };
    return num(s.width) + "x" + num(s.height) + "_M" + num(s.M) + "_at_" + num(s.originX) + "_" +
           num(s.originY);
}

INSTANTIATE_TEST_SUITE_P(Shapes, RoundTrip,
                         testing::Values(Shape{1, 1, 1, 0, 0}, Shape{13, 7, 4, 0, 0},
                                         Shape{9, 20, 3, -5, 17}, Shape{5, 33, 16, 2, -40},
                                         Shape{3, 2, 999, 0, 0}),
                         shapeName);

TEST(RoundTripSpecial, EmptyPixelsHaveInfiniteDepthAndZeroMeans) {
    StatsImage img = renderImage(4, 3, 4, 5, [](int x, int) { return x == 0 ? 0 : 2; });
    ScratchDir dir;
    std::string err;
    ASSERT_TRUE(writeStatsFile(dir.file("e.mcstat"), img, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(dir.file("e.mcstat"), back, err)) << err;
    EXPECT_EQ(back.count[0], 0.f);
    EXPECT_TRUE(std::isinf(back.depth[0]) && back.depth[0] > 0);
    EXPECT_EQ(back.bufferMean[0], 0.f);
    EXPECT_EQ(back.count[1], 2.f);
    // Two samples over four buffers: buffers 0 and 1 hold one each, 2 and 3 are empty.
    EXPECT_EQ(back.bufferCount[1 * 4 + 0], 1.f);
    EXPECT_EQ(back.bufferCount[1 * 4 + 1], 1.f);
    EXPECT_EQ(back.bufferCount[1 * 4 + 2], 0.f);
    EXPECT_EQ(back.bufferMean[(1 * 4 + 3) * 3], 0.f);
}

TEST(RoundTripSpecial, BytesAreDeterministicAndIndependentOfThreadCount) {
    ThreadCountGuard guard;
    const StatsImage img = renderImage(31, 40, 5, 3, [](int x, int y) { return 1 + (x ^ y) % 9; });
    ScratchDir dir;
    std::string err;
    Imf::setGlobalThreadCount(0);
    ASSERT_TRUE(writeStatsFile(dir.file("t0.mcstat"), img, err)) << err;
    ASSERT_TRUE(writeStatsFile(dir.file("t0b.mcstat"), img, err)) << err;
    Imf::setGlobalThreadCount(4);
    ASSERT_TRUE(writeStatsFile(dir.file("t4.mcstat"), img, err)) << err;
    const auto b0 = readBytes(dir.file("t0.mcstat"));
    EXPECT_EQ(b0, readBytes(dir.file("t0b.mcstat")));
    EXPECT_EQ(b0, readBytes(dir.file("t4.mcstat")));

    StatsImage r4, r0;
    ASSERT_TRUE(readStatsFile(dir.file("t0.mcstat"), r4, err)) << err;  // 4 threads
    Imf::setGlobalThreadCount(0);
    ASSERT_TRUE(readStatsFile(dir.file("t4.mcstat"), r0, err)) << err;
    expectImagesBitEqual(img, r4);
    expectImagesBitEqual(img, r0);
}

TEST(RoundTripSpecial, OverwritesAnExistingFile) {
    ScratchDir dir;
    const std::string path = dir.file("o.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, renderImage(2, 2, 1, 1, [](int, int) { return 1; }), err));
    const StatsImage img2 = renderImage(3, 5, 2, 2, [](int, int) { return 3; });
    ASSERT_TRUE(writeStatsFile(path, img2, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    expectImagesBitEqual(img2, back);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"o.mcstat"});
}

TEST(ReadHeader, ReturnsHeaderWithoutPixelsAndHonoursLimits) {
    const StatsImage img = renderImage(
        6, 4, 3, 9, [](int, int) { return 5; }, 10, 20);
    ScratchDir dir;
    const std::string path = dir.file("h.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    StatsHeader hdr;
    ASSERT_TRUE(readStatsHeader(path, hdr, err)) << err;
    expectHeaderEq(img.header, hdr);

    ReadLimits small;
    small.maxPixels = 23;  // 6 x 4 = 24
    EXPECT_FALSE(readStatsHeader(path, hdr, err, small));
    EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
    EXPECT_TRUE(contains(err, "exceeds the limit of 23 pixels")) << err;
    small.maxPixels = 24;
    EXPECT_TRUE(readStatsHeader(path, hdr, err, small)) << err;

    ReadLimits bytes;
    bytes.maxBytes = 24 * (21 + 4 * 3) * 4 - 1;  // one byte short of what the pixels need
    StatsImage out;
    EXPECT_FALSE(readStatsFile(path, out, err, bytes));
    EXPECT_TRUE(contains(err, "bytes")) << err;
    EXPECT_TRUE(out.count.empty());
    bytes.maxBytes += 1;
    EXPECT_TRUE(readStatsFile(path, out, err, bytes)) << err;

    ReadLimits buffers;
    buffers.maxBuffers = 2;
    EXPECT_FALSE(readStatsHeader(path, hdr, err, buffers));
    EXPECT_TRUE(contains(err, "mcstat:M = 3 out of range 1..2")) << err;
}

}  // namespace
}  // namespace mcstat::test
