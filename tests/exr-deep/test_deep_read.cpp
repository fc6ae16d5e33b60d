// The deep part `vbuffers` through OpenEXR's Core API and libdeflate (exr-deep/deep_part_reader.h):
// for the compressions it takes (NONE, ZIPS) and the one it leaves to the C++ API (RLE), the
// buffers equal the image written, NaN payloads and infinities included, whole and by blocks of
// rows, on 1 and 2 threads, with the AOV channels of version 6; a damaged sample count table or
// chunk is a one-line error naming the file, the part and the row, the first damaged row whatever
// the thread count.
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/openexr.h>
#include <fcntl.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "mcstat/exr-deep/codec/detail/deep_part_reader.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/detail/flat_part_reader.h"
#include "mcstat/exr-deep/stats_file.h"
#include "raw_exr.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

/// m_p in {1, 2, 5, 9} by position, spp 0..9, a few special floats among the buffer means.
StatsImage deepImage(int w, int h) {
    StatsImage img = adaptiveImage(
        w, h, 9, 3,
        [](int x, int y) {
            static const int ms[4] = {1, 2, 5, 9};
            return ms[(x * 3 + y) % 4];
        },
        [](int x, int y) { return (x * 7 + y * 5) % 10; });
    const float special[] = {std::numeric_limits<float>::quiet_NaN(),
                             std::numeric_limits<float>::infinity(), -0.f, 1e-45f, 3e38f};
    for (size_t i = 7, k = 0; i < img.bufferMean.size(); i += 13, ++k)
        img.bufferMean[i] = special[k % 5];
    return img;
}

