// Statistics files through OpenEXR's Core API with libdeflate's ZIP.
// Reading (exr-deep/flat_part_reader.h): for every compression OpenEXR writes, the pixels equal
// the C++ API's read of the same file bit for bit (NaN payloads, infinities, denormals, -0
// included), on 1 and 2 threads and for blocks that cut chunks; a damaged ZIP chunk is a one-line
// error. Writing (exr-deep/core_part_writer.h): the bytes are standard ZIP that OpenEXR's C++
// API, its file checker (exrcheck's engine) and stock oiiotool read, the same whatever the blocks
// and threads; a chunk ZIP cannot shrink is stored as it is; a bad count is refused whether the
// image is written whole or streamed by blocks.
#include <OpenEXR/ImfCheckFile.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/openexr.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "mcstat/exr-deep/stats_file.h"
#include "raw_exr.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

float bits(uint32_t u) {
    float f;
    std::memcpy(&f, &u, sizeof f);
    return f;
}

/// Values no arithmetic produces by chance: NaNs with payloads (quiet and signalling, both
/// signs), infinities, denormals, -0, the extremes.
const std::vector<float> kSpecial = {bits(0x7fc00001u),
                                     bits(0xffc12345u),
                                     bits(0x7f800001u),
                                     bits(0xff80beefu),
                                     std::numeric_limits<float>::infinity(),
                                     -std::numeric_limits<float>::infinity(),
                                     bits(0x00000001u),
                                     bits(0x807fffffu),
                                     bits(0x80000000u),
                                     std::numeric_limits<float>::max(),
                                     std::numeric_limits<float>::lowest(),
                                     bits(0x00400000u)};

/// A version-5 image (two AOVs) of w x h pixels and M buffers, every float array but the counts
/// seeded with kSpecial every few elements.
StatsImage specialImage(int w, int h, int M) {
    StatsImage img = renderImage(w, h, M, 7, [](int x, int y) { return (x * 3 + y * 5) % 9; });
    StatsHeader& hd = img.header;
    hd.formatVersion = kStatsFormatVersionAovs;
    hd.aovs = {{"ViewLayer.Combined.A", AovClass::Alpha, ""}, {"diffuse.R", AovClass::Light, "d"}};
    hd.beautyNames = {"ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B"};
    hd.beautyPart = "ViewLayer";
    img.aov.resize(img.pixelCount() * size_t(M) * hd.aovs.size());
    for (size_t i = 0; i < img.aov.size(); ++i) img.aov[i] = 0.375f * float(i % 1013) - 7.f;
    size_t k = 0;
    for (std::vector<float>* a :
         {&img.beauty, &img.bufferMean, &img.mean, &img.variance, &img.normal, &img.position,
          &img.albedo, &img.depth, &img.coverage, &img.aov})
        for (size_t i = k % 5; i < a->size(); i += 5 + (k++ % 7)) (*a)[i] = kSpecial[k % 12];
    return img;
}

/// Every channel of every flat part of `img` as the file holds it, by part name: the four parts
/// from rawPartsFrom, part aovs as FORMAT.md lays it out (bNNN.<name>).
std::map<std::string, std::map<std::string, std::vector<float>>> channelsOf(const StatsImage& img) {
    std::map<std::string, std::map<std::string, std::vector<float>>> out;
    for (RawPart& p : rawPartsFrom(img)) out[p.header.name()] = std::move(p.values);
    const size_t M = size_t(img.header.M), A = img.header.aovs.size(), n = img.pixelCount();
    for (size_t j = 0; j < M; ++j)
        for (size_t a = 0; a < A; ++a) {
            char prefix[32];
            std::snprintf(prefix, sizeof prefix, "b%03zu.", j);
            std::vector<float>& v = out["aovs"][prefix + img.header.aovs[a].name];
            for (size_t p = 0; p < n; ++p) v.push_back(img.aov[(p * M + j) * A + a]);
        }
    return out;
}

