// Streaming a statistics file by blocks of rows (StatsFileReader) and the image operations over it
// (imageops.h, "streamed from a file"): every block equals the same rows of the whole-file read,
// and every streamed operation equals the in-memory one bit for bit, for fixed and adaptive M, any
// block height, regions of interest, and one or two threads. (A damaged late block:
// tests/exr-deep/test_stream_reader.cpp.)
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "filters/pixel/pixel_support.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/filters/window/window_kernel.h"
#include "mcstat/image/imageops.h"

using namespace mcstat;
using mcstat::testing::kLuma;

namespace {

namespace fs = std::filesystem;

class Stream : public ::testing::Test {
  protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() /
               ("mcstat-stream-" +
                std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "-" +
                std::to_string(::getpid()));
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }
    std::string file(const std::string& name) const { return (dir_ / name).string(); }
    fs::path dir_;
};

/// A W x H image (origin (ox, oy)) with fireflies, NaN buffers, empty buffers and negative means;
/// adaptive M gives each pixel 1..M buffers. Counts sum to the moments count.
StatsImage makeImage(int W, int H, int M, bool adaptive, unsigned seed, int ox = 0, int oy = 0) {
    StatsImage s;
    s.header.width = W;
    s.header.height = H;
    s.header.originX = ox;
    s.header.originY = oy;
    s.header.M = M;
    s.header.spp = 64;
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::string err;
    if (adaptive) {
        s.header.formatVersion = kStatsFormatVersionAdaptive;
        s.header.assignment = kAssignmentLeastCount;
        std::vector<uint32_t> m(size_t(W) * size_t(H));
        for (auto& v : m) v = 1 + uint32_t(rng() % uint32_t(M));
        EXPECT_TRUE(s.allocateAdaptive(m, err)) << err;
    } else {
        EXPECT_TRUE(s.allocate(err)) << err;
    }
    for (size_t p = 0; p < s.pixelCount(); ++p) {
        double n = 0;
        const size_t k0 = s.bufferBegin(p);
        for (int j = 0; j < s.buffersOf(p); ++j) {
            const size_t k = k0 + size_t(j);
            const float r = u(rng);
            const float count = r < 0.05f ? 0.f : float(1 + rng() % 9);
            s.bufferCount[k] = count;
            n += count;
            for (int c = 0; c < 3; ++c) {
                float v = 0.1f + u(rng) * (r > 0.97f ? 5000.f : 1.f);
                if (r > 0.05f && r < 0.07f) v = -v;
                s.bufferMean[k * 3 + size_t(c)] = v;
            }
            if (r > 0.995f) s.bufferMean[k * 3] = std::numeric_limits<float>::quiet_NaN();
        }
        s.count[p] = float(n);
        for (int c = 0; c < 3; ++c) {
            s.beauty[p * 3 + size_t(c)] = u(rng);
            s.mean[p * 3 + size_t(c)] = u(rng);
            s.variance[p * 3 + size_t(c)] = u(rng);
            s.normal[p * 3 + size_t(c)] = u(rng);
            s.position[p * 3 + size_t(c)] = u(rng);
            s.albedo[p * 3 + size_t(c)] = u(rng);
        }
        s.depth[p] = u(rng);
        s.coverage[p] = u(rng);
    }
    return s;
}

bool sameBits(const std::vector<float>& a, const float* b, size_t n) {
    return a.size() == n && (n == 0 || std::memcmp(a.data(), b, n * sizeof(float)) == 0);
}

/// Whether two float images have the same windows, channels and pixel bits.
void expectSameImage(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b, const std::string& what) {
    ASSERT_FALSE(a.has_error()) << what << ": " << a.geterror();
    ASSERT_FALSE(b.has_error()) << what << ": " << b.geterror();
    ASSERT_EQ(a.roi(), b.roi()) << what;
    ASSERT_EQ(a.roi_full(), b.roi_full()) << what;
    ASSERT_EQ(a.spec().channelnames, b.spec().channelnames) << what;
    const size_t n = size_t(a.spec().image_pixels()) * size_t(a.nchannels());
    ASSERT_EQ(0, std::memcmp(a.localpixels(), b.localpixels(), n * sizeof(float))) << what;
}