bool sameBits(const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() &&
           (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

/// Expects `path` read whole and by blocks of 1, 2 and 3 rows on `threads` threads to hold
/// `img`'s buffers (and AOVs) bit for bit.
void expectBuffers(const StatsImage& img, const std::string& path, int threads,
                   const std::string& what) {
    StatsFileReader reader;
    std::string err;
    ASSERT_TRUE(reader.open(path, err, ReadLimits(), threads)) << what << ": " << err;
    const size_t w = size_t(img.header.width), A = img.header.aovs.size();
    for (int rows : {img.header.height, 1, 2, 3}) {
        for (int y = 0; y < img.header.height; y += rows) {
            const int n = std::min(rows, img.header.height - y);
            StatsImage blk;
            ASSERT_TRUE(reader.read(y, n, kStatsAllParts, blk, err)) << what << ": " << err;
            const size_t b0 = img.bufferBegin(size_t(y) * w);
            const size_t b1 = img.bufferBegin(size_t(y + n) * w - 1) +
                              size_t(img.buffersOf(size_t(y + n) * w - 1));
            const auto slice = [&](const std::vector<float>& v, size_t per) {
                return std::vector<float>(v.begin() + long(b0 * per), v.begin() + long(b1 * per));
            };
            EXPECT_TRUE(sameBits(blk.bufferMean, slice(img.bufferMean, 3)))
                << what << ", rows " << y << "+" << n;
            EXPECT_TRUE(sameBits(blk.bufferCount, slice(img.bufferCount, 1)))
                << what << ", rows " << y << "+" << n;
            EXPECT_TRUE(sameBits(blk.aov, slice(img.aov, A))) << what << ", rows " << y << "+" << n;
        }
    }
}

/// The Core chunk info of row `y` of part 1 (vbuffers) of `path`.
exr_chunk_info_t chunkOf(const std::string& path, int y) {
    exr_context_t ctxt = nullptr;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    EXPECT_EQ(exr_start_read(&ctxt, path.c_str(), &init), EXR_ERR_SUCCESS);
    exr_chunk_info_t ci{};
    EXPECT_EQ(exr_read_scanline_chunk_info(ctxt, 1, y, &ci), EXR_ERR_SUCCESS);
    exr_finish(&ctxt);
    return ci;
}

void putInt32(std::vector<unsigned char>& bytes, uint64_t at, int32_t v) {
    std::memcpy(bytes.data() + at, &v, 4);
}

class DeepRead : public testing::Test {
  protected:
    void SetUp() override { img = deepImage(7, 6); }
    std::string raw(Imf::Compression c, const char* name) {
        std::vector<RawPart> parts = rawAdaptivePartsFrom(img);
        parts[1].header.compression() = c;
        const std::string path = dir.file(std::string(name) + ".mcstat");
        writeRaw(path, parts);
        return path;
    }
    std::string readError(const std::string& path, int threads = 1) {
        StatsImage out;
        std::string err;
        StatsFileReader reader;
        EXPECT_TRUE(reader.open(path, err, ReadLimits(), threads)) << err;
        EXPECT_FALSE(reader.read(0, img.header.height, kStatsAllParts, out, err));
        EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
        EXPECT_EQ(err.find('\n'), std::string::npos) << err;
        return err;
    }

    ScratchDir dir;
    StatsImage img;
};

TEST_F(DeepRead, TheCoreReaderTakesNoneAndZipsAndLeavesRleToTheCppApi) {
    const struct {
        Imf::Compression c;
        const char* name;
        bool core;
    } codecs[] = {{Imf::NO_COMPRESSION, "none", true},
                  {Imf::ZIPS_COMPRESSION, "zips", true},
                  {Imf::RLE_COMPRESSION, "rle", false}};
    for (const auto& codec : codecs) {
        const std::string path = raw(codec.c, codec.name);
        detail::Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
        const uint64_t size = readBytes(path).size();
        detail::FlatPartReader flat;
        detail::DeepPartReader deep;
        std::string problem;
        ASSERT_TRUE(
            flat.open(fd.get(), size, path, 0, 0, img.header.width, img.header.height, problem))
            << problem;
        ASSERT_TRUE(deep.open(flat, 1, problem)) << problem;
        EXPECT_EQ(deep.handles(), codec.core) << codec.name;
        EXPECT_FALSE(deep.open(flat, 0, problem)) << "part 0 is flat";
        EXPECT_TRUE(contains(problem, "not a deep scan-line part")) << problem;
        for (int threads : {1, 2}) expectBuffers(img, path, threads, codec.name);
    }
}

TEST_F(DeepRead, CountsAndSamplesOfAnyRowsDirectly) {
    const std::string path = raw(Imf::ZIPS_COMPRESSION, "zips");
    detail::Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    detail::FlatPartReader flat;
    detail::DeepPartReader deep;
    std::string problem;
    ASSERT_TRUE(flat.open(fd.get(), readBytes(path).size(), path, 0, 0, img.header.width,
                          img.header.height, problem));
    ASSERT_TRUE(deep.open(flat, 1, problem)) << problem;
    std::vector<uint32_t> counts;
    ASSERT_EQ(deep.readCounts(2, 3, 2, counts, problem), detail::DeepPartReader::Result::Ok)
        << problem;
    const size_t w = size_t(img.header.width);
    ASSERT_EQ(counts.size(), 3 * w);
    size_t total = 0;
    for (size_t i = 0; i < counts.size(); ++i) {
        EXPECT_EQ(counts[i], uint32_t(img.buffersOf(2 * w + i))) << i;
        total += counts[i];
    }
    // Only the channel "count", with a stride of 2 (every other float left alone).
    std::vector<float> got(2 * total, -1.f);
    ASSERT_EQ(deep.readSamples(2, 3, counts, {{"count", got.data(), 2}}, 2, problem),
              detail::DeepPartReader::Result::Ok)
        << problem;
    const size_t b0 = img.bufferBegin(2 * w);
    for (size_t k = 0; k < total; ++k) {
        EXPECT_EQ(got[2 * k], img.bufferCount[b0 + k]) << k;
        EXPECT_EQ(got[2 * k + 1], -1.f) << k;
    }
    EXPECT_EQ(deep.readSamples(2, 3, counts, {{"nope", got.data(), 1}}, 1, problem),
              detail::DeepPartReader::Result::Corrupt);
    EXPECT_TRUE(contains(problem, "channel 'nope' changed while reading")) << problem;
}

TEST_F(DeepRead, AovChannelsOfVersion6RoundTripThroughTheCoreReader) {
    StatsImage a = img;
    a.header.formatVersion = kStatsFormatVersionCompact;
    a.header.aovs = {{"alpha", AovClass::Alpha, ""}, {"light.R", AovClass::Light, "l"}};
    a.aov.resize(a.bufferCount.size() * 2);
    for (size_t i = 0; i < a.aov.size(); ++i) a.aov[i] = 0.25f * float(i % 97) - 3.f;
    a.aov[5] = std::numeric_limits<float>::quiet_NaN();
    const std::string path = dir.file("aovs.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, a, err)) << err;
    for (int threads : {1, 2}) expectBuffers(a, path, threads, "written with AOVs");
}

TEST_F(DeepRead, ADecreasingSampleCountTableIsAOneLineError) {
    const std::string path = raw(Imf::NO_COMPRESSION, "none");
    const exr_chunk_info_t ci = chunkOf(path, 2);
    ASSERT_EQ(ci.sample_count_table_size, uint64_t(img.header.width) * 4);
    std::vector<unsigned char> bytes = readBytes(path);
    putInt32(bytes, ci.sample_count_data_offset + 3 * 4, -1);  // pixel 3's cumulative count
    writeBytes(path, bytes);
    const std::string err = readError(path);
    EXPECT_TRUE(contains(err,
                         "part 'vbuffers': the chunk of row 2: its sample count table "
                         "decreases at pixel 3 (-1 after"))
        << err;
}

TEST_F(DeepRead, ATableThatDisagreesWithTheChunksSizeIsAnError) {
    const std::string path = raw(Imf::NO_COMPRESSION, "none");
    const exr_chunk_info_t ci = chunkOf(path, 1);
    std::vector<unsigned char> bytes = readBytes(path);
    const uint64_t last = ci.sample_count_data_offset + uint64_t(img.header.width - 1) * 4;
    int32_t v;
    std::memcpy(&v, bytes.data() + last, 4);
    putInt32(bytes, last, v + 1);  // one sample more in the line's last pixel
    writeBytes(path, bytes);
    const std::string err = readError(path);
    EXPECT_TRUE(
        contains(err, "the chunk of row 1: " + std::to_string(v + 1) + " samples of 24 bytes need"))
        << err;
}

TEST_F(DeepRead, DamagedZipChunksReportTheFirstWhateverTheThreads) {
    const std::string path = raw(Imf::ZIPS_COMPRESSION, "zips");
    std::vector<unsigned char> bytes = readBytes(path);
    for (int y : {4, 1}) {
        const exr_chunk_info_t ci = chunkOf(path, y);
        ASSERT_LT(ci.packed_size, ci.unpacked_size) << "row " << y << " is not compressed";
        for (uint64_t i = 2; i < ci.packed_size; ++i) bytes[ci.data_offset + i] ^= 0x5a;
    }
    writeBytes(path, bytes);
    for (int threads : {1, 2}) {
        const std::string err = readError(path, threads);
        EXPECT_TRUE(contains(err, "part 'vbuffers': the chunk of row 1: its samples: its")) << err;
    }
}

}  // namespace
}  // namespace mcstat::test
