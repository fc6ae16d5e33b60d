// Format version 5 (FORMAT.md "Version 5"): part `aovs` (M * A channels bNNN.<name>), the input's
// beauty names and part, its metadata and the display window. Round trips (whole, streamed by
// blocks, parts alone), the version-4 parts after it, merge (count-weighted, labels whole), and
// damaged headers, each refused in one line before anything is allocated.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCheckFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfStringVectorAttribute.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <memory>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "raw_exr.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

const std::vector<AovChannel> kAovList = {
    {"ViewLayer.Combined.A", AovClass::Alpha, ""},
    {"ViewLayer.Combined_key.R", AovClass::Light, ""},
    {"ViewLayer.Combined_key.G", AovClass::Light, ""},
    {"diffuse.R", AovClass::Light, "diffuse"},
    {"ViewLayer.Normal.X", AovClass::Data, ""},
    {"CryptoObject00.R", AovClass::Id, "crypto"},
};
const std::array<std::string, 3> kBeautyNames = {"ViewLayer.Combined.R", "ViewLayer.Combined.G",
                                                 "ViewLayer.Combined.B"};

/// Opaque text of the size a render's metadata reaches (camera matrices, renderer attributes),
/// with line breaks, quotes and UTF-8.
std::string longMetadata() {
    std::string s = "{\"worldToCamera\": [1, 0, 0, 0],\n \"note\": \"caf\xc3\xa9 \\\"q\\\"\"";
    for (int i = 0; s.size() < 200000; ++i) s += ",\n \"cycles.attr" + std::to_string(i) + "\": 1";
    return s + "}";
}

/// A version-5 image: renderImage's statistics plus AOV values that differ per pixel, buffer and
/// channel; two of them NaN and +inf (the format does not look at AOV values).
StatsImage aovImage(int w, int h, int M, uint64_t seed, int originX = 0, int originY = 0) {
    StatsImage img = renderImage(
        w, h, M, seed, [](int x, int y) { return (x * 3 + y * 5) % 7; }, originX, originY);
    StatsHeader& hd = img.header;
    hd.formatVersion = kStatsFormatVersionAovs;
    hd.aovs = kAovList;
    hd.beautyNames = kBeautyNames;
    hd.beautyPart = "ViewLayer";
    hd.sourceMetadata = longMetadata();
    img.aov.resize(img.pixelCount() * size_t(M) * kAovList.size());
    for (size_t i = 0; i < img.aov.size(); ++i)
        img.aov[i] = float(seed) + 0.125f * float(i % 997) - 3.f;
    img.aov[3] = std::numeric_limits<float>::quiet_NaN();
    img.aov.back() = std::numeric_limits<float>::infinity();
    return img;
}

void expectBitEqual(const std::vector<float>& a, const std::vector<float>& b, const char* what) {
    ASSERT_EQ(a.size(), b.size()) << what;
    if (a.empty()) return;  // memcmp must not be given the null data() of empty vectors
    EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(float))) << what;
}

void expectHeaderEq(const StatsHeader& a, const StatsHeader& b) {
    EXPECT_EQ(a.formatVersion, b.formatVersion);
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.height, b.height);
    EXPECT_EQ(a.originX, b.originX);
    EXPECT_EQ(a.originY, b.originY);
    EXPECT_EQ(a.M, b.M);
    EXPECT_EQ(a.spp, b.spp);
    EXPECT_EQ(a.seeds, b.seeds);
    EXPECT_EQ(a.renderer, b.renderer);
    EXPECT_TRUE(a.aovs == b.aovs);
    EXPECT_EQ(a.beautyNames, b.beautyNames);
    EXPECT_EQ(a.beautyPart, b.beautyPart);
    EXPECT_EQ(a.sourceMetadata, b.sourceMetadata);
    EXPECT_EQ(a.displayX, b.displayX);
    EXPECT_EQ(a.displayY, b.displayY);
    EXPECT_EQ(a.displayWidth, b.displayWidth);
    EXPECT_EQ(a.displayHeight, b.displayHeight);
    EXPECT_EQ(a.state, b.state);
    EXPECT_EQ(a.hasRecords, b.hasRecords);
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
    expectBitEqual(a.albedo, b.albedo, "albedo");
    expectBitEqual(a.depth, b.depth, "depth");
    expectBitEqual(a.coverage, b.coverage, "coverage");
    expectBitEqual(a.aov, b.aov, "aov");
}

// ---- in memory ---------------------------------------------------------------------------------

TEST(AovFormat, RequiredVersionIsFiveForTheInputsLayout) {
    StatsHeader h;
    EXPECT_EQ(requiredFormatVersion(h), 1);
    h.displayX = -4;  // any version holds a display window
    h.displayWidth = h.displayHeight = 8;
    EXPECT_EQ(requiredFormatVersion(h), 1);
    StatsHeader a = h;
    a.aovs = kAovList;
    EXPECT_EQ(requiredFormatVersion(a), kStatsFormatVersionAovs);
    StatsHeader b = h;
    b.beautyNames[1] = "RGBA.G";
    EXPECT_EQ(requiredFormatVersion(b), kStatsFormatVersionAovs);
    StatsHeader c = h;
    c.beautyPart = "rgba";
    EXPECT_EQ(requiredFormatVersion(c), kStatsFormatVersionAovs);
    StatsHeader d = h;
    d.sourceMetadata = "{}";
    EXPECT_EQ(requiredFormatVersion(d), kStatsFormatVersionAovs);
    // Version 6 holds AOVs with the deep layout (compact files).
    StatsHeader e = h;
    e.adaptiveM = true;
    EXPECT_EQ(requiredFormatVersion(e), kStatsFormatVersionAdaptive) << "no AOVs: version 2";
    e.aovs = {{"A", AovClass::Alpha, ""}};
    EXPECT_EQ(requiredFormatVersion(e), kStatsFormatVersionCompact);
    e.compact = true;
    e.compactRule = "gmon";
    EXPECT_EQ(requiredFormatVersion(e), kStatsFormatVersionCompact)
        << "a compact file of version 6 (moments with mean and variance) stays valid";
    EXPECT_EQ(kStatsFormatVersion, kStatsFormatVersionMeansInBeauty);
    EXPECT_EQ(kStatsAllParts, kStatsPartBeauty | kStatsPartBuffers | kStatsPartMoments |
                                  kStatsPartFeatures | kStatsPartAovs);
}

