// Invalid files, each built directly with the OpenEXR C++ API: the reader must refuse them with a
// one-line message that starts with the path and names the problem.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfTileDescriptionAttribute.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <limits>

#include "mcstat/exr-deep/stats_file.h"
#include "raw_exr.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

/// Removes attribute `name` from `h`. Imf::Header::erase and Header's move assignment of
/// OpenEXR 3.1 leak attributes (the sanitizer build reports it), so `h` is rebuilt and copied.
void eraseAttribute(Imf::Header& h, const char* name) {
    Imf::Header out;
    for (auto it = h.begin(); it != h.end(); ++it)
        if (std::strcmp(it.name(), name) != 0) out.insert(it.name(), it.attribute());
    const Imf::Header& copy = out;
    h = copy;
}

class Corrupt : public testing::Test {
  protected:
    void SetUp() override {
        img = renderImage(5, 4, 3, 21, [](int x, int y) { return 2 + (x + y) % 4; });
        parts = rawPartsFrom(img);
        path = dir.file("bad.mcstat");
    }
    /// Writes `parts`, checks that the library's own write of `img` would be readable, and returns
    /// the reader's message for the raw file (failing the test if it was accepted).
    std::string readError() {
        writeRaw(path, parts);
        StatsImage out;
        std::string err;
        EXPECT_FALSE(readStatsFile(path, out, err)) << "accepted an invalid file";
        EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
        EXPECT_EQ(err.find('\n'), std::string::npos) << err;
        EXPECT_TRUE(out.count.empty()) << "output touched on failure";
        // The header-only read agrees whenever the problem lies in the headers.
        StatsHeader hdr;
        std::string herr;
        if (!readStatsHeader(path, hdr, herr)) {
            EXPECT_EQ(herr, err);
        }
        return err;
    }
    RawPart& part(const char* name) {
        for (RawPart& p : parts)
            if (p.header.name() == name) return p;
        throw std::runtime_error(name);
    }

    ScratchDir dir;
    StatsImage img;
    std::vector<RawPart> parts;
    std::string path;
};

TEST_F(Corrupt, RawLayoutOfTheTestIsValid) {
    // Guards the fixture: the untouched raw parts read back as the image.
    writeRaw(path, parts);
    StatsImage out;
    std::string err;
    ASSERT_TRUE(readStatsFile(path, out, err)) << err;
    EXPECT_EQ(out.bufferMean, img.bufferMean);
    EXPECT_EQ(out.variance, img.variance);
    EXPECT_EQ(out.coverage, img.coverage);
}

TEST_F(Corrupt, MissingPart) {
    parts.pop_back();
    EXPECT_TRUE(contains(readError(), "missing part 'features'"));
}

TEST_F(Corrupt, MissingMiddlePart) {
    parts.erase(parts.begin() + 1);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 1 is named 'moments', expected 'buffers'")) << err;
}

TEST_F(Corrupt, ExtraPart) {
    RawPart extra = parts[2];
    extra.header.setName("extra");
    parts.push_back(extra);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "extra part 'extra'")) << err;
}

TEST_F(Corrupt, WrongPartName) {
    part("buffers").header.setName("buffer");
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 1 is named 'buffer', expected 'buffers'")) << err;
}

TEST_F(Corrupt, HalfChannel) {
    part("moments").header.channels()["mean.G"].type = Imf::HALF;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'moments': channel 'mean.G' has wrong type HALF")) << err;
}

TEST_F(Corrupt, MissingChannel) {
    Imf::ChannelList fewer;
    for (auto it = part("moments").header.channels().begin();
         it != part("moments").header.channels().end(); ++it)
        if (std::strcmp(it.name(), "variance.B") != 0) fewer.insert(it.name(), it.channel());
    part("moments").header.channels() = fewer;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'moments': missing channel 'variance.B'")) << err;
}

TEST_F(Corrupt, ExtraChannel) {
    part("features").header.channels().insert("Ns.X", Imf::Channel(Imf::FLOAT));
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'features': unexpected channel 'Ns.X'")) << err;
}

TEST_F(Corrupt, DeepPart) {
    RawPart& f = part("features");
    f.header.setType(Imf::DEEPSCANLINE);
    f.header.compression() = Imf::ZIPS_COMPRESSION;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'features' is a deep scanline image")) << err;
}