TEST_F(Stream, BlocksEqualTheRowsOfTheWholeFileForEveryPart) {
    for (const bool adaptive : {false, true}) {
        const StatsImage img = makeImage(13, 70, 5, adaptive, 7, -3, 11);
        const std::string path = file(adaptive ? "a.mcstat" : "f.mcstat");
        std::string err;
        ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
        StatsImage whole;
        ASSERT_TRUE(readStatsFile(path, whole, err)) << err;
        StatsFileReader reader;
        ASSERT_TRUE(reader.open(path, err, ReadLimits(), 2)) << err;
        // The writer's ZIP (16 rows per chunk); the deep part of adaptive M is ZIPS (one row).
        EXPECT_EQ(adaptive ? 1 : 16, reader.chunkRows());
        EXPECT_EQ(reader.header().height, 70);
        for (const int rows : {1, 16, 23, 70}) {
            StatsImage block;
            for (int y = 0; y < 70; y += rows) {
                const int n = std::min(rows, 70 - y);
                ASSERT_TRUE(reader.read(y, n, kStatsAllParts, block, err)) << err;
                EXPECT_EQ(block.header.originY, 11 + y);
                EXPECT_EQ(block.header.height, n);
                const size_t p0 = size_t(y) * 13, np = size_t(n) * 13;
                EXPECT_TRUE(sameBits(block.beauty, whole.beauty.data() + p0 * 3, np * 3));
                EXPECT_TRUE(sameBits(block.count, whole.count.data() + p0, np));
                EXPECT_TRUE(sameBits(block.variance, whole.variance.data() + p0 * 3, np * 3));
                EXPECT_TRUE(sameBits(block.coverage, whole.coverage.data() + p0, np));
                const size_t k0 = whole.bufferBegin(p0);
                const size_t k1 =
                    whole.bufferBegin(p0 + np - 1) + size_t(whole.buffersOf(p0 + np - 1));
                EXPECT_TRUE(
                    sameBits(block.bufferMean, whole.bufferMean.data() + k0 * 3, (k1 - k0) * 3))
                    << "rows " << y << "+" << n << (adaptive ? " adaptive" : " fixed");
                EXPECT_TRUE(sameBits(block.bufferCount, whole.bufferCount.data() + k0, k1 - k0));
            }
        }
        // Only the parts asked for are filled.
        StatsImage part;
        ASSERT_TRUE(reader.read(20, 9, kStatsPartBuffers, part, err)) << err;
        EXPECT_TRUE(part.beauty.empty() && part.count.empty() && part.depth.empty());
        EXPECT_EQ(part.pixelCount(), 9u * 13u);
        ASSERT_TRUE(reader.read(20, 9, kStatsPartFeatures, part, err)) << err;
        EXPECT_TRUE(part.bufferMean.empty() && part.bufferOffset.empty());
        EXPECT_TRUE(sameBits(part.depth, whole.depth.data() + 20 * 13, 9 * 13));
    }
}