TEST(AovFormat, AllocateSizesTheAovArrayAndValidateChecksIt) {
    StatsImage img;
    img.header.width = 5;
    img.header.height = 3;
    img.header.M = 4;
    img.header.formatVersion = kStatsFormatVersionAovs;
    img.header.aovs = kAovList;
    std::string err;
    ASSERT_TRUE(img.allocate(err)) << err;
    EXPECT_EQ(img.aov.size(), 15u * 4 * kAovList.size());
    for (float v : img.aov) EXPECT_EQ(v, 0.f);
    EXPECT_TRUE(validateStats(img, "fresh", err)) << err;
    // NaN and infinity are values like any other: not looked at.
    img.aov[7] = std::numeric_limits<float>::quiet_NaN();
    img.aov[8] = -std::numeric_limits<float>::infinity();
    EXPECT_TRUE(validateStats(img, "fresh", err)) << err;
    // An array of the wrong size: refused by the full check and by checkBufferLayout; an empty one
    // (part not read) only by the full check.
    img.aov.pop_back();
    EXPECT_FALSE(validateStats(img, "short", err));
    EXPECT_TRUE(contains(err, "short: array of part 'aovs' holds 359 floats, expected 360")) << err;
    std::string why;
    EXPECT_FALSE(img.checkBufferLayout(why));
    EXPECT_TRUE(contains(why, "AOV array holds 359 values")) << why;
    img.aov.clear();
    EXPECT_TRUE(img.checkBufferLayout(why)) << why;
    EXPECT_TRUE(validateStats(img, kStatsAllParts & ~kStatsPartAovs, "no aovs", err)) << err;
    EXPECT_FALSE(validateStats(img, "no aovs", err));
    // Without AOVs the array must be empty.
    img.header.aovs.clear();
    img.aov.assign(3, 0.f);
    EXPECT_FALSE(validateStats(img, "stray", err));
    EXPECT_TRUE(contains(err, "holds 3 floats, expected 0")) << err;
}

TEST(AovFormat, WriterRefusesWhatTheFormatCannotHold) {
    ScratchDir dir;
    const std::string path = dir.file("w.mcstat");
    const StatsImage good = aovImage(4, 3, 2, 1);
    std::string err;
    const auto refused = [&](const StatsImage& img, const std::string& what) {
        EXPECT_FALSE(writeStatsFile(path, img, err)) << what;
        EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
        EXPECT_EQ(err.find('\n'), std::string::npos) << err;
        EXPECT_TRUE(contains(err, what)) << err;
        EXPECT_TRUE(dir.entries().empty());
    };
    StatsImage v4 = good;
    v4.header.formatVersion = kStatsFormatVersionSamples;
    refused(v4, "it needs version 5");
    StatsImage dup = good;
    dup.header.aovs[2].name = dup.header.aovs[1].name;
    refused(dup, "AOV 'ViewLayer.Combined_key.R' listed twice");
    StatsImage beauty = good;
    beauty.header.aovs[0].name = "ViewLayer.Combined.G";
    refused(beauty, "AOV 'ViewLayer.Combined.G' is also a beauty channel name");
    StatsImage empty = good;
    empty.header.aovs[3].name.clear();
    refused(empty, "AOV name is empty");
    StatsImage longName = good;
    longName.header.aovs[3].name = std::string(kMaxAovNameBytes + 1, 'x');
    refused(longName, "has 201 bytes, more than 200");
    StatsImage cls = good;
    cls.header.aovs[4].cls = AovClass(7);
    refused(cls, "AOV 'ViewLayer.Normal.X' has unknown class 7");
    StatsImage twice = good;
    twice.header.beautyNames[2] = twice.header.beautyNames[0];
    refused(twice, "beauty channel name 'ViewLayer.Combined.R' given twice");
    StatsImage many = good;
    many.header.aovs.resize(size_t(kMaxAovs) + 1);
    for (size_t a = 0; a < many.header.aovs.size(); ++a)
        many.header.aovs[a].name = "aov" + std::to_string(a);
    many.aov.assign(many.pixelCount() * 2 * many.header.aovs.size(), 0.f);
    refused(many, "4097 AOV channels, more than 4096");
    StatsImage size = good;
    size.aov.resize(size.aov.size() + 1);
    refused(size, "array of part 'aovs' holds");
    // AOVs with adaptive M live in the deep part, from version 6 on (FORMAT.md "Version 6").
    StatsImage adaptive = renderImage(3, 2, 2, 1, [](int, int) { return 2; });
    adaptive.header.formatVersion = kStatsFormatVersionAovs;
    ASSERT_TRUE(adaptive.allocateAdaptive(std::vector<uint32_t>(6, 1), err)) << err;
    adaptive.header.aovs = kAovList;
    adaptive.aov.assign(6 * kAovList.size(), 0.f);
    refused(adaptive, "it needs version 6");
    // The streaming writer checks the header on open and each block's AOVs.
    StatsFileWriter w;
    EXPECT_FALSE(w.open(path, dup.header, err));
    EXPECT_TRUE(contains(err, "listed twice")) << err;
    ASSERT_TRUE(w.open(path, good.header, err)) << err;
    StatsImage other = good;
    other.header.aovs[5].cls = AovClass::Light;
    EXPECT_FALSE(w.write(other, err));
    EXPECT_TRUE(contains(err,
                         "a block's AOV 5 is 'CryptoObject00.R' (light, part 'crypto'), the "
                         "image's is 'CryptoObject00.R' (id, part 'crypto')"))
        << err;
}

// ---- files -------------------------------------------------------------------------------------

