// Adaptive M (format version 2, FORMAT.md "Adaptive M"): the in-memory view, the deep part
// "vbuffers" written and read back, corrupt deep files, limits and merge.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCheckFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfPartType.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <random>

#include "mcstat/exr-deep/stats_file.h"
#include "raw_exr.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

/// m_p in {1, 3, 5, 17} by position, spp 0..9 (some buffers empty, some pixels without samples).
StatsImage sampleAdaptive(int w = 7, int h = 5, int ox = 0, int oy = 0) {
    return adaptiveImage(
        w, h, 17, 3,
        [](int x, int y) {
            static const int ms[4] = {1, 3, 5, 17};
            return ms[(x * 3 + y) % 4];
        },
        [](int x, int y) { return (x * 7 + y * 5) % 10; }, ox, oy);
}

bool sameBits(const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() &&
           (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

void expectSameImage(const StatsImage& a, const StatsImage& b) {
    EXPECT_EQ(a.header.formatVersion, b.header.formatVersion);
    EXPECT_EQ(a.header.adaptiveM, b.header.adaptiveM);
    EXPECT_EQ(a.header.M, b.header.M);
    EXPECT_EQ(a.header.width, b.header.width);
    EXPECT_EQ(a.header.height, b.header.height);
    EXPECT_EQ(a.header.originX, b.header.originX);
    EXPECT_EQ(a.header.originY, b.header.originY);
    EXPECT_EQ(a.header.spp, b.header.spp);
    EXPECT_EQ(a.header.seeds, b.header.seeds);
    EXPECT_EQ(a.bufferOffset, b.bufferOffset);
    EXPECT_TRUE(sameBits(a.bufferMean, b.bufferMean));
    EXPECT_TRUE(sameBits(a.bufferCount, b.bufferCount));
    EXPECT_TRUE(sameBits(a.beauty, b.beauty));
    EXPECT_TRUE(sameBits(a.count, b.count));
    EXPECT_TRUE(sameBits(a.mean, b.mean));
    EXPECT_TRUE(sameBits(a.variance, b.variance));
    EXPECT_TRUE(sameBits(a.normal, b.normal));
    EXPECT_TRUE(sameBits(a.position, b.position));
    EXPECT_TRUE(sameBits(a.albedo, b.albedo));
    EXPECT_TRUE(sameBits(a.depth, b.depth));
    EXPECT_TRUE(sameBits(a.coverage, b.coverage));
}

// ---- the in-memory view ---------------------------------------------------------------------

TEST(AdaptiveView, PixelBuffersOfFixedMIsTheOldIndexing) {
    const StatsImage img = renderImage(4, 3, 5, 9, [](int x, int) { return 3 + x; });
    for (size_t p = 0; p < img.pixelCount(); ++p) {
        const PixelBuffers b = img.pixelBuffers(p);
        EXPECT_EQ(b.M, 5);
        EXPECT_EQ(b.mean, img.bufferMean.data() + p * 5 * 3);
        EXPECT_EQ(b.count, img.bufferCount.data() + p * 5);
    }
}

TEST(AdaptiveView, OffsetsCountsAndPointers) {
    StatsImage img;
    img.header.width = 3;
    img.header.height = 2;
    img.header.M = 7;
    img.header.formatVersion = 2;
    std::string err;
    ASSERT_TRUE(img.allocateAdaptive({1, 3, 7, 1, 5, 1}, err)) << err;
    EXPECT_TRUE(img.header.adaptiveM);
    EXPECT_EQ(img.bufferOffset, (std::vector<uint64_t>{0, 1, 4, 11, 12, 17, 18}));
    EXPECT_EQ(img.bufferCount.size(), 18u);
    EXPECT_EQ(img.bufferMean.size(), 54u);
    EXPECT_EQ(img.count.size(), 6u);
    EXPECT_EQ(img.buffersOf(2), 7);
    const PixelBuffers b = img.pixelBuffers(4);
    EXPECT_EQ(b.M, 5);
    EXPECT_EQ(b.mean, img.bufferMean.data() + 12 * 3);
    EXPECT_EQ(b.count, img.bufferCount.data() + 12);
    EXPECT_TRUE(validateStats(img, "fresh", err)) << err;
}

TEST(AdaptiveView, AllocateRejectsBadCountsAndVersionAndLeavesImageUntouched) {
    StatsImage img;
    img.header.width = 2;
    img.header.height = 1;
    img.header.M = 5;
    img.header.formatVersion = 2;
    std::string err;
    ASSERT_TRUE(img.allocateAdaptive({1, 5}, err)) << err;
    const std::vector<uint64_t> before = img.bufferOffset;
    EXPECT_FALSE(img.allocateAdaptive({0, 5}, err));
    EXPECT_TRUE(contains(err, "pixel (0, 0) has 0 buffers, outside 1..5")) << err;
    EXPECT_FALSE(img.allocateAdaptive({1, 6}, err));
    EXPECT_TRUE(contains(err, "pixel (1, 0) has 6 buffers")) << err;
    EXPECT_FALSE(img.allocateAdaptive({1}, err));
    EXPECT_TRUE(contains(err, "1 buffer counts given for 2 pixels")) << err;
    EXPECT_EQ(img.bufferOffset, before);
    img.header.formatVersion = 1;
    EXPECT_FALSE(img.allocateAdaptive({1, 1}, err));
    EXPECT_TRUE(contains(err, "adaptive M needs format version 2")) << err;
    // allocate() is for fixed M only.
    img.header.formatVersion = 2;
    EXPECT_FALSE(img.allocate(err));
    EXPECT_TRUE(contains(err, "allocateAdaptive")) << err;
}

TEST(AdaptiveView, ValidateChecksOffsetsAndCounts) {
    StatsImage img = sampleAdaptive();
    std::string err;
    ASSERT_TRUE(validateStats(img, "img", err)) << err;

    StatsImage bad = img;
    bad.bufferOffset[3] = bad.bufferOffset[2];  // pixel 2 with 0 buffers
    EXPECT_FALSE(validateStats(bad, "img", err));
    EXPECT_TRUE(contains(err, "img: pixel (2, 0) has 0 sub-buffers, outside 1..17")) << err;

    bad = img;
    bad.bufferOffset.pop_back();
    EXPECT_FALSE(validateStats(bad, "img", err));
    EXPECT_TRUE(contains(err, "buffer offsets")) << err;

    bad = img;
    bad.bufferCount.pop_back();
    EXPECT_FALSE(validateStats(bad, "img", err));
    EXPECT_TRUE(contains(err, "sub-buffer arrays hold")) << err;

    bad = img;           // one more sample in a buffer than the moments count
    const size_t p = 5;  // pixel (5, 0): 17 buffers, 5 samples
    ASSERT_EQ(img.buffersOf(p), 17);
    ASSERT_EQ(img.count[p], 5.f);
    bad.bufferCount[bad.bufferBegin(p)] += 1.f;
    EXPECT_FALSE(validateStats(bad, "img", err));
    EXPECT_TRUE(contains(err, "img: pixel (5, 0): buffer counts sum to")) << err;

    bad = img;
    bad.bufferCount[bad.bufferBegin(p) + 0] = std::numeric_limits<float>::quiet_NaN();
    EXPECT_FALSE(validateStats(bad, "img", err));
    EXPECT_TRUE(contains(err, "buffer 0 count is NaN")) << err;

    bad = img;  // declared fixed M, arrays of adaptive M
    bad.header.adaptiveM = false;
    EXPECT_FALSE(validateStats(bad, "img", err));
    EXPECT_TRUE(contains(err, "of part 'buffers' holds")) << err;
    bad = renderImage(2, 2, 3, 1, [](int, int) { return 1; });  // fixed M with offsets left over
    bad.bufferOffset = {0, 3, 6, 9, 12};
    EXPECT_FALSE(validateStats(bad, "img", err));
    EXPECT_TRUE(contains(err, "img: fixed M but 5 buffer offsets")) << err;
}

// ---- files ----------------------------------------------------------------------------------

TEST(AdaptiveFile, RoundTripIsBitExact) {
    ScratchDir dir;
    for (auto [ox, oy] : {std::pair{0, 0}, std::pair{-3, 11}}) {
        const StatsImage img = sampleAdaptive(7, 5, ox, oy);
        const std::string path = dir.file("a.mcstat");
        std::string err;
        ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
        StatsImage back;
        ASSERT_TRUE(readStatsFile(path, back, err)) << err;
        expectSameImage(img, back);
        StatsHeader hdr;
        ASSERT_TRUE(readStatsHeader(path, hdr, err)) << err;
        EXPECT_TRUE(hdr.adaptiveM);
        EXPECT_EQ(hdr.formatVersion, 2);
        EXPECT_EQ(hdr.M, 17);
    }
}

TEST(AdaptiveFile, LeastCountAssignmentRoundTrips) {
    // Buffers grown during the render (mcstat-render --m-strategy grow) record "leastcount".
    ScratchDir dir;
    StatsImage img = sampleAdaptive();
    img.header.assignment = "leastcount";
    const std::string path = dir.file("grown.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    expectSameImage(img, back);
    EXPECT_EQ(back.header.assignment, "leastcount");
}

TEST(AdaptiveFile, RawLayoutFromTheSpecReadsBack) {
    // The deep part written independently of the library (raw_exr.cpp), as FORMAT.md describes it.
    ScratchDir dir;
    const StatsImage img = sampleAdaptive();
    const std::string path = dir.file("raw.mcstat");
    writeRaw(path, rawAdaptivePartsFrom(img));
    StatsImage back;
    std::string err;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    expectSameImage(img, back);
}

TEST(AdaptiveFile, FixedMInVersion2ReadsAndVersion1IsUnchanged) {
    ScratchDir dir;
    StatsImage img = renderImage(4, 3, 3, 5, [](int, int) { return 4; });
    std::string err;
    const std::string v1 = dir.file("v1.mcstat"), v2 = dir.file("v2.mcstat");
    ASSERT_TRUE(writeStatsFile(v1, img, err)) << err;
    img.header.formatVersion = 2;  // fixed M written as version 2: mcstat:adaptiveM = 0
    ASSERT_TRUE(writeStatsFile(v2, img, err)) << err;
    StatsImage a, b;
    ASSERT_TRUE(readStatsFile(v1, a, err)) << err;
    ASSERT_TRUE(readStatsFile(v2, b, err)) << err;
    EXPECT_EQ(a.header.formatVersion, 1);
    EXPECT_EQ(b.header.formatVersion, 2);
    EXPECT_FALSE(b.header.adaptiveM);
    EXPECT_TRUE(sameBits(a.bufferMean, b.bufferMean));
    EXPECT_TRUE(b.bufferOffset.empty());
}

TEST(AdaptiveFile, LimitsOnDeepSamplesAndBytes) {
    ScratchDir dir;
    const StatsImage img = sampleAdaptive();
    const std::string path = dir.file("a.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    const int64_t total = int64_t(img.bufferCount.size());
    StatsImage back;
    ReadLimits lim;
    lim.maxDeepSamples = total;  // exactly enough
    ASSERT_TRUE(readStatsFile(path, back, err, lim)) << err;
    lim.maxDeepSamples = total - 1;
    StatsImage none;
    EXPECT_FALSE(readStatsFile(path, none, err, lim));
    EXPECT_TRUE(contains(err, "part 'vbuffers' holds " + std::to_string(total) + " sub-buffers"))
        << err;
    EXPECT_TRUE(none.count.empty());
    // The byte limit: fixed per-pixel floats (21) and offset (8 bytes) plus 16 bytes per buffer.
    const int64_t bytes = int64_t(img.pixelCount()) * (21 * 4 + 8) + total * 16;
    lim = ReadLimits();
    lim.maxBytes = bytes;
    ASSERT_TRUE(readStatsFile(path, back, err, lim)) << err;
    lim.maxBytes = bytes - 1;
    EXPECT_FALSE(readStatsFile(path, none, err, lim));
    EXPECT_TRUE(contains(err, "exceeding the limit")) << err;
    // Headers alone: a row with at least one buffer per pixel must fit.
    lim.maxBytes = int64_t(img.header.width) * (25 * 4 + 8) - 1;
    StatsHeader hdr;
    EXPECT_FALSE(readStatsHeader(path, hdr, err, lim));
    EXPECT_TRUE(contains(err, "a row of image")) << err;
    EXPECT_TRUE(contains(err, "adaptive M, M_max = 17 needs at least")) << err;
}

TEST(AdaptiveFile, ExrToolsAcceptTheDeepPart) {
    ScratchDir dir;
    const std::string path = dir.file("a.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, sampleAdaptive(), err)) << err;
    // OpenEXR's exrcheck engine (both its C++ and its Core API paths): deep scanline parts need Z
    // and A to pass it. It returns true when it found a problem (its header comment says the
    // opposite; the truncated copy pins the meaning).
    EXPECT_FALSE(Imf::checkOpenEXRFile(path.c_str(), false, false, false));
    EXPECT_FALSE(Imf::checkOpenEXRFile(path.c_str(), false, false, true));
    std::vector<unsigned char> cut = readBytes(path);
    cut.resize(cut.size() / 2);
    writeBytes(dir.file("cut.mcstat"), cut);
    EXPECT_TRUE(Imf::checkOpenEXRFile(dir.file("cut.mcstat").c_str(), false, false, false));
    // exrinfo goes through the Core API, which needs "version" = 1 on every part of a deep file.
    if (::access("/usr/bin/exrinfo", X_OK) == 0) {
        const std::string cmd = "/usr/bin/exrinfo -v '" + path + "' > /dev/null 2>&1";
        EXPECT_EQ(std::system(cmd.c_str()), 0);
    }
}

// ---- corrupt deep files -----------------------------------------------------------------------

class AdaptiveCorrupt : public testing::Test {
  protected:
    void SetUp() override {
        img = sampleAdaptive(5, 4);
        parts = rawAdaptivePartsFrom(img);
        path = dir.file("bad.mcstat");
    }
    std::string readError() {
        writeRaw(path, parts);
        StatsImage out;
        std::string err;
        EXPECT_FALSE(readStatsFile(path, out, err)) << "accepted an invalid file";
        EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
        EXPECT_EQ(err.find('\n'), std::string::npos) << err;
        EXPECT_TRUE(out.count.empty()) << "output touched on failure";
        return err;
    }
    /// Index of pixel p's first sample in the raw deep part's value arrays.
    size_t firstSample(size_t p) const {
        size_t k = 0;
        for (size_t q = 0; q < p; ++q) k += parts[1].deepCounts[q];
        return k;
    }

    ScratchDir dir;
    StatsImage img;
    std::vector<RawPart> parts;
    std::string path;
};

TEST_F(AdaptiveCorrupt, FixtureIsValid) {
    writeRaw(path, parts);
    StatsImage out;
    std::string err;
    ASSERT_TRUE(readStatsFile(path, out, err)) << err;
    expectSameImage(img, out);
}

TEST_F(AdaptiveCorrupt, PixelWithoutBuffers) {
    // Drop pixel 6's samples (its counts sum to its moments count only if it had none: use the
    // sample-count rule, which is checked first, before anything is allocated).
    const size_t p = 6, k = firstSample(p), m = parts[1].deepCounts[p];
    for (auto& [name, v] : parts[1].values) v.erase(v.begin() + long(k), v.begin() + long(k + m));
    parts[1].deepCounts[p] = 0;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "pixel (1, 1): part 'vbuffers' holds 0 sub-buffers, outside 1..17"))
        << err;
}

TEST_F(AdaptiveCorrupt, MoreBuffersThanMMax) {
    setIntOnAll(parts, "mcstat:M", 4);  // pixels with 5 and 17 buffers exceed it
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "sub-buffers, outside 1..4 (mcstat:M)")) << err;
}

TEST_F(AdaptiveCorrupt, CountsDoNotSumToTheMoments) {
    size_t p = 0;
    while (img.count[p] == 0.f || img.buffersOf(p) < 2) ++p;
    const size_t k = firstSample(p);
    parts[1].values["count"][k] += 1.f;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "buffer counts sum to")) << err;
}