TEST_F(Corrupt, TiledPart) {
    RawPart& b = part("beauty");
    b.header.setType(Imf::TILEDIMAGE);
    b.header.setTileDescription(Imf::TileDescription(4, 4, Imf::ONE_LEVEL));
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'beauty' is a tiled image")) << err;
}

TEST_F(Corrupt, DimensionMismatch) {
    RawPart& m = part("moments");
    m.header.dataWindow() = Imath::Box2i(Imath::V2i(0, 0), Imath::V2i(4, 2));
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "dimension mismatch")) << err;
    EXPECT_TRUE(contains(err, "'moments'") && contains(err, "'beauty'")) << err;
    EXPECT_TRUE(contains(err, "(0,0)-(4,2)") && contains(err, "(0,0)-(4,3)")) << err;
}

TEST_F(Corrupt, MMismatch) {
    part("moments").header.insert("mcstat:M", Imf::IntAttribute(4));
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "M mismatch: part 'moments' has mcstat:M = 4, part 'beauty' has 3"))
        << err;
}

TEST_F(Corrupt, BadM) {
    setIntOnAll(parts, "mcstat:M", 0);
    EXPECT_TRUE(contains(readError(), "mcstat:M = 0 out of range 1..999"));
    setIntOnAll(parts, "mcstat:M", 1000);
    EXPECT_TRUE(contains(readError(), "mcstat:M = 1000 out of range 1..999"));
}

TEST_F(Corrupt, MDisagreesWithBufferChannels) {
    setIntOnAll(parts, "mcstat:M", 2);
    const std::string err = readError();
    EXPECT_TRUE(contains(err,
                         "part 'buffers' has 3 buffer channel groups (bNNN.count) but "
                         "mcstat:M = 2"))
        << err;
}

TEST_F(Corrupt, NewerVersion) {
    setIntOnAll(parts, "mcstat:formatVersion", kStatsFormatVersion + 1);
    RawPart modes = parts[0];  // a later version adds parts
    modes.header.setName("modes");
    parts.push_back(modes);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "written by a newer mcstat (format " +
                                  std::to_string(kStatsFormatVersion + 1) +
                                  "); this reader knows " + std::to_string(kStatsFormatVersion)))
        << err;
}

TEST_F(Corrupt, OlderOrZeroVersion) {
    setIntOnAll(parts, "mcstat:formatVersion", 0);
    EXPECT_TRUE(contains(readError(), "unsupported mcstat:formatVersion 0"));
}

TEST_F(Corrupt, MissingAttribute) {
    eraseAttribute(part("features").header, "mcstat:seeds");
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'features': missing attribute 'mcstat:seeds'")) << err;
}

TEST_F(Corrupt, AttributeOfWrongType) {
    eraseAttribute(part("buffers").header, "mcstat:spp");
    part("buffers").header.insert("mcstat:spp", Imf::StringAttribute("64"));
    const std::string err = readError();
    EXPECT_TRUE(
        contains(err, "part 'buffers': attribute 'mcstat:spp' has type string, expected int"))
        << err;
}

TEST_F(Corrupt, AttributeDiffersBetweenParts) {
    part("features").header.insert("mcstat:colorSpace", Imf::StringAttribute("ACEScg"));
    const std::string err = readError();
    EXPECT_TRUE(contains(err,
                         "part 'features' has mcstat:colorSpace = 'ACEScg', part 'beauty' has "
                         "'lin_rec709'"))
        << err;
}

TEST_F(Corrupt, UnknownAssignment) {
    for (RawPart& p : parts) p.header.insert("mcstat:assignment", Imf::StringAttribute("random"));
    EXPECT_TRUE(contains(readError(), "mcstat:assignment: unknown sample assignment 'random'"));
    // Least count exists only with adaptive M (buffers that grew during the render).
    for (RawPart& p : parts)
        p.header.insert("mcstat:assignment", Imf::StringAttribute("leastcount"));
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "mcstat:assignment: sample assignment 'leastcount' needs adaptive M"))
        << err;
}

// Pixel (x, y) = index y * 5 + x of the 5x4 image.
TEST_F(Corrupt, NegativeCount) {
    part("buffers").values["b002.count"][1 * 5 + 3] = -1.f;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "pixel (3, 1): buffer 2 count is negative")) << err;
}