TEST(AovFile, RoundTripKeepsEveryValueAndTheLayout) {
    const StatsImage img = aovImage(9, 7, 3, 5, -2, 11);
    ScratchDir dir;
    const std::string path = dir.file("a.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    expectImagesBitEqual(img, back);
    EXPECT_TRUE(std::isnan(back.aov[3]));
    StatsHeader hdr;
    ASSERT_TRUE(readStatsHeader(path, hdr, err)) << err;
    expectHeaderEq(img.header, hdr);

    // What any OpenEXR reader sees: part aovs fifth, M * A channels, the attributes where
    // FORMAT.md puts them.
    Imf::MultiPartInputFile in(path.c_str());
    ASSERT_EQ(in.parts(), 5);
    const char* names[] = {"beauty", "buffers", "moments", "features", "aovs"};
    for (int i = 0; i < 5; ++i) {
        const Imf::Header& ph = in.header(i);
        EXPECT_EQ(ph.name(), names[i]);
        const auto* v = ph.findTypedAttribute<Imf::IntAttribute>("mcstat:formatVersion");
        ASSERT_NE(v, nullptr);
        EXPECT_EQ(v->value(), 5);
        const auto* bc = ph.findTypedAttribute<Imf::StringVectorAttribute>("mcstat:beautyChannels");
        ASSERT_NE(bc, nullptr) << names[i];
        EXPECT_EQ(bc->value(), std::vector<std::string>(kBeautyNames.begin(), kBeautyNames.end()));
        const auto* bp = ph.findTypedAttribute<Imf::StringAttribute>("mcstat:beautyPart");
        ASSERT_NE(bp, nullptr);
        EXPECT_EQ(bp->value(), "ViewLayer");
        EXPECT_EQ(ph.findTypedAttribute<Imf::StringAttribute>("mcstat:sourceMetadata") != nullptr,
                  i == 0)
            << names[i];
        EXPECT_EQ(ph.findTypedAttribute<Imf::StringVectorAttribute>("mcstat:aovNames") != nullptr,
                  i == 4)
            << names[i];
    }
    const Imf::Header& ah = in.header(4);
    int channels = 0;
    for (auto it = ah.channels().begin(); it != ah.channels().end(); ++it) ++channels;
    EXPECT_EQ(channels, 3 * 6);
    EXPECT_NE(ah.channels().findChannel("b002.ViewLayer.Combined_key.R"), nullptr);
    EXPECT_NE(ah.channels().findChannel("b000.CryptoObject00.R"), nullptr);
    const auto* cl = ah.findTypedAttribute<Imf::StringVectorAttribute>("mcstat:aovClasses");
    ASSERT_NE(cl, nullptr);
    EXPECT_EQ(cl->value(),
              (std::vector<std::string>{"alpha", "light", "light", "light", "data", "id"}));
    const auto* pa = ah.findTypedAttribute<Imf::StringVectorAttribute>("mcstat:aovParts");
    ASSERT_NE(pa, nullptr);
    EXPECT_EQ(pa->value(), (std::vector<std::string>{"", "", "", "diffuse", "", "crypto"}));
}

TEST(AovFile, VersionFiveWithoutAovsHasTheFourParts) {
    StatsImage img = renderImage(4, 3, 2, 3, [](int, int) { return 3; });
    img.header.formatVersion = kStatsFormatVersionAovs;
    img.header.beautyNames = {"RGBA.R", "RGBA.G", "RGBA.B"};
    ScratchDir dir;
    std::string err;
    ASSERT_TRUE(writeStatsFile(dir.file("n.mcstat"), img, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(dir.file("n.mcstat"), back, err)) << err;
    expectImagesBitEqual(img, back);
    EXPECT_TRUE(back.aov.empty());
    EXPECT_EQ(Imf::MultiPartInputFile(dir.file("n.mcstat").c_str()).parts(), 4);
}

TEST(AovFile, StreamedByBlocksGivesTheSameFile) {
    const StatsImage img = aovImage(11, 37, 4, 8);
    ScratchDir dir;
    std::string err;
    ASSERT_TRUE(writeStatsFile(dir.file("whole.mcstat"), img, err)) << err;
    const std::vector<unsigned char> whole = readBytes(dir.file("whole.mcstat"));
    MemoryStatsSource src(std::make_shared<const StatsImage>(img), "memory");
    for (int rows : {1, 3, 16, 17, 37}) {
        SCOPED_TRACE("blocks of " + std::to_string(rows) + " rows");
        const std::string path = dir.file("b" + std::to_string(rows) + ".mcstat");
        writeByBlocks(path, img, rows, 2);
        // The same pixels and headers; one block is writeStatsFile byte for byte (with several,
        // OpenEXR stores each chunk when it is complete, so the parts' chunks interleave).
        StatsImage back;
        ASSERT_TRUE(readStatsFile(path, back, err)) << err;
        expectImagesBitEqual(img, back);
        EXPECT_FALSE(Imf::checkOpenEXRFile(path.c_str(), false, false, true));
        if (rows == 37) {
            EXPECT_EQ(readBytes(path), whole);
        }
    }
    // writeStatsFile over a source: one block within the default budget, so the same bytes; a
    // budget of a few rows, the same image.
    ASSERT_TRUE(writeStatsFile(dir.file("src.mcstat"), src, err, 1)) << err;
    EXPECT_EQ(readBytes(dir.file("src.mcstat")), whole);
    // 61 floats per pixel (3 + 4 M + 7 + 11 + M A): blocks of 5 rows.
    const size_t budget = 11 * 4 * 61 * 5;
    EXPECT_EQ(src.blockRows(kStatsAllParts, budget), 5);
    ASSERT_TRUE(writeStatsFile(dir.file("few.mcstat"), src, err, 1, budget)) << err;
    StatsImage few;
    ASSERT_TRUE(readStatsFile(dir.file("few.mcstat"), few, err)) << err;
    expectImagesBitEqual(img, few);
    // Read back block by block from the file: the same rows.
    StatsFileReader reader;
    ASSERT_TRUE(reader.open(dir.file("whole.mcstat"), err)) << err;
    StatsImage all;
    ASSERT_TRUE(readAll(reader, all, err)) << err;
    expectImagesBitEqual(img, all);
}

TEST(AovFile, ReadsOnlyThePartAovs) {
    const StatsImage img = aovImage(6, 20, 3, 2);
    ScratchDir dir;
    const std::string path = dir.file("p.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    StatsFileReader reader;
    ASSERT_TRUE(reader.open(path, err, ReadLimits(), 1)) << err;
    const size_t per = 3 * kAovList.size(), w = 6;
    StatsImage block;
    ASSERT_TRUE(reader.read(5, 7, kStatsPartAovs, block, err)) << err;
    EXPECT_TRUE(block.beauty.empty() && block.bufferMean.empty() && block.bufferCount.empty() &&
                block.count.empty() && block.normal.empty());
    ASSERT_EQ(block.aov.size(), 7 * w * per);
    EXPECT_EQ(0, std::memcmp(block.aov.data(), img.aov.data() + 5 * w * per,
                             block.aov.size() * sizeof(float)));
    EXPECT_EQ(block.header.originY, 5);
    EXPECT_EQ(block.header.height, 7);
    // The sub-buffers alone leave the AOVs out; both together hold both.
    ASSERT_TRUE(reader.read(0, 20, kStatsPartBuffers, block, err)) << err;
    EXPECT_TRUE(block.aov.empty());
    EXPECT_EQ(block.bufferCount, img.bufferCount);
    ASSERT_TRUE(reader.read(0, 20, kStatsPartBuffers | kStatsPartAovs, block, err)) << err;
    expectBitEqual(block.aov, img.aov, "aov");
    EXPECT_EQ(block.bufferMean, img.bufferMean);
    // The same from memory.
    MemoryStatsSource mem(std::make_shared<const StatsImage>(img), "memory");
    ASSERT_TRUE(mem.read(5, 7, kStatsPartAovs, block, err)) << err;
    ASSERT_EQ(block.aov.size(), 7 * w * per);
    EXPECT_EQ(0, std::memcmp(block.aov.data(), img.aov.data() + 5 * w * per,
                             block.aov.size() * sizeof(float)));
    EXPECT_TRUE(block.bufferMean.empty());
    // Block heights count the AOV floats: M * A = 18 floats per pixel of part aovs.
    const size_t rowBytes = (3 + 4 * 3 + 7 + 11 + per) * sizeof(float) * w;
    EXPECT_EQ(reader.blockRows(kStatsAllParts, rowBytes * 20), 16);  // ZIP: multiples of 16 rows
    EXPECT_EQ(mem.blockRows(kStatsAllParts, rowBytes * 5), 5);
    EXPECT_EQ(mem.blockRows(kStatsAllParts, rowBytes * 5 - 1), 4);
    EXPECT_EQ(mem.blockRows(kStatsPartAovs, per * sizeof(float) * w * 3), 3);
}

TEST(AovFile, VersionFourPartsFollowPartAovs) {
    StatsImage img = aovImage(5, 4, 2, 6);
    ScratchDir dir;
    const std::string path = dir.file("x.mcstat");
    std::string err;
    SampleRecordsWriter rw;
    ASSERT_TRUE(rw.open(path, img.header, err)) << err;
    SampleBlock b;
    b.clear(0, img.header.height, img.header.width);
    for (size_t p = 0; p < b.counts.size(); ++p) b.counts[p] = uint32_t(p % 3);
    size_t total = 0;
    for (uint32_t c : b.counts) total += c;
    b.samples.assign(total * 4, 0.5f);
    ASSERT_TRUE(rw.write(b, err)) << err;
    ASSERT_TRUE(rw.close(err)) << err;
    // An operation's per-pixel state (Pajot's, in practice): named channels, stored as given.
    PixelStateParts state;
    state.owner = {"pajot", "delayed=64:delta=0:luma=0.2126,0.7152,0.0722:method=hybrid:n=50:t=2",
                   "pajot", "modes"};
    // Listed in OpenEXR's order (by name), the order the reader gives them back in.
    state.floatChannels = {"B", "G", "R"};
    state.floats.assign(img.pixelCount() * 3, 0.25f);
    state.uintChannels = {"word"};
    state.words.assign(img.pixelCount(), 7u);
    state.recordChannels = {"A", "Z", "kind"};  // deep tools (and exrcheck) want Z and A
    state.recordCounts.assign(img.pixelCount(), 0);
    state.recordCounts[1] = 2;
    state.records = {1.f, 0.f, 4.f, 1.f, 1.f, 4.f};
    StatsExtras extras;
    extras.state = &state;
    extras.recordsFile = rw.path();
    ASSERT_TRUE(writeStatsFile(path, img, extras, err)) << err;

    Imf::MultiPartInputFile in(path.c_str());
    ASSERT_EQ(in.parts(), 8);
    EXPECT_EQ(in.header(4).name(), "aovs");
    EXPECT_EQ(in.header(5).name(), "pajot");
    EXPECT_EQ(in.header(6).name(), "modes");
    EXPECT_EQ(in.header(7).name(), "records");
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path, back, err)) << err;
    EXPECT_TRUE(back.header.state == state.owner && back.header.hasRecords);
    expectBitEqual(back.aov, img.aov, "aov");
    PixelStateParts st;
    ASSERT_TRUE(readPixelStateParts(path, st, err)) << err;
    EXPECT_EQ(st.owner, state.owner);
    EXPECT_EQ(st.floatChannels, state.floatChannels);
    EXPECT_EQ(st.floats, state.floats);
    EXPECT_EQ(st.uintChannels, state.uintChannels);
    EXPECT_EQ(st.words, state.words);
    EXPECT_EQ(st.recordCounts, state.recordCounts);
    EXPECT_EQ(st.recordChannels, state.recordChannels);
    EXPECT_EQ(st.records, state.records);
    SampleRecordsReader rr;
    ASSERT_TRUE(rr.open(path, err)) << err;
    SampleBlock rb;
    ASSERT_TRUE(rr.read(0, img.header.height, rb, err)) << err;
    EXPECT_EQ(rb.counts, b.counts);
    StatsCheckReport report;
    ASSERT_TRUE(checkStatsFile(path, report, err)) << err;
    EXPECT_TRUE(report.state);
    EXPECT_EQ(report.records, int64_t(total));
    // Rewriting (as -o f.mcstat does) keeps part aovs and drops the version-4 parts.
    MemoryStatsSource src(std::make_shared<const StatsImage>(back), "memory");
    ASSERT_TRUE(writeStatsFile(dir.file("y.mcstat"), src, err)) << err;
    StatsImage y;
    ASSERT_TRUE(readStatsFile(dir.file("y.mcstat"), y, err)) << err;
    EXPECT_FALSE(y.header.hasState() || y.header.hasRecords);
    EXPECT_EQ(y.header.formatVersion, 5);
    expectBitEqual(y.aov, img.aov, "aov");
}

TEST(AovFile, PassesTheFullCheckAndOpenExrsChecker) {
    const StatsImage img = aovImage(8, 18, 3, 4);
    ScratchDir dir;
    const std::string path = dir.file("c.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
    StatsCheckReport report;
    ASSERT_TRUE(checkStatsFile(path, report, err)) << err;
    EXPECT_TRUE(report.openexrChecked);
    EXPECT_EQ(report.pixels, 8 * 18);
    EXPECT_TRUE(report.header.aovs == kAovList);
    // exrcheck's engine, in its full mode too (it returns true when it finds a problem).
    EXPECT_FALSE(Imf::checkOpenEXRFile(path.c_str(), false, false, true));
    EXPECT_FALSE(Imf::checkOpenEXRFile(path.c_str(), true, true, true));
}

// ---- display window ----------------------------------------------------------------------------

struct Display {
    int x, y, w, h;
};

class DisplayWindow : public testing::TestWithParam<Display> {};

TEST_P(DisplayWindow, RoundTripsInEveryPart) {
    const Display d = GetParam();
    // Overscan: a 20 x 14 data window around the display window (or anywhere else).
    for (bool aovs : {false, true}) {
        SCOPED_TRACE(aovs ? "version 5" : "version 1");
        StatsImage img = aovs ? aovImage(20, 14, 2, 3, -2, -3)
                              : renderImage(
                                    20, 14, 2, 3, [](int, int) { return 2; }, -2, -3);
        img.header.displayX = d.x;
        img.header.displayY = d.y;
        img.header.displayWidth = d.w;
        img.header.displayHeight = d.h;
        ScratchDir dir;
        const std::string path = dir.file("d.mcstat");
        std::string err;
        ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
        StatsImage back;
        ASSERT_TRUE(readStatsFile(path, back, err)) << err;
        expectImagesBitEqual(img, back);
        EXPECT_EQ(back.header.formatVersion, aovs ? 5 : 1);
        Imf::MultiPartInputFile in(path.c_str());
        for (int i = 0; i < in.parts(); ++i) {
            const Imath::Box2i b = in.header(i).displayWindow();
            EXPECT_EQ(b.min, Imath::V2i(d.x, d.y)) << i;
            EXPECT_EQ(b.max, Imath::V2i(d.x + d.w - 1, d.y + d.h - 1)) << i;
            EXPECT_EQ(in.header(i).dataWindow(),
                      Imath::Box2i(Imath::V2i(-2, -3), Imath::V2i(17, 10)));
        }
    }
}

INSTANTIATE_TEST_SUITE_P(Windows, DisplayWindow,
                         testing::Values(Display{0, 0, 16, 10},          // overscan of 2, 3 pixels
                                         Display{100, 50, 10, 10},       // elsewhere
                                         Display{-2, -3, 19, 14},        // one column less
                                         Display{-40, -40, 200, 100}));  // larger than the data

TEST(DisplayWindowSpecial, EqualToTheDataWindowReadsBackAsNone) {
    StatsImage img = renderImage(
        6, 4, 1, 1, [](int, int) { return 1; }, 3, 2);
    img.header.displayX = 3;
    img.header.displayY = 2;
    img.header.displayWidth = 6;
    img.header.displayHeight = 4;
    ScratchDir dir;
    std::string err;
    ASSERT_TRUE(writeStatsFile(dir.file("e.mcstat"), img, err)) << err;
    StatsHeader h;
    ASSERT_TRUE(readStatsHeader(dir.file("e.mcstat"), h, err)) << err;
    EXPECT_EQ(h.displayX, 0);
    EXPECT_EQ(h.displayY, 0);
    EXPECT_EQ(h.displayWidth, 0);
    EXPECT_EQ(h.displayHeight, 0);
    // A window of no size is refused by the writer.
    img.header.displayHeight = 0;
    EXPECT_FALSE(writeStatsFile(dir.file("f.mcstat"), img, err));
    EXPECT_TRUE(contains(err, "invalid display window 6x0 at (3, 2)")) << err;
}

// ---- merge -------------------------------------------------------------------------------------

/// A 4 x 1 image, M = 2, AOVs "L" (light) and "I" (id): buffer counts as given (pixel after pixel,
/// buffer after buffer), AOV values `l` and `id` per buffer; moments count the sum.
StatsImage smallImage(const std::vector<float>& counts, const std::vector<float>& l,
                      const std::vector<float>& id, const std::string& seed) {
    StatsImage img;
    StatsHeader& h = img.header;
    h.width = 4;
    h.height = 1;
    h.M = 2;
    h.formatVersion = kStatsFormatVersionAovs;
    h.seeds = seed;
    h.aovs = {{"L", AovClass::Light, ""}, {"I", AovClass::Id, "ids"}};
    std::string err;
    EXPECT_TRUE(img.allocate(err)) << err;
    img.bufferCount = counts;
    for (size_t p = 0; p < 4; ++p) img.count[p] = counts[2 * p] + counts[2 * p + 1];
    for (size_t k = 0; k < 8; ++k) {
        img.aov[k * 2 + 0] = l[k];
        img.aov[k * 2 + 1] = id[k];
    }
    return img;
}

TEST(AovMerge, ThreeInputsLabelFromTheLargestCountFirstOnTies) {
    //                      pixel 0     pixel 1     pixel 2     pixel 3
    const StatsImage a = smallImage({3, 1, 0, 2, 0, 0, 5, 2}, {1, 1, 1, 1, 1, 1, 1, 1},
                                    {10, 11, 12, 13, 14, 15, 16, 17}, "1");
    const StatsImage b = smallImage({1, 3, 2, 2, 0, 0, 4, 6}, {2, 2, 2, 2, 2, 2, 2, 2},
                                    {20, 21, 22, 23, 24, 25, 26, 27}, "2");
    const StatsImage c = smallImage({3, 4, 2, 5, 0, 0, 0, 6}, {4, 4, 4, 4, 4, 4, 4, 4},
                                    {30, 31, 32, 33, 34, 35, 36, 37}, "3");
    StatsImage r;
    std::string err;
    ASSERT_TRUE(mergeStats({&a, &b, &c}, r, err)) << err;
    const auto L = [&](size_t k) { return r.aov[k * 2]; };
    const auto I = [&](size_t k) { return r.aov[k * 2 + 1]; };
    EXPECT_EQ(L(0), float((3.0 * 1 + 1.0 * 2 + 3.0 * 4) / 7.0));
    EXPECT_EQ(L(2), 3.f);   // a empty: (2*2 + 2*4) / 4
    EXPECT_EQ(L(4), 0.f);   // all empty
    EXPECT_EQ(I(0), 10.f);  // 3, 1, 3: the first of the largest
    EXPECT_EQ(I(1), 31.f);  // 1, 3, 4
    EXPECT_EQ(I(2), 22.f);  // 0, 2, 2: a empty, b first of the largest
    EXPECT_EQ(I(3), 33.f);  // 2, 2, 5
    EXPECT_EQ(I(4), 34.f);  // all empty: the last input's
    EXPECT_EQ(I(6), 16.f);  // 5, 4, 0
    EXPECT_EQ(I(7), 27.f);  // 2, 6, 6: b first of the largest
}

TEST(AovMerge, CountWeightedLikeBufferMeansAndLabelsWhole) {
    //                      pixel 0     pixel 1     pixel 2     pixel 3
    const StatsImage a = smallImage({3, 1, 0, 2, 0, 0, 5, 5}, {1, 0.1f, 9, 4, 7, 7, 2, 1},
                                    {10, 11, 12, 13, 14, 15, 16, 17}, "1");
    const StatsImage b = smallImage({1, 3, 2, 2, 0, 0, 4, 6}, {5, 0.7f, 3, -2, 8, 8, 6, 3},
                                    {20, 21, 22, 23, 24, 25, 26, 27}, "2");
    StatsImage r;
    std::string err;
    ASSERT_TRUE(mergeStats(a, b, r, err)) << err;
    ASSERT_EQ(r.aov.size(), 16u);
    const auto L = [&](size_t k) { return r.aov[k * 2]; };
    const auto I = [&](size_t k) { return r.aov[k * 2 + 1]; };
    // Light: (n_a x_a + n_b x_b) / (n_a + n_b) in double, rounded once; 0 when both are empty.
    EXPECT_EQ(L(0), 2.f);  // (3*1 + 1*5) / 4
    EXPECT_EQ(L(1), float((1.0 * double(0.1f) + 3.0 * double(0.7f)) / 4.0));
    EXPECT_EQ(L(2), 3.f);  // a empty: b's value
    EXPECT_EQ(L(3), 1.f);  // (2*4 + 2*-2) / 4
    EXPECT_EQ(L(4), 0.f);  // both empty
    EXPECT_EQ(L(5), 0.f);
    EXPECT_EQ(L(6), float((5.0 * 2 + 4.0 * 6) / 9.0));
    EXPECT_EQ(L(7), float((5.0 * 1 + 6.0 * 3) / 11.0));
    // Id: the input whose buffer holds more samples; a on ties; b when a's buffer is empty.
    EXPECT_EQ(I(0), 10.f);  // 3 vs 1
    EXPECT_EQ(I(1), 21.f);  // 1 vs 3
    EXPECT_EQ(I(2), 22.f);  // a empty
    EXPECT_EQ(I(3), 13.f);  // tie
    EXPECT_EQ(I(4), 24.f);  // both empty: a's count is 0
    EXPECT_EQ(I(6), 16.f);  // 5 vs 4
    EXPECT_EQ(I(7), 27.f);  // 5 vs 6
    // The same arithmetic as the buffer means: a buffer mean given these values merges alike.
    StatsImage a2 = a, b2 = b;
    for (size_t k = 0; k < 8; ++k) {
        a2.bufferMean[k * 3] = a.aov[k * 2];
        b2.bufferMean[k * 3] = b.aov[k * 2];
    }
    StatsImage r2;
    ASSERT_TRUE(mergeStats(a2, b2, r2, err)) << err;
    for (size_t k = 0; k < 8; ++k) EXPECT_EQ(r2.bufferMean[k * 3], L(k)) << k;
    EXPECT_TRUE(r.header.aovs == a.header.aovs);
}

TEST(AovMerge, StreamedEqualsWholeAndKeepsTheFirstInputsMetadata) {
    StatsImage a = aovImage(7, 19, 3, 1), b = aovImage(7, 19, 3, 2);
    b.header.sourceMetadata = "{\"other\": 1}";
    a.header.displayWidth = b.header.displayWidth = 5;
    a.header.displayHeight = b.header.displayHeight = 15;
    a.header.displayX = b.header.displayX = 1;
    a.header.displayY = b.header.displayY = 2;
    StatsImage whole;
    std::string err;
    ASSERT_TRUE(mergeStats(a, b, whole, err)) << err;
    EXPECT_EQ(whole.header.sourceMetadata, a.header.sourceMetadata);
    EXPECT_EQ(whole.header.displayWidth, 5);
    ScratchDir dir;
    ASSERT_TRUE(writeStatsFile(dir.file("a.mcstat"), a, err)) << err;
    ASSERT_TRUE(writeStatsFile(dir.file("b.mcstat"), b, err)) << err;
    ASSERT_TRUE(writeStatsFile(dir.file("whole.mcstat"), whole, err)) << err;
    StatsFileReader ra, rb;
    ASSERT_TRUE(ra.open(dir.file("a.mcstat"), err)) << err;
    ASSERT_TRUE(rb.open(dir.file("b.mcstat"), err)) << err;
    MergedStatsSource m;
    ASSERT_TRUE(m.init(ra, rb, err)) << err;
    // One block (the default budget): the bytes of the whole merge's file.
    ASSERT_TRUE(writeStatsFile(dir.file("one.mcstat"), m, err, 1)) << err;
    EXPECT_EQ(readBytes(dir.file("one.mcstat")), readBytes(dir.file("whole.mcstat")));
    // Blocks of a few rows: the same image.
    ASSERT_GT(m.blockRows(kStatsAllParts, 7 * 4 * 200), 1);
    ASSERT_TRUE(writeStatsFile(dir.file("streamed.mcstat"), m, err, 1, 7 * 4 * 200)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(dir.file("streamed.mcstat"), back, err)) << err;
    expectImagesBitEqual(whole, back);
}

TEST(AovMerge, RefusesDifferentLayoutsNamingTheFirstDifference) {
    const StatsImage a = aovImage(4, 3, 2, 1);
    StatsImage out;
    std::string err;
    const auto refused = [&](const StatsImage& b, const std::string& what) {
        EXPECT_FALSE(mergeStats(a, b, out, err)) << what;
        EXPECT_TRUE(contains(err, "cannot merge: " + what)) << err;
        StatsHeader h;
        EXPECT_FALSE(mergeHeaders(a.header, b.header, h, err));
        EXPECT_TRUE(contains(err, what)) << err;
    };
    StatsImage b = aovImage(4, 3, 2, 2);
    ASSERT_TRUE(mergeStats(a, b, out, err)) << err;
    StatsImage name = b;
    name.header.aovs[3].name = "specular.R";
    refused(name, "AOV 3 differs ('diffuse.R' vs 'specular.R')");
    StatsImage cls = b;
    cls.header.aovs[5].cls = AovClass::Data;
    refused(cls, "AOV 'CryptoObject00.R' has class id in one input, data in the other");
    StatsImage part = b;
    part.header.aovs[3].part = "";
    refused(part, "AOV 'diffuse.R' comes from part 'diffuse' in one input, '' in the other");
    StatsImage fewer = b;
    fewer.header.aovs.pop_back();
    fewer.aov.resize(fewer.pixelCount() * 2 * 5);
    refused(fewer, "AOV lists differ (6 vs 5 AOVs; 'CryptoObject00.R' is only in the first input)");
    StatsImage none = renderImage(4, 3, 2, 2, [](int x, int y) { return (x * 3 + y * 5) % 7; });
    none.header.formatVersion = kStatsFormatVersionAovs;
    none.header.beautyNames = kBeautyNames;
    none.header.beautyPart = "ViewLayer";
    refused(none, "AOV lists differ (6 vs 0 AOVs");
    StatsImage beauty = b;
    beauty.header.beautyNames[1] = "RGBA.G";
    refused(beauty, "beauty channel names differ ('ViewLayer.Combined.G' vs 'RGBA.G')");
    StatsImage bpart = b;
    bpart.header.beautyPart = "";
    refused(bpart, "beauty parts differ ('ViewLayer' vs '')");
    StatsImage display = b;
    display.header.displayWidth = display.header.displayHeight = 2;
    refused(display, "display windows differ (4x3 at (0,0) vs 2x2 at (0,0))");
    // An explicit display window equal to the data window is no window at all.
    StatsImage same = b;
    same.header.displayWidth = 4;
    same.header.displayHeight = 3;
    EXPECT_TRUE(mergeStats(a, same, out, err)) << err;
}

// ---- damaged files -----------------------------------------------------------------------------

/// Removes attribute `name` from `h` (rebuilt: OpenEXR 3.1's Header::erase leaks, see
/// test_corrupt.cpp).
void eraseAttribute(Imf::Header& h, const char* name) {
    Imf::Header out;
    for (auto it = h.begin(); it != h.end(); ++it)
        if (std::strcmp(it.name(), name) != 0) out.insert(it.name(), it.attribute());
    const Imf::Header& copy = out;
    h = copy;
}

class AovCorrupt : public testing::Test {
  protected:
    void SetUp() override {
        img = aovImage(5, 4, 3, 21);
        path = dir.file("bad.mcstat");
        std::string err;
        ASSERT_TRUE(writeStatsFile(path, img, err)) << err;
        parts = readRaw(path);
        ASSERT_EQ(parts.size(), 5u);
    }
    RawPart& part(const char* name) {
        for (RawPart& p : parts)
            if (p.header.name() == name) return p;
        throw std::runtime_error(name);
    }
    void setStrings(const char* partName, const char* attr, const std::vector<std::string>& v) {
        part(partName).header.insert(attr, Imf::StringVectorAttribute(v));
    }
    std::vector<std::string> strings(const char* partName, const char* attr) {
        return part(partName).header.typedAttribute<Imf::StringVectorAttribute>(attr).value();
    }
    /// Writes `parts` and returns the reader's message, checking that it is one line naming the
    /// file, that it comes from the headers (readStatsHeader and StatsFileReader::open say the
    /// same, so nothing the headers claim was allocated) and that the output is untouched.
    std::string readError(const ReadLimits& limits = ReadLimits()) {
        writeRaw(path, parts);
        StatsImage out;
        std::string err, herr, oerr;
        EXPECT_FALSE(readStatsFile(path, out, err, limits)) << "accepted an invalid file";
        EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
        EXPECT_EQ(err.find('\n'), std::string::npos) << err;
        EXPECT_TRUE(out.count.empty() && out.aov.empty()) << "output touched on failure";
        StatsHeader hdr;
        EXPECT_FALSE(readStatsHeader(path, hdr, herr, limits));
        EXPECT_EQ(herr, err);
        StatsFileReader reader;
        EXPECT_FALSE(reader.open(path, oerr, limits));
        EXPECT_EQ(oerr, err);
        return err;
    }

    ScratchDir dir;
    StatsImage img;
    std::vector<RawPart> parts;
    std::string path;
};

TEST_F(AovCorrupt, RawLayoutOfTheTestIsValid) {
    writeRaw(path, parts);
    StatsImage out;
    std::string err;
    ASSERT_TRUE(readStatsFile(path, out, err)) << err;
    expectImagesBitEqual(img, out);
}

TEST_F(AovCorrupt, MissingChannel) {
    Imf::ChannelList fewer;
    for (auto it = part("aovs").header.channels().begin();
         it != part("aovs").header.channels().end(); ++it)
        if (std::strcmp(it.name(), "b001.diffuse.R") != 0) fewer.insert(it.name(), it.channel());
    part("aovs").header.channels() = fewer;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'aovs': missing channel 'b001.diffuse.R' (6 AOVs x M = 3)"))
        << err;
}

TEST_F(AovCorrupt, ExtraChannel) {
    part("aovs").header.channels().insert("b003.diffuse.R", Imf::Channel(Imf::FLOAT));
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'aovs': unexpected channel 'b003.diffuse.R'")) << err;
}

TEST_F(AovCorrupt, HalfChannel) {
    part("aovs").header.channels()["b002.CryptoObject00.R"].type = Imf::HALF;
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'aovs': channel 'b002.CryptoObject00.R' has wrong type HALF"))
        << err;
}

TEST_F(AovCorrupt, VectorsOfDifferentLengths) {
    std::vector<std::string> classes = strings("aovs", "mcstat:aovClasses");
    classes.pop_back();
    setStrings("aovs", "mcstat:aovClasses", classes);
    const std::string err = readError();
    EXPECT_TRUE(contains(err,
                         "part 'aovs': mcstat:aovNames has 6 entries, mcstat:aovClasses 5 and "
                         "mcstat:aovParts 6"))
        << err;
}

TEST_F(AovCorrupt, UnknownClass) {
    std::vector<std::string> classes = strings("aovs", "mcstat:aovClasses");
    classes[2] = "glow";
    setStrings("aovs", "mcstat:aovClasses", classes);
    const std::string err = readError();
    EXPECT_TRUE(contains(err,
                         "part 'aovs': mcstat:aovClasses: unknown class 'glow' of AOV "
                         "'ViewLayer.Combined_key.G' (known: alpha, light, data, id)"))
        << err;
}

TEST_F(AovCorrupt, DuplicateName) {
    std::vector<std::string> names = strings("aovs", "mcstat:aovNames");
    names[2] = names[1];
    setStrings("aovs", "mcstat:aovNames", names);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "AOV 'ViewLayer.Combined_key.R' listed twice")) << err;
}