TEST_F(AdaptiveCorrupt, BadCountValues) {
    size_t p = 0;
    while (img.count[p] == 0.f) ++p;
    const size_t k = firstSample(p);
    for (auto [v, why] : {std::pair{std::numeric_limits<float>::quiet_NaN(), "is NaN"},
                          std::pair{-1.f, "is negative"}, std::pair{0.5f, "is not an integer"},
                          std::pair{std::numeric_limits<float>::infinity(), "is infinite"}}) {
        const float saved = parts[1].values["count"][k];
        parts[1].values["count"][k] = v;
        const std::string err = readError();
        EXPECT_TRUE(contains(err, std::string("buffer 0 count ") + why)) << err;
        parts[1].values["count"][k] = saved;
    }
}

TEST_F(AdaptiveCorrupt, DeepPartStoredFlat) {
    parts[1].header.setType(Imf::SCANLINEIMAGE);
    parts[1].deepCounts.clear();
    parts[1].values.clear();
    const std::string err = readError();
    EXPECT_TRUE(
        contains(err, "part 'vbuffers' is a scanline image, expected a deep scanline image"))
        << err;
}

TEST_F(AdaptiveCorrupt, FlatBuffersPartInAnAdaptiveFile) {
    parts[1].header.setName("buffers");
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 1 is named 'buffers', expected 'vbuffers'")) << err;
}

