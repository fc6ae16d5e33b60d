// StatsImage::allocate and validateStats on in-memory images.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "mcstat/exr-deep/stats_file.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

TEST(Allocate, SizesZeroFillAndInfiniteDepth) {
    StatsImage img;
    img.header.width = 5;
    img.header.height = 3;
    img.header.M = 7;
    std::string err;
    ASSERT_TRUE(img.allocate(err)) << err;
    EXPECT_EQ(img.pixelCount(), 15u);
    EXPECT_EQ(img.beauty.size(), 45u);
    EXPECT_EQ(img.bufferMean.size(), 15u * 7 * 3);
    EXPECT_EQ(img.bufferCount.size(), 15u * 7);
    EXPECT_EQ(img.count.size(), 15u);
    EXPECT_EQ(img.mean.size(), 45u);
    EXPECT_EQ(img.variance.size(), 45u);
    EXPECT_EQ(img.normal.size(), 45u);
    EXPECT_EQ(img.position.size(), 45u);
    EXPECT_EQ(img.albedo.size(), 45u);
    EXPECT_EQ(img.depth.size(), 15u);
    EXPECT_EQ(img.coverage.size(), 15u);
    for (float d : img.depth) EXPECT_TRUE(std::isinf(d) && d > 0);
    for (float v : img.bufferMean) EXPECT_EQ(v, 0.f);
    EXPECT_TRUE(validateStats(img, "fresh", err)) << err;
}

TEST(Allocate, RejectsAbsurdSizesAndLeavesImageUntouched) {
    StatsImage img;
    img.header.width = 2;
    img.header.height = 2;
    std::string err;
    ASSERT_TRUE(img.allocate(err));
    const StatsImage before = img;
    for (auto [w, h, M] :
         {std::tuple{0, 5, 1}, std::tuple{5, -1, 1}, std::tuple{4, 4, 0}, std::tuple{4, 4, 1000}}) {
        img.header.width = w;
        img.header.height = h;
        img.header.M = M;
        EXPECT_FALSE(img.allocate(err)) << w << "x" << h << " M=" << M;
        EXPECT_FALSE(err.empty());
        EXPECT_EQ(img.count.size(), before.count.size());
        EXPECT_EQ(img.bufferCount.size(), before.bufferCount.size());
    }
    // 2^31-1 squared pixels times 4017 floats: too large for memory, must fail cleanly.
    img.header.width = std::numeric_limits<int>::max();
    img.header.height = std::numeric_limits<int>::max();
    img.header.M = 999;
    EXPECT_FALSE(img.allocate(err));
    EXPECT_EQ(img.count.size(), before.count.size());
}

class ValidateCounts : public testing::Test {
  protected:
    void SetUp() override {
        img = renderImage(
            4, 3, 2, 1, [](int, int) { return 3; }, 100, 200);
        std::string err;
        ASSERT_TRUE(validateStats(img, "img", err)) << err;
    }
    std::string check() {
        std::string err;
        EXPECT_FALSE(validateStats(img, "img", err));
        EXPECT_EQ(err.rfind("img: ", 0), 0u) << err;
        return err;
    }
    StatsImage img;
};

TEST_F(ValidateCounts, NegativeBufferCount) {
    // pixel index 6 = (2, 1) in the data window, (102, 201) in EXR coordinates
    img.bufferCount[6 * 2 + 1] = -1.f;
    img.count[6] = 1.f;
    const std::string err = check();
    EXPECT_TRUE(contains(err, "pixel (102, 201)")) << err;
    EXPECT_TRUE(contains(err, "buffer 1 count is negative")) << err;
}

TEST_F(ValidateCounts, NanAndInfiniteCounts) {
    img.count[5] = std::numeric_limits<float>::quiet_NaN();
    std::string err = check();
    EXPECT_TRUE(contains(err, "pixel (101, 201): moments count is NaN")) << err;
    img.count[5] = 3.f;
    img.bufferCount[0] = std::numeric_limits<float>::infinity();
    err = check();
    EXPECT_TRUE(contains(err, "pixel (100, 200): buffer 0 count is infinite")) << err;
}

TEST_F(ValidateCounts, NonIntegralAndHugeCounts) {
    const float saved = img.bufferCount[3];
    img.bufferCount[3] = 1.5f;
    std::string err = check();
    EXPECT_TRUE(contains(err, "pixel (101, 200): buffer 1 count is not an integer")) << err;
    img.bufferCount[3] = saved;
    img.count[11] = 33554432.f;  // 2^25
    err = check();
    EXPECT_TRUE(contains(err, "pixel (103, 202): moments count exceeds 2^24")) << err;
}

TEST_F(ValidateCounts, BufferCountsMustSumToCount) {
    img.count[7] = 4.f;
    const std::string err = check();
    EXPECT_TRUE(
        contains(err, "pixel (103, 201): buffer counts sum to 3 but the moments count is 4"))
        << err;
}

TEST_F(ValidateCounts, ArraySizesAndHeaderFields) {
    img.variance.pop_back();
    std::string err = check();
    EXPECT_TRUE(contains(err, "variance")) << err;
    img.variance.push_back(0.f);
    img.header.assignment = "random";
    err = check();
    EXPECT_TRUE(contains(err, "unknown sample assignment 'random'")) << err;
    img.header.assignment = "leastcount";
    err = check();
    EXPECT_TRUE(contains(err, "sample assignment 'leastcount' needs adaptive M")) << err;
    img.header.assignment = "roundrobin";
    img.header.spp = -1;
    err = check();
    EXPECT_TRUE(contains(err, "negative spp")) << err;
}

}  // namespace
}  // namespace mcstat::test