TEST_F(AovCorrupt, NameOfTheBeautyEmptyOrTooLong) {
    std::vector<std::string> names = strings("aovs", "mcstat:aovNames");
    names[0] = "ViewLayer.Combined.B";
    setStrings("aovs", "mcstat:aovNames", names);
    EXPECT_TRUE(contains(readError(), "AOV 'ViewLayer.Combined.B' is also a beauty channel name"));
    names[0] = "";
    setStrings("aovs", "mcstat:aovNames", names);
    EXPECT_TRUE(contains(readError(), "AOV name is empty"));
    names[0] = std::string(201, 'n');
    setStrings("aovs", "mcstat:aovNames", names);
    EXPECT_TRUE(contains(readError(), "has 201 bytes, more than 200"));
}

TEST_F(AovCorrupt, EmptyList) {
    for (const char* a : {"mcstat:aovNames", "mcstat:aovClasses", "mcstat:aovParts"})
        setStrings("aovs", a, {});
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'aovs': mcstat:aovNames is empty")) << err;
}

TEST_F(AovCorrupt, MoreAovsThanTheFormatAllows) {
    std::vector<std::string> names, classes(size_t(kMaxAovs) + 1, "light"),
        where(size_t(kMaxAovs) + 1);
    for (int a = 0; a <= kMaxAovs; ++a) names.push_back("a" + std::to_string(a));
    setStrings("aovs", "mcstat:aovNames", names);
    setStrings("aovs", "mcstat:aovClasses", classes);
    setStrings("aovs", "mcstat:aovParts", where);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 'aovs': 4097 AOV channels, more than 4096")) << err;
}