TEST_F(AdaptiveCorrupt, MissingAndExtraChannels) {
    {
        Imf::ChannelList ch;
        for (const char* c : {"R", "G", "B", "count", "A"}) ch.insert(c, Imf::Channel(Imf::FLOAT));
        parts[1].header.channels() = ch;
        const std::string err = readError();
        EXPECT_TRUE(contains(err, "part 'vbuffers': missing channel 'Z'")) << err;
    }
    {
        Imf::ChannelList ch;
        for (const char* c : {"R", "G", "B", "count", "Z", "A", "extra"})
            ch.insert(c, Imf::Channel(Imf::FLOAT));
        parts[1].header.channels() = ch;
        const std::string err = readError();
        EXPECT_TRUE(contains(err, "part 'vbuffers': unexpected channel 'extra'")) << err;
    }
}

TEST_F(AdaptiveCorrupt, AdaptiveAttributeMismatched) {
    parts[2].header.insert("mcstat:adaptiveM", Imf::IntAttribute(0));
    std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'moments' has mcstat:adaptiveM = '0', part 'beauty' has '1'"))
        << err;
    setIntOnAll(parts, "mcstat:adaptiveM", 0);  // part 0 no longer declares adaptive M
    err = readError();
    EXPECT_TRUE(contains(err, "part 1 is named 'vbuffers', expected 'buffers'")) << err;
}