bool bitEqual(const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() &&
           (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

/// Expects the flat parts of `img` to equal, bit for bit, the C++ API's read of `path`.
void expectEqualsCppRead(const StatsImage& img, const std::string& path, const std::string& what) {
    const auto mine = channelsOf(img);
    for (const RawPart& p : readRaw(path)) {
        const auto part = mine.find(p.header.name());
        ASSERT_NE(part, mine.end()) << what << ": part " << p.header.name();
        ASSERT_EQ(part->second.size(), p.values.size()) << what << ": part " << p.header.name();
        for (const auto& [name, values] : p.values) {
            const auto it = part->second.find(name);
            ASSERT_NE(it, part->second.end()) << what << ": channel " << name;
            EXPECT_TRUE(bitEqual(it->second, values))
                << what << ": part " << p.header.name() << ", channel " << name;
        }
    }
}

/// Reads `path` whole and by blocks of `blockRows` rows (which cut the chunks of every
/// compression) on `threads` threads; expects the blocks to be the whole read's rows.
StatsImage readWholeAndBlocks(const std::string& path, int threads, int blockRows) {
    StatsFileReader reader;
    std::string err;
    EXPECT_TRUE(reader.open(path, err, ReadLimits(), threads)) << err;
    StatsImage whole;
    EXPECT_TRUE(reader.read(0, reader.header().height, kStatsAllParts, whole, err)) << err;
    const size_t w = size_t(whole.header.width);
    StatsImage block;
    for (int y = 0; y < whole.header.height; y += blockRows) {
        const int n = std::min(blockRows, whole.header.height - y);
        EXPECT_TRUE(reader.read(y, n, kStatsAllParts, block, err)) << err;
        const auto rowsOf = [&](const std::vector<float>& a, const std::vector<float>& b) {
            const size_t perPixel = a.size() / whole.pixelCount();
            const size_t from = size_t(y) * w * perPixel, len = size_t(n) * w * perPixel;
            return b.size() == len &&
                   std::memcmp(a.data() + from, b.data(), len * sizeof(float)) == 0;
        };
        EXPECT_TRUE(rowsOf(whole.bufferMean, block.bufferMean)) << "rows " << y << "+" << n;
        EXPECT_TRUE(rowsOf(whole.bufferCount, block.bufferCount)) << "rows " << y << "+" << n;
        EXPECT_TRUE(rowsOf(whole.beauty, block.beauty)) << "rows " << y << "+" << n;
        EXPECT_TRUE(rowsOf(whole.variance, block.variance)) << "rows " << y << "+" << n;
        EXPECT_TRUE(rowsOf(whole.coverage, block.coverage)) << "rows " << y << "+" << n;
        EXPECT_TRUE(rowsOf(whole.aov, block.aov)) << "rows " << y << "+" << n;
    }
    return whole;
}

struct Codec {
    Imf::Compression c;
    const char* name;
    bool lossless;  // for FLOAT channels
};

class CoreIo : public testing::Test {
  protected:
    void SetUp() override {
        // 53 rows: a last chunk of 5 rows for ZIP's 16 and 21 for PIZ's 32; an odd width makes
        // ZIP's byte halves unequal; M = 3 and two AOVs give 12 + 6 channels.
        img = specialImage(37, 53, 3);
        zipPath = dir.file("zip.mcstat");
        std::string err;
        ASSERT_TRUE(writeStatsFile(zipPath, img, err)) << err;
    }
    /// `zipPath` written again with every part compressed with `c`.
    std::string rewritten(const Codec& codec) {
        std::vector<RawPart> parts = readRaw(zipPath);
        for (RawPart& p : parts) p.header.compression() = codec.c;
        const std::string path = dir.file(std::string(codec.name) + ".mcstat");
        writeRaw(path, parts);
        return path;
    }

    ScratchDir dir;
    StatsImage img;
    std::string zipPath;
};

TEST_F(CoreIo, EveryCompressionGivesTheCppApisPixelsOnOneAndTwoThreads) {
    const Codec codecs[] = {
        {Imf::ZIP_COMPRESSION, "zip", true},    {Imf::ZIPS_COMPRESSION, "zips", true},
        {Imf::NO_COMPRESSION, "none", true},    {Imf::PIZ_COMPRESSION, "piz", true},
        {Imf::RLE_COMPRESSION, "rle", true},    {Imf::PXR24_COMPRESSION, "pxr24", false},
        {Imf::B44_COMPRESSION, "b44", true},    {Imf::B44A_COMPRESSION, "b44a", true},
        {Imf::DWAA_COMPRESSION, "dwaa", false}, {Imf::DWAB_COMPRESSION, "dwab", false}};
    for (const Codec& codec : codecs) {
        const std::string path = codec.c == Imf::ZIP_COMPRESSION ? zipPath : rewritten(codec);
        for (int threads : {1, 2}) {
            const std::string what = std::string(codec.name) + ", " + std::to_string(threads) +
                                     " thread" + (threads > 1 ? "s" : "");
            StatsImage got = readWholeAndBlocks(path, threads, 7);
            expectEqualsCppRead(got, path, what);
            if (codec.lossless) {
                EXPECT_TRUE(bitEqual(got.bufferMean, img.bufferMean)) << what;
                EXPECT_TRUE(bitEqual(got.aov, img.aov)) << what;
                EXPECT_TRUE(bitEqual(got.variance, img.variance)) << what;
                EXPECT_TRUE(bitEqual(got.position, img.position)) << what;
            }
        }
    }
}

TEST_F(CoreIo, OnlySomePartsAndBlocksOfWholeChunks) {
    StatsFileReader reader;
    std::string err;
    ASSERT_TRUE(reader.open(zipPath, err, ReadLimits(), 2)) << err;
    EXPECT_EQ(reader.chunkRows(), 16);
    StatsImage block;
    ASSERT_TRUE(reader.read(16, 32, kStatsPartBuffers, block, err)) << err;
    const size_t from = size_t(16) * 37 * 9, n = size_t(32) * 37 * 9;
    ASSERT_EQ(block.bufferMean.size(), n);
    EXPECT_EQ(0, std::memcmp(block.bufferMean.data(), img.bufferMean.data() + from, n * 4));
    EXPECT_TRUE(block.beauty.empty());
    EXPECT_TRUE(block.aov.empty());
}

/// The chunk of part `part` that holds row `y`: where its data start and how many bytes.
exr_chunk_info_t chunkOf(const std::string& path, int part, int y) {
    exr_context_t ctxt = nullptr;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_chunk_info_t ci{};
    if (exr_start_read(&ctxt, path.c_str(), &init) != EXR_ERR_SUCCESS ||
        exr_read_scanline_chunk_info(ctxt, part, y, &ci) != EXR_ERR_SUCCESS)
        ADD_FAILURE() << "no chunk info";
    exr_finish(&ctxt);
    return ci;
}

/// Reads `path` whole on `threads` threads and returns the error (failing if it was accepted).
std::string readError(const std::string& path, int threads) {
    StatsFileReader reader;
    std::string err;
    if (!reader.open(path, err, ReadLimits(), threads)) return err;
    StatsImage out;
    EXPECT_FALSE(reader.read(0, reader.header().height, kStatsAllParts, out, err))
        << "accepted a damaged chunk";
    return err;
}

TEST_F(CoreIo, CorruptZipChunkIsAOneLineErrorNamingTheFile) {
    const exr_chunk_info_t ci = chunkOf(zipPath, 1, 16);  // part buffers, rows 16..31
    ASSERT_GT(ci.packed_size, 64u);
    ASSERT_LT(ci.packed_size, ci.unpacked_size) << "the chunk is stored, not compressed";
    std::vector<unsigned char> bytes = readBytes(zipPath);
    for (uint64_t i = ci.data_offset + ci.packed_size / 2; i < ci.data_offset + ci.packed_size; ++i)
        bytes[size_t(i)] ^= 0x5a;
    const std::string bad = dir.file("corrupt.mcstat");
    writeBytes(bad, bytes);
    const std::string one = readError(bad, 1), two = readError(bad, 2);
    EXPECT_EQ(one, two) << "the error depends on the thread count";
    EXPECT_EQ(
        one.rfind(bad + ": truncated or corrupt (part 'buffers': the chunk of rows 16..31: ", 0),
        0u)
        << one;
    EXPECT_TRUE(contains(one, "ZIP data")) << one;
    EXPECT_EQ(one.find('\n'), std::string::npos) << one;
}

TEST_F(CoreIo, ShortZipChunkIsAnError) {
    // The chunk's size field says fewer bytes than its data: inflating stops short.
    const exr_chunk_info_t ci = chunkOf(zipPath, 3, 32);  // part features, rows 32..47
    ASSERT_LT(ci.packed_size, ci.unpacked_size);
    std::vector<unsigned char> bytes = readBytes(zipPath);
    const uint32_t shorter = uint32_t(ci.packed_size / 2);
    for (int b = 0; b < 4; ++b)
        bytes[size_t(ci.data_offset) - 4 + size_t(b)] =
            (unsigned char)((shorter >> (8 * b)) & 0xff);
    const std::string bad = dir.file("short.mcstat");
    writeBytes(bad, bytes);
    for (int threads : {1, 2}) {
        const std::string err = readError(bad, threads);
        EXPECT_EQ(err.rfind(bad + ": truncated or corrupt (part 'features': the chunk of rows "
                                  "32..47: ",
                            0),
                  0u)
            << err;
        EXPECT_EQ(err.find('\n'), std::string::npos) << err;
    }
}

TEST_F(CoreIo, TwoDamagedChunksReportTheSameOneWhateverTheThreads) {
    std::vector<unsigned char> bytes = readBytes(zipPath);
    for (int y : {0, 48}) {
        const exr_chunk_info_t ci = chunkOf(zipPath, 1, y);
        for (uint64_t i = ci.data_offset + 2; i < ci.data_offset + ci.packed_size; i += 3)
            bytes[size_t(i)] ^= 0xff;
    }
    const std::string bad = dir.file("two.mcstat");
    writeBytes(bad, bytes);
    const std::string one = readError(bad, 1);
    EXPECT_TRUE(contains(one, "part 'buffers': the chunk of rows ")) << one;
    for (int i = 0; i < 4; ++i) EXPECT_EQ(readError(bad, 2), one);
}

// ---- writing ------------------------------------------------------------------------------------

TEST_F(CoreIo, WrittenBytesAreTheSameWhateverTheBlocksAndThreads) {
    // zipPath is writeStatsFile's (the whole image at once, straight into the file); streamed
    // writes go through the spill file and the staging of rows that do not fill a chunk.
    const std::vector<unsigned char> whole = readBytes(zipPath);
    const std::pair<int, int> runs[] = {{7, 1}, {7, 2}, {16, 2}, {40, 1}, {53, 2}, {1, 2}};
    for (const auto& [rows, threads] : runs) {
        const std::string path = dir.file("blocks.mcstat");
        writeByBlocks(path, img, rows, threads);
        EXPECT_TRUE(readBytes(path) == whole) << rows << " rows a block, " << threads << " threads";
    }
}

TEST_F(CoreIo, WrittenZipIsStandardOpenExr) {
    // Every part says ZIP and holds compressed chunks; OpenEXR's C++ API reads the image's bits;
    // its file checker (exrcheck's engine, every read path, the Core's included) finds nothing.
    expectEqualsCppRead(img, zipPath, "written");
    for (const RawPart& p : readRaw(zipPath))
        EXPECT_EQ(p.header.compression(), Imf::ZIP_COMPRESSION) << p.header.name();
    const exr_chunk_info_t ci = chunkOf(zipPath, 1, 0);
    EXPECT_LT(ci.packed_size, ci.unpacked_size);
    EXPECT_FALSE(Imf::checkOpenEXRFile(zipPath.c_str(), false, false, true));
    EXPECT_FALSE(Imf::checkOpenEXRFile(zipPath.c_str(), false, false, false));
}

TEST_F(CoreIo, StockOiiotoolReadsTheWrittenFile) {
    const std::string oiiotool = MCSTAT_OIIOTOOL;
    if (oiiotool.empty()) GTEST_SKIP() << "no oiiotool";
    // Named .exr, so that OIIO's own OpenEXR reader opens it (not mcstat's plugin).
    const std::string exr = dir.file("stats.exr"), out = dir.file("buffers.exr");
    std::filesystem::copy_file(zipPath, exr);
    const std::string cmd =
        oiiotool + " '" + exr + "' --subimage buffers -d float -o '" + out + "' 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
    const std::vector<RawPart> parts = readRaw(out);
    ASSERT_EQ(parts.size(), 1u);
    const auto mine = channelsOf(img);
    const auto& buffers = mine.at("buffers");
    ASSERT_EQ(parts[0].values.size(), buffers.size());
    for (const auto& [name, values] : parts[0].values) {
        ASSERT_TRUE(buffers.count(name)) << name;
        EXPECT_TRUE(bitEqual(values, buffers.at(name))) << name;
    }
}

TEST_F(CoreIo, ABadCountIsRefusedByTheWholeWriteAndInAStreamedBlock) {
    // writeStatsFile checks its image once, before the writer opens; a block handed to the
    // streaming writer is still checked by the writer.
    img.bufferCount[1] = -1.f;  // the first pixel's buffer 1
    const std::string path = dir.file("bad.mcstat");
    std::string err;
    EXPECT_FALSE(writeStatsFile(path, img, err));
    EXPECT_NE(err.find("buffer 1 count is negative"), std::string::npos) << err;
    EXPECT_FALSE(std::filesystem::exists(path));
    {
        StatsFileWriter w;
        ASSERT_TRUE(w.open(path, img.header, err)) << err;
        err.clear();
        EXPECT_FALSE(w.write(img, err));
        EXPECT_NE(err.find("buffer 1 count is negative"), std::string::npos) << err;
        EXPECT_FALSE(w.commit(err));
    }
    EXPECT_FALSE(std::filesystem::exists(path));
}

TEST_F(CoreIo, AChunkZipCannotShrinkIsStoredAsItIs) {
    // Random bits in the beauty: its chunks do not compress, so they are stored (packed size ==
    // unpacked size, which readers take as uncompressed); they still read back bit for bit.
    std::mt19937 rng(5);
    for (float& v : img.beauty) {
        uint32_t u = rng();
        std::memcpy(&v, &u, sizeof v);
    }
    const std::string path = dir.file("noise.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    const exr_chunk_info_t ci = chunkOf(path, 0, 0);
    EXPECT_EQ(ci.packed_size, ci.unpacked_size);
    expectEqualsCppRead(img, path, "noise");
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    EXPECT_TRUE(bitEqual(back.beauty, img.beauty));
    EXPECT_TRUE(bitEqual(back.bufferMean, img.bufferMean));
}

}  // namespace
}  // namespace mcstat::test