TEST_F(AovCorrupt, AovBytesCountAgainstTheLimit) {
    // 20 pixels x (21 + 4 M + M A) floats: the AOVs are most of it. The limit holds for what one
    // read holds: the whole image for a whole read, a block of rows for a streamed one.
    const int64_t need = 20 * (21 + 4 * 3 + 3 * 6) * 4;
    ReadLimits limits;
    limits.maxBytes = need - 1;
    writeRaw(path, parts);
    StatsImage out;
    std::string err;
    EXPECT_FALSE(readStatsFile(path, out, err, limits));
    EXPECT_TRUE(contains(err,
                         "rows 0..3 (5x4 with M = 3 and 6 AOVs) need 4080 bytes, exceeding the "
                         "limit of 4079 bytes"))
        << err;
    EXPECT_TRUE(out.count.empty());
    StatsFileReader reader;
    ASSERT_TRUE(reader.open(path, err, limits)) << err;  // a row (1,020 bytes) fits
    StatsImage block;
    EXPECT_TRUE(reader.read(0, 3, kStatsAllParts, block, err)) << err;  // so do three
    limits.maxBytes = need;
    std::string ok;
    EXPECT_TRUE(readStatsFile(path, out, ok, limits)) << ok;
    // A row that cannot fit is refused by the headers alone.
    limits.maxBytes = need / 4 - 1;
    EXPECT_TRUE(contains(readError(limits),
                         "a row of image 5x4 with M = 3 and 6 AOVs needs 1020 bytes, exceeding the "
                         "limit of 1019 bytes"));
}