TEST(AdaptiveCorruptFixed, Version2NeedsTheAdaptiveAttributeWithValue0Or1) {
    ScratchDir dir;
    const std::string path = dir.file("bad.mcstat");
    StatsImage img = renderImage(3, 2, 2, 1, [](int, int) { return 3; });
    img.header.formatVersion = 2;
    std::vector<RawPart> parts = rawPartsFrom(img);  // no mcstat:adaptiveM yet
    std::string err;
    StatsImage out;
    writeRaw(path, parts);
    EXPECT_FALSE(readStatsFile(path, out, err));
    EXPECT_TRUE(contains(err, "part 'beauty': missing attribute 'mcstat:adaptiveM' (int)")) << err;
    setIntOnAll(parts, "mcstat:adaptiveM", 2);
    writeRaw(path, parts);
    EXPECT_FALSE(readStatsFile(path, out, err));
    EXPECT_TRUE(contains(err, "part 'beauty': mcstat:adaptiveM = 2, expected 0 or 1")) << err;
    setIntOnAll(parts, "mcstat:adaptiveM", 0);
    writeRaw(path, parts);
    EXPECT_TRUE(readStatsFile(path, out, err)) << err;
    EXPECT_FALSE(out.header.adaptiveM);
}

TEST_F(AdaptiveCorrupt, Version1FileWithTheDeepPart) {
    // Version 1 has no adaptive M: the attribute is not looked at, the deep part is misnamed.
    setIntOnAll(parts, "mcstat:formatVersion", 1);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 1 is named 'vbuffers', expected 'buffers'")) << err;
}