TEST_F(Corrupt, NanCount) {
    part("moments").values["count"][2 * 5 + 4] = std::numeric_limits<float>::quiet_NaN();
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "pixel (4, 2): moments count is NaN")) << err;
}

TEST_F(Corrupt, NonIntegralCount) {
    part("buffers").values["b000.count"][0] = 0.5f;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "pixel (0, 0): buffer 0 count is not an integer")) << err;
}

TEST_F(Corrupt, BufferCountsNotSummingToCount) {
    part("moments").values["count"][3 * 5 + 2] += 1.f;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "pixel (2, 3): buffer counts sum to")) << err;
}

TEST_F(Corrupt, NotAnExrFile) {
    writeBytes(path, {'h', 'e', 'l', 'l', 'o', ' ', 'w', 'o', 'r', 'l', 'd', '\n'});
    StatsImage out;
    std::string err;
    EXPECT_FALSE(readStatsFile(path, out, err));
    EXPECT_EQ(err, path + ": not an OpenEXR file");
}

TEST_F(Corrupt, EmptyFile) {
    writeBytes(path, {});
    StatsImage out;
    std::string err;
    EXPECT_FALSE(readStatsFile(path, out, err));
    EXPECT_EQ(err, path + ": not an OpenEXR file (empty file)");
}

TEST_F(Corrupt, NonexistentFileAndDirectory) {
    StatsImage out;
    std::string err;
    const std::string missing = dir.file("nope.mcstat");
    EXPECT_FALSE(readStatsFile(missing, out, err));
    EXPECT_EQ(err, missing + ": cannot open (No such file or directory)");
    StatsHeader hdr;
    EXPECT_FALSE(readStatsHeader(missing, hdr, err));
    EXPECT_EQ(err, missing + ": cannot open (No such file or directory)");
    EXPECT_FALSE(readStatsFile(dir.path().string(), out, err));
    EXPECT_EQ(err, dir.path().string() + ": not a regular file");
}

TEST_F(Corrupt, TruncatedAtManyOffsets) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    const std::vector<unsigned char> bytes = readBytes(path);
    ASSERT_GT(bytes.size(), 1000u);
    const std::string cut = dir.file("cut.mcstat");
    std::vector<size_t> offsets = {1, 3, 4, 7, 8, 50, 300, 1000};
    for (size_t k = 1; k < 16; ++k) offsets.push_back(bytes.size() * k / 16);
    for (size_t back : {1, 2, 8, 100}) offsets.push_back(bytes.size() - back);
    for (size_t n : offsets) {
        writeBytes(cut, std::vector<unsigned char>(bytes.begin(), bytes.begin() + long(n)));
        StatsImage out;
        EXPECT_FALSE(readStatsFile(cut, out, err)) << "cut at " << n;
        EXPECT_EQ(err.rfind(cut + ": ", 0), 0u) << err;
        if (n < 4) {
            EXPECT_EQ(err, cut + ": not an OpenEXR file") << "cut at " << n;
        } else {
            EXPECT_TRUE(contains(err, ": truncated or corrupt (")) << "cut at " << n << ": " << err;
        }
    }
}

/// Overwrites the box2i value of every `name` attribute in an EXR byte image.
void patchBox(std::vector<unsigned char>& bytes, const std::string& name, int32_t maxX,
              int32_t maxY) {
    const std::string key = name + std::string(1, '\0') + "box2i" + std::string(1, '\0');
    int found = 0;
    for (size_t i = 0; i + key.size() + 20 <= bytes.size(); ++i) {
        if (std::memcmp(bytes.data() + i, key.data(), key.size()) != 0) continue;
        unsigned char* v = bytes.data() + i + key.size() + 4;  // after the int32 size (16)
        std::memcpy(v + 8, &maxX, 4);                          // little endian on this machine
        std::memcpy(v + 12, &maxY, 4);
        ++found;
    }
    ASSERT_EQ(found, 4) << name;
}