TEST_F(AovCorrupt, AbsurdAovCountWithASmallFileIsRejectedBeforeAllocating) {
    // A channel list of the claimed length would be large; the claim alone is refused.
    std::vector<std::string> names, classes(4000, "data"), where(4000);
    for (int a = 0; a < 4000; ++a) names.push_back("channel" + std::to_string(a));
    setStrings("aovs", "mcstat:aovNames", names);
    setStrings("aovs", "mcstat:aovClasses", classes);
    setStrings("aovs", "mcstat:aovParts", where);
    ReadLimits limits;
    limits.maxBytes = int64_t(1) << 17;  // a row: 5 pixels x 3 x 4000 x 4 bytes is 240 KB
    const std::string err = readError(limits);
    EXPECT_TRUE(contains(err, "with M = 3 and 4000 AOVs needs")) << err;
    // Within the limits, the channel list gives it away.
    EXPECT_TRUE(contains(readError(), "part 'aovs': missing channel 'b000.channel0'"));
}

TEST_F(AovCorrupt, AttributesOfTheWrongTypeOrMissing) {
    eraseAttribute(part("aovs").header, "mcstat:aovParts");
    part("aovs").header.insert("mcstat:aovParts", Imf::StringAttribute(""));
    EXPECT_TRUE(contains(readError(),
                         "part 'aovs': attribute 'mcstat:aovParts' has type string, expected "
                         "string vector"));
    eraseAttribute(part("aovs").header, "mcstat:aovParts");
    EXPECT_TRUE(
        contains(readError(), "part 'aovs': missing attribute 'mcstat:aovParts' (string vector)"));
}