TEST_F(AdaptiveCorrupt, NewerVersionIsRejectedFirst) {
    setIntOnAll(parts, "mcstat:formatVersion", kStatsFormatVersion + 1);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "written by a newer mcstat (format " +
                                  std::to_string(kStatsFormatVersion + 1) +
                                  "); this reader knows " + std::to_string(kStatsFormatVersion)))
        << err;
}

TEST(AdaptiveCorruptBytes, FlippedBytesAndTruncationsNeverCrash) {
    // Like test_fuzz.cpp, on a deep file: every outcome is a clean accept or a one-line error; an
    // accepted file is valid. Run under ASan/UBSan by scripts/test.sh.
    ScratchDir dir;
    const std::string good = dir.file("good.mcstat"), bad = dir.file("bad.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(good, sampleAdaptive(6, 5), err)) << err;
    const std::vector<unsigned char> bytes = readBytes(good);
    std::mt19937 rng(7);
    ReadLimits lim;
    lim.maxBytes = int64_t(1) << 26;
    for (int iter = 0; iter < 300; ++iter) {
        std::vector<unsigned char> b = bytes;
        if (iter % 10 == 0) {
            b.resize(std::uniform_int_distribution<size_t>(0, b.size() - 1)(rng));
        } else {
            const int flips = 1 + iter % 4;
            for (int f = 0; f < flips; ++f)
                b[std::uniform_int_distribution<size_t>(0, b.size() - 1)(rng)] ^=
                    (unsigned char)(1u << (rng() % 8));
        }
        writeBytes(bad, b);
        StatsImage out;
        if (readStatsFile(bad, out, err, lim)) {
            EXPECT_TRUE(validateStats(out, "accepted", err)) << err;
        } else {
            EXPECT_EQ(err.find('\n'), std::string::npos) << err;
            EXPECT_EQ(err.rfind(bad + ": ", 0), 0u) << err;
        }
    }
}

// ---- merge ----------------------------------------------------------------------------------

TEST(AdaptiveMerge, SameBuffersPerPixelEqualsOneRender) {
    const auto mFn = [](int x, int y) { return 1 + 2 * ((x + 2 * y) % 4); };
    const auto sppA = [](int x, int) { return 3 + x; };
    const auto sppB = [](int, int y) { return 2 + y; };
    const StatsImage a = adaptiveImage(5, 4, 7, 11, mFn, sppA);
    const StatsImage b = adaptiveImage(5, 4, 7, 12, mFn, sppB);
    StatsImage ab;
    std::string err;
    ASSERT_TRUE(mergeStats(a, b, ab, err)) << err;
    EXPECT_TRUE(ab.header.adaptiveM);
    EXPECT_EQ(ab.header.formatVersion, 2);
    EXPECT_EQ(ab.bufferOffset, a.bufferOffset);
    EXPECT_TRUE(validateStats(ab, "merged", err)) << err;
    // Per pixel and buffer: counts add, means are count-weighted.
    for (size_t p = 0; p < ab.pixelCount(); ++p) {
        const PixelBuffers pa = a.pixelBuffers(p), pb = b.pixelBuffers(p), pr = ab.pixelBuffers(p);
        ASSERT_EQ(pr.M, pa.M);
        for (int j = 0; j < pr.M; ++j) {
            ASSERT_EQ(pr.count[j], pa.count[j] + pb.count[j]);
            for (int c = 0; c < 3; ++c) {
                const double n = double(pa.count[j]) + pb.count[j];
                const double want = n == 0 ? 0.0
                                           : (double(pa.count[j]) * pa.mean[j * 3 + c] +
                                              double(pb.count[j]) * pb.mean[j * 3 + c]) /
                                                 n;
                EXPECT_NEAR(pr.mean[j * 3 + c], want, 1e-6 * (1 + std::fabs(want)));
            }
        }
    }
    // And through the file.
    ScratchDir dir;
    ASSERT_TRUE(writeStatsFile(dir.file("ab.mcstat"), ab, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(dir.file("ab.mcstat"), back, err)) << err;
    expectSameImage(ab, back);
}

TEST(AdaptiveMerge, RefusesDifferentBuffersPerPixelAndMixedInputs) {
    const auto spp = [](int, int) { return 6; };
    const StatsImage a = adaptiveImage(
        4, 3, 7, 1, [](int, int) { return 3; }, spp);
    const StatsImage b = adaptiveImage(
        4, 3, 7, 2, [](int x, int y) { return x == 2 && y == 1 ? 5 : 3; }, spp);
    StatsImage out;
    std::string err;
    EXPECT_FALSE(mergeStats(a, b, out, err));
    EXPECT_TRUE(contains(err, "adaptive M differs at pixel (2, 1): 3 vs 5 sub-buffers")) << err;
    EXPECT_TRUE(out.count.empty());

    const StatsImage fixed = renderImage(4, 3, 7, 3, spp);
    EXPECT_FALSE(mergeStats(a, fixed, out, err));
    EXPECT_TRUE(contains(err, "one input has adaptive M, the other M = 7 in every pixel")) << err;
    EXPECT_FALSE(mergeStats(fixed, a, out, err));

    StatsImage otherMax = a;
    otherMax.header.M = 9;
    otherMax.header.seeds = "99";
    EXPECT_FALSE(mergeStats(a, otherMax, out, err));
    EXPECT_TRUE(contains(err, "M_max differs (7 vs 9)")) << err;
}

}  // namespace
}  // namespace mcstat::test