TEST_F(Stream, BadRangesAndUnopenedReadersAreErrors) {
    const std::string path = file("f.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, makeImage(4, 20, 3, false, 1), err)) << err;
    StatsFileReader reader;
    StatsImage block;
    EXPECT_FALSE(reader.read(0, 1, kStatsAllParts, block, err));
    EXPECT_NE(err.find("before a successful open"), std::string::npos) << err;
    ASSERT_TRUE(reader.open(path, err)) << err;
    for (const auto& [y, n] : {std::pair{-1, 2}, {0, 0}, {19, 2}, {0, 21}, {5, -3}}) {
        err.clear();
        EXPECT_FALSE(reader.read(y, n, kStatsAllParts, block, err)) << y << "+" << n;
        EXPECT_NE(err.find(path), std::string::npos) << err;
        EXPECT_NE(err.find("cannot read rows"), std::string::npos) << err;
    }
    EXPECT_FALSE(reader.read(0, 1, 32u, block, err));
    EXPECT_FALSE(reader.open(file("missing.mcstat"), err));
    EXPECT_FALSE(reader.isOpen());
    EXPECT_NE(err.find("missing.mcstat"), std::string::npos) << err;
}

TEST_F(Stream, BlockHeightIsAMultipleOfTheChunkWithinTheBudget) {
    const std::string path = file("f.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, makeImage(100, 300, 21, false, 2), err)) << err;
    StatsFileReader reader;
    ASSERT_TRUE(reader.open(path, err, ReadLimits(), 1)) << err;  // one decoding thread
    // A row of buffers is 100 x 21 x 4 floats = 33,600 bytes: 1 MiB holds 31 rows -> 16.
    EXPECT_EQ(16, reader.blockRows(kStatsPartBuffers, size_t(1) << 20));
    EXPECT_EQ(16, reader.blockRows(kStatsPartBuffers, 1));                 // at least one chunk
    EXPECT_EQ(300, reader.blockRows(kStatsPartBuffers, size_t(1) << 30));  // at most the image
    EXPECT_EQ(3 * 16 * 2, reader.blockRows(kStatsPartBeauty, 100 * 12 * 100));
    // Three decoding threads: at least one chunk each, so that wide rows do not leave two idle.
    StatsFileReader three;
    ASSERT_TRUE(three.open(path, err, ReadLimits(), 3)) << err;
    EXPECT_EQ(3, three.decodeThreads());
    EXPECT_EQ(3 * 16, three.blockRows(kStatsPartBuffers, 1));
    EXPECT_EQ(3 * 16, three.blockRows(kStatsPartBuffers, size_t(1) << 20));
    EXPECT_EQ(300, three.blockRows(kStatsPartBuffers, size_t(1) << 30));
}

TEST_F(Stream, StreamedOperationsEqualTheInMemoryOnesBitForBit) {
    for (const bool adaptive : {false, true}) {
        const StatsImage img = makeImage(37, 150, 6, adaptive, 11, 4, -9);
        const std::string path = file("s.mcstat");
        std::string err;
        ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
        StatsImage whole;
        ASSERT_TRUE(readStatsFile(path, whole, err)) << err;
        const OIIO::ROI regions[] = {OIIO::ROI(), OIIO::ROI(10, 30, 20, 97),
                                     OIIO::ROI(4, 41, 120, 141)};
        for (const Operation& op : operationRegistry()) {
            if (op.input == InputKind::Samples) continue;
            for (const char* mode : {"lum", "channel"}) {
                ParamValues values;
                std::map<std::string, std::string> kv;
                if (op.param("mode")) kv["mode"] = mode;
                ASSERT_TRUE(parseOperationParams(op, kv, values, err)) << err;
                for (const OIIO::ROI& roi : regions)
                    for (const int threads : {1, 2}) {
                        StatsFileReader reader;
                        ASSERT_TRUE(reader.open(path, err, ReadLimits(), threads)) << err;
                        OIIO::ImageBuf mem, streamed;
                        ASSERT_TRUE(
                            applyOperation(mem, whole, op, values, kLuma, true, roi, threads));
                        ASSERT_TRUE(applyOperation(streamed, reader, op, values, kLuma, true, roi,
                                                   threads));
                        expectSameImage(mem, streamed,
                                        op.name + " " + mode + (adaptive ? " adaptive" : " fixed") +
                                            " roi " + std::to_string(roi.ybegin));
                        EXPECT_EQ(operationChannels(op, values, true), streamed.spec().channelnames)
                            << op.name;
                    }
            }
            // The expected value's interval pools over cipool rows above and below: a block
            // carries them (its halo), so a region's pixels see the whole image's windows.
            if (!hasIntervals(op)) continue;
            std::map<std::string, std::string> kv = {
                {"ci", "0.9"}, {"citarget", "expected"}, {"cipool", "3"}};
            ParamValues ci, values;
            ASSERT_TRUE(takeConfidenceModifiers(op.name, kv, ci, err)) << err;
            ASSERT_TRUE(parseOperationParams(op, kv, values, err)) << err;
            values.insert(ci.begin(), ci.end());
            for (const OIIO::ROI& roi : regions) {
                StatsFileReader reader;
                ASSERT_TRUE(reader.open(path, err, ReadLimits(), 2)) << err;
                OIIO::ImageBuf mem, streamed;
                ASSERT_TRUE(applyOperation(mem, whole, op, values, kLuma, false, roi, 2));
                ASSERT_TRUE(applyOperation(streamed, reader, op, values, kLuma, false, roi, 1));
                expectSameImage(mem, streamed,
                                op.name + " citarget=expected roi " + std::to_string(roi.ybegin));
            }
        }
    }
}

/// Whether two images hold the same header size fields and every array bit for bit.
void expectSameStats(const StatsImage& a, const StatsImage& b, const std::string& what) {
    EXPECT_EQ(a.header.width, b.header.width) << what;
    EXPECT_EQ(a.header.height, b.header.height) << what;
    EXPECT_EQ(a.header.M, b.header.M) << what;
    EXPECT_EQ(a.header.spp, b.header.spp) << what;
    EXPECT_EQ(a.header.seeds, b.header.seeds) << what;
    EXPECT_EQ(a.bufferOffset, b.bufferOffset) << what;
    const std::vector<float> StatsImage::*arrays[] = {
        &StatsImage::beauty, &StatsImage::bufferMean, &StatsImage::bufferCount,
        &StatsImage::count,  &StatsImage::mean,       &StatsImage::variance,
        &StatsImage::normal, &StatsImage::position,   &StatsImage::albedo,
        &StatsImage::depth,  &StatsImage::coverage};
    for (auto arr : arrays) EXPECT_TRUE(sameBits(a.*arr, (b.*arr).data(), (b.*arr).size())) << what;
}

TEST_F(Stream, TheWriterByBlocksEqualsTheWholeWrite) {
    for (const bool adaptive : {false, true}) {
        const StatsImage img = makeImage(11, 53, 4, adaptive, 5, 2, -7);
        const std::string whole = file("whole.mcstat"), blocks = file("blocks.mcstat");
        std::string err;
        ASSERT_TRUE(writeStatsFile(whole, img, err)) << err;
        auto shared = std::make_shared<const StatsImage>(img);
        MemoryStatsSource src(shared, "memory");
        for (const int rows : {1, 7, 16, 53}) {
            StatsFileWriter w;
            ASSERT_TRUE(w.open(blocks, img.header, err, 2)) << err;
            StatsImage block;
            for (int y = 0; y < 53; y += rows) {
                ASSERT_TRUE(src.read(y, std::min(rows, 53 - y), kStatsAllParts, block, err)) << err;
                ASSERT_TRUE(w.write(block, err)) << err;
            }
            ASSERT_TRUE(w.commit(err)) << err;
            StatsImage back;
            ASSERT_TRUE(readStatsFile(blocks, back, err)) << err;
            expectSameStats(back, img, "rows " + std::to_string(rows));
            // One block is the whole write, byte for byte (the parts one after the other).
            if (rows == 53) {
                std::ifstream x(whole, std::ios::binary), y(blocks, std::ios::binary);
                const std::string bx((std::istreambuf_iterator<char>(x)), {});
                const std::string by((std::istreambuf_iterator<char>(y)), {});
                EXPECT_TRUE(bx == by) << "one block differs from writeStatsFile";
            }
        }
    }
}

TEST_F(Stream, AnUnfinishedWriteLeavesTheTargetAndNoTemporaryFile) {
    const StatsImage img = makeImage(5, 30, 2, false, 6);
    const std::string target = file("t.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(target, makeImage(5, 30, 2, false, 99), err)) << err;
    const auto before = fs::file_size(target);
    auto shared = std::make_shared<const StatsImage>(img);
    MemoryStatsSource src(shared, "memory");
    StatsImage block;
    {
        StatsFileWriter w;
        ASSERT_TRUE(w.open(target, img.header, err)) << err;
        ASSERT_TRUE(src.read(0, 10, kStatsAllParts, block, err)) << err;
        ASSERT_TRUE(w.write(block, err)) << err;
        // Rows out of order, and a commit before the last row, are refused.
        ASSERT_TRUE(src.read(20, 10, kStatsAllParts, block, err)) << err;
        EXPECT_FALSE(w.write(block, err));
        EXPECT_NE(err.find("does not continue the image at row 10"), std::string::npos) << err;
        EXPECT_FALSE(w.commit(err));
        EXPECT_NE(err.find("10 of 30 rows written"), std::string::npos) << err;
    }  // abandoned
    size_t files = 0;
    for (const auto& e : fs::directory_iterator(dir_)) files += e.is_regular_file() ? 1 : 0;
    EXPECT_EQ(files, 1u) << "a temporary file was left behind";
    EXPECT_EQ(fs::file_size(target), before);
    StatsImage back;
    EXPECT_TRUE(readStatsFile(target, back, err)) << err;
}

TEST_F(Stream, AMergeBlockByBlockEqualsTheWholeMerge) {
    for (const bool adaptive : {false, true}) {
        StatsImage a = makeImage(9, 45, 3, adaptive, 21), b = makeImage(9, 45, 3, adaptive, 22);
        a.header.seeds = "1";
        b.header.seeds = "2";
        b.header.spp = 100;
        if (adaptive) {  // the same m_p in every pixel: refill b's buffers on a's layout
            StatsImage c = makeImage(9, 45, 3, adaptive, 21);
            for (size_t k = 0; k < c.bufferMean.size(); ++k) c.bufferMean[k] *= 2.f;
            c.header = b.header;
            b = c;
        }
        const std::string pa = file("a.mcstat"), pb = file("b.mcstat"), pm = file("m.mcstat");
        std::string err;
        ASSERT_TRUE(writeStatsFile(pa, a, err)) << err;
        ASSERT_TRUE(writeStatsFile(pb, b, err)) << err;
        StatsImage ra, rb, expected;
        ASSERT_TRUE(readStatsFile(pa, ra, err) && readStatsFile(pb, rb, err)) << err;
        ASSERT_TRUE(mergeStats(ra, rb, expected, err)) << err;
        StatsFileReader fa, fb;
        ASSERT_TRUE(fa.open(pa, err) && fb.open(pb, err)) << err;
        MergedStatsSource merged;
        ASSERT_TRUE(merged.init(fa, fb, err)) << err;
        EXPECT_EQ(merged.header().spp, 164);
        EXPECT_EQ(merged.header().seeds, "1,2");
        // Blocks of 16 rows (one ZIP chunk): three blocks for 45 rows.
        ASSERT_TRUE(writeStatsFile(pm, merged, err, 2, 9 * 16 * (4 * 3 + 2 + 21) * 4)) << err;
        StatsImage back;
        ASSERT_TRUE(readStatsFile(pm, back, err)) << err;
        expectSameStats(back, expected, adaptive ? "adaptive" : "fixed");
    }
    // Adaptive inputs with different buffer counts: the pixel is named when its block is read.
    const StatsImage a = makeImage(4, 20, 3, true, 31), b = makeImage(4, 20, 3, true, 32);
    std::string err;
    ASSERT_TRUE(writeStatsFile(file("x.mcstat"), a, err) &&
                writeStatsFile(file("y.mcstat"), b, err));
    StatsFileReader fa, fb;
    ASSERT_TRUE(fa.open(file("x.mcstat"), err) && fb.open(file("y.mcstat"), err)) << err;
    MergedStatsSource merged;
    ASSERT_TRUE(merged.init(fa, fb, err)) << err;
    StatsImage block;
    EXPECT_FALSE(merged.read(0, 20, kStatsAllParts, block, err));
    EXPECT_NE(err.find("adaptive M differs at pixel"), std::string::npos) << err;
}

TEST_F(Stream, ARegionOutsideTheImageIsAnError) {
    const std::string path = file("f.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, makeImage(8, 8, 2, false, 4), err)) << err;
    StatsFileReader reader;
    ASSERT_TRUE(reader.open(path, err)) << err;
    const Operation& gmon = *findOperation("gmon");
    const PixelKernel kernel = gmon.bindPixel(ParamValues(), kLuma);
    OIIO::ImageBuf out;
    EXPECT_FALSE(estimate(out, reader, gmon, kernel, false, OIIO::ROI(20, 30, 0, 4)));
    EXPECT_NE(out.geterror().find("outside the data window"), std::string::npos);
    StatsFileReader closed;
    EXPECT_FALSE(estimate(out, closed, gmon, kernel));
}

/// A source that counts the blocks read through it (each read forwarded to `inner`).
class CountingSource final : public StatsBlockSource {
  public:
    explicit CountingSource(StatsBlockSource& inner) : inner_(inner) {}
    const StatsHeader& header() const override { return inner_.header(); }
    const std::string& name() const override { return inner_.name(); }
    int chunkRows() const override { return inner_.chunkRows(); }
    bool read(int firstRow, int rows, unsigned parts, StatsImage& block,
              std::string& err) override {
        ++reads;
        return inner_.read(firstRow, rows, parts, block, err);
    }
    int reads = 0;

  private:
    StatsBlockSource& inner_;
};

TEST_F(Stream, AHandBuiltInvalidWindowFailsBeforeAnyBlockIsRead) {
    const std::string path = file("f.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, makeImage(8, 40, 2, false, 4), err)) << err;
    SpatialParams params;
    params.luma = kLuma;
    params.windowWidth = 4;  // even: out of range (what spatialParams' parser never builds)
    std::string why;
    ASSERT_FALSE(validateSpatialParams(params, why));
    const WindowKernel bad = windowKernel(Neighbourhood::SubBuffers, params);
    {
        StatsFileReader reader;
        ASSERT_TRUE(reader.open(path, err)) << err;
        CountingSource counted(reader);
        OIIO::ImageBuf out;
        EXPECT_FALSE(windowFilter(out, counted, bad));
        EXPECT_EQ(0, counted.reads);
        EXPECT_EQ(bad.name + ": " + why, out.geterror());
    }
    // The same kernel with a valid window reads the file.
    params.windowWidth = 3;
    StatsFileReader reader;
    ASSERT_TRUE(reader.open(path, err)) << err;
    CountingSource counted(reader);
    OIIO::ImageBuf out;
    EXPECT_TRUE(windowFilter(out, counted, windowKernel(Neighbourhood::SubBuffers, params)))
        << out.geterror();
    EXPECT_GT(counted.reads, 0);
}

}  // namespace