TEST_F(AovCorrupt, BeautyAttributes) {
    eraseAttribute(part("moments").header, "mcstat:beautyChannels");
    EXPECT_TRUE(contains(readError(),
                         "part 'moments': missing attribute 'mcstat:beautyChannels' (string "
                         "vector)"));
    setStrings("moments", "mcstat:beautyChannels", {"R", "G"});
    EXPECT_TRUE(contains(
        readError(), "part 'moments': mcstat:beautyChannels has 2 names, expected 3 (R, G, B)"));
    setStrings("moments", "mcstat:beautyChannels", {"R", "G", "B"});
    EXPECT_TRUE(contains(readError(),
                         "part 'moments' has mcstat:beautyChannels = 'R', part 'beauty' has "
                         "'ViewLayer.Combined.R'"));
    setStrings("moments", "mcstat:beautyChannels",
               std::vector<std::string>(kBeautyNames.begin(), kBeautyNames.end()));
    part("aovs").header.insert("mcstat:beautyPart", Imf::StringAttribute("rgba"));
    EXPECT_TRUE(contains(readError(),
                         "part 'aovs' has mcstat:beautyPart = 'rgba', part 'beauty' has "
                         "'ViewLayer'"));
    part("aovs").header.insert("mcstat:beautyPart", Imf::StringAttribute("ViewLayer"));
    eraseAttribute(part("beauty").header, "mcstat:sourceMetadata");
    EXPECT_TRUE(
        contains(readError(), "part 'beauty': missing attribute 'mcstat:sourceMetadata' (string)"));
}