TEST_F(Corrupt, AbsurdSizeIsRejectedWithoutAllocating) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    std::vector<unsigned char> bytes = readBytes(path);
    // (2^30 - 1) x (2^30 - 1) pixels: OpenEXR's Core refuses window coordinates >= 2^30 - 1 itself.
    const int32_t big = (int32_t(1) << 30) - 2;
    patchBox(bytes, "dataWindow", big, big);
    writeBytes(path, bytes);
    StatsImage out;
    EXPECT_FALSE(readStatsFile(path, out, err));
    EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
    EXPECT_TRUE(contains(err, "image size 1073741823x1073741823")) << err;
    EXPECT_TRUE(contains(err, "exceeds the limit")) << err;
    // Generous limits still stop at the byte limit before allocating.
    ReadLimits limits;
    limits.maxPixels = std::numeric_limits<int64_t>::max();
    EXPECT_FALSE(readStatsFile(path, out, err, limits));
    EXPECT_TRUE(contains(err, "bytes, exceeding the limit")) << err;

    // A full 2^30 x 2^30 window is refused by OpenEXR's header parser already.
    bytes = readBytes(path);
    patchBox(bytes, "dataWindow", (int32_t(1) << 30) - 1, (int32_t(1) << 30) - 1);
    writeBytes(path, bytes);
    EXPECT_FALSE(readStatsFile(path, out, err, limits));
    EXPECT_EQ(err, path +
                       ": truncated or corrupt (header: Invalid data window (0, 0 - 1073741823, "
                       "1073741823))");
}

/// Reads `path` expecting a rejection that mentions `what`; the message is one line naming the
/// file, and it comes from the headers (readStatsHeader gives the same), so nothing the claim
/// sized was allocated.
void expectHeaderRejection(const std::string& path, const std::string& what) {
    StatsImage out;
    std::string err, herr;
    EXPECT_FALSE(readStatsFile(path, out, err));
    EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
    EXPECT_EQ(err.find('\n'), std::string::npos) << err;
    EXPECT_TRUE(contains(err, what)) << err;
    EXPECT_TRUE(out.count.empty() && out.bufferMean.empty());
    StatsHeader hdr;
    EXPECT_FALSE(readStatsHeader(path, hdr, herr));
    EXPECT_EQ(herr, err);
    StatsFileReader reader;
    EXPECT_FALSE(reader.open(path, herr));
    EXPECT_EQ(herr, err);
}

// A 52 KB file claiming 24 x 1,000,001 pixels cost 5.1 GB before it failed. The chunk
// offset table cannot point inside the file for rows it does not hold.
TEST_F(Corrupt, TallClaimOfASmallFileIsRejectedBeforeAllocating) {
    img = renderImage(24, 16, 3, 5, [](int x, int y) { return 1 + (x + y) % 3; });
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    std::vector<unsigned char> bytes = readBytes(path);
    patchBox(bytes, "dataWindow", 23, 1000000);
    writeBytes(path, bytes);
    expectHeaderRejection(
        path, "no valid offset within the file's " + std::to_string(bytes.size()) + " bytes");
}

// As wide as the pixel limit allows but still one chunk per 16 rows: every offset is valid, so
// it is the codec's ratio that gives the claim away (a ZIP chunk of a few hundred bytes cannot
// hold 16 x 10^6 pixels).
TEST_F(Corrupt, WideClaimBeyondTheCodecsRatioIsRejectedBeforeAllocating) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    std::vector<unsigned char> bytes = readBytes(path);
    patchBox(bytes, "dataWindow", 999999, 3);
    writeBytes(path, bytes);
    expectHeaderRejection(path, "more than ZIP compression gives (1040:1)");
}

// Found by fuzzing (tests/fuzz/regressions): a string attribute claiming 1.8 GB in a 10 KB file.
// OpenEXR's C++ reader allocates the claimed size before reading; the reader checks it first.
TEST_F(Corrupt, AttributeSizeBeyondTheFileIsRejectedBeforeAllocating) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    std::vector<unsigned char> bytes = readBytes(path);
    const std::string key = std::string("mcstat:renderer") + '\0' + "string" + '\0';
    const auto at = std::search(bytes.begin(), bytes.end(), key.begin(), key.end());
    ASSERT_NE(at, bytes.end());
    const int32_t claim = 1828745984;
    std::memcpy(&*(at + std::ptrdiff_t(key.size())), &claim, 4);  // little endian here
    writeBytes(path, bytes);
    expectHeaderRejection(path, "attribute 'mcstat:renderer' claims 1828745984 bytes");
}

}  // namespace
}  // namespace mcstat::test