TEST_F(AovCorrupt, NewerVersionIsRefusedFirst) {
    // What a version-8 reader says about version 9, as a version-4 reader said about version 5.
    setIntOnAll(parts, "mcstat:formatVersion", kStatsFormatVersion + 1);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "written by a newer mcstat (format 9); this reader knows 8")) << err;
}

TEST_F(AovCorrupt, PartAovsInAnOlderVersion) {
    setIntOnAll(parts, "mcstat:formatVersion", kStatsFormatVersionSamples);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "extra part 'aovs' at index 4")) << err;
}

TEST_F(AovCorrupt, PartAovsElsewhere) {
    std::swap(parts[3], parts[4]);
    const std::string err = readError();
    EXPECT_TRUE(contains(err, "part 3 is named 'aovs', expected 'features'")) << err;
}

TEST_F(AovCorrupt, PartAovsWithAdaptiveM) {
    StatsImage a = renderImage(5, 4, 3, 2, [](int, int) { return 2; });
    a.header.formatVersion = kStatsFormatVersionAdaptive;
    std::string err;
    ASSERT_TRUE(a.allocateAdaptive(std::vector<uint32_t>(20, 1), err)) << err;
    for (size_t p = 0; p < 20; ++p) a.bufferCount[p] = a.count[p] = 2.f;
    std::vector<RawPart> adaptive = rawAdaptivePartsFrom(a);
    RawPart aovs = parts[4];  // the header check stops at the part list
    adaptive.push_back(aovs);
    setIntOnAll(adaptive, "mcstat:formatVersion", kStatsFormatVersionAovs);
    parts = adaptive;
    err = readError();
    EXPECT_TRUE(contains(err, "part 'aovs' in a file with adaptive M (AOVs need a fixed M")) << err;
}

TEST_F(AovCorrupt, TruncatedInPartAovs) {
    // Part aovs' chunks come last: a file cut there is refused before any pixel is allocated.
    const std::vector<unsigned char> bytes = readBytes(path);
    for (size_t back : {1, 9, 100}) {
        writeBytes(path, std::vector<unsigned char>(bytes.begin(), bytes.end() - long(back)));
        StatsImage out;
        std::string err, herr;
        EXPECT_FALSE(readStatsFile(path, out, err));
        EXPECT_TRUE(contains(err, path + ": truncated or corrupt (part 'aovs': the chunk of row "))
            << err;
        EXPECT_FALSE(readStatsHeader(path, out.header, herr));
        EXPECT_EQ(herr, err);
    }
}

}  // namespace
}  // namespace mcstat::test
