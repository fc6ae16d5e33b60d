// Every part through OpenEXR's Core writer with libdeflate (exr-deep/core_part_writer.h): the
// version-4 parts (pajot with FLOAT and UINT channels, the deep modes and records) and adaptive
// M's deep vbuffers. What a file written so holds, read back by OpenEXR's C++ API part by part
// (sample counts and the bits of every value), equals what the C++ API writes for the same image
// (MCSTAT_EXR_WRITER=cpp) and what the image holds; OpenEXR's file checker (exrcheck's engine),
// stock exrinfo and stock oiiotool read it; streamed writes give the whole write's bytes on 1 and
// 2 threads; a records file that does not fit is a one-line error naming the file.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCheckFile.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepScanLineInputPart.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputPart.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfPartType.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

/// One part as OpenEXR's C++ API reads it: per channel the 32-bit patterns of its values in
/// scanline order (a deep part: every pixel's samples in turn), and a deep part's sample counts.
struct PartBits {
    std::string name, type;
    std::map<std::string, std::pair<Imf::PixelType, std::vector<uint32_t>>> channels;
    std::vector<uint32_t> counts;
};

/// Every part of `path`, read whole by OpenEXR's C++ API.
std::vector<PartBits> readAllParts(const std::string& path) {
    Imf::MultiPartInputFile in(path.c_str());
    std::vector<PartBits> out;
    for (int i = 0; i < in.parts(); ++i) {
        const Imf::Header& h = in.header(i);
        const Imath::Box2i dw = h.dataWindow();
        const size_t w = size_t(dw.max.x - dw.min.x + 1), rows = size_t(dw.max.y - dw.min.y + 1);
        const size_t pixels = w * rows;
        PartBits pb;
        pb.name = h.name();
        pb.type = h.type();
        const auto origin = [&](size_t pixelStride) {
            return ptrdiff_t(dw.min.x + dw.min.y * w) * ptrdiff_t(pixelStride);
        };
        if (h.type() == Imf::DEEPSCANLINE) {
            Imf::DeepScanLineInputPart part(in, i);
            pb.counts.assign(pixels, 0);
            Imf::DeepFrameBuffer fb;
            fb.insertSampleCountSlice(Imf::Slice(
                Imf::UINT, reinterpret_cast<char*>(pb.counts.data()) - origin(4), 4, 4 * w));
            std::vector<std::vector<char*>> ptrs;
            std::vector<std::string> names;
            for (auto c = h.channels().begin(); c != h.channels().end(); ++c) {
                names.emplace_back(c.name());
                ptrs.emplace_back(pixels, nullptr);
                fb.insert(c.name(), Imf::DeepSlice(c.channel().type,
                                                   reinterpret_cast<char*>(ptrs.back().data()) -
                                                       origin(sizeof(char*)),
                                                   sizeof(char*), sizeof(char*) * w, 4));
            }
            part.setFrameBuffer(fb);
            part.readPixelSampleCounts(dw.min.y, dw.max.y);
            size_t total = 0;
            for (uint32_t n : pb.counts) total += n;
            for (size_t c = 0; c < names.size(); ++c) {
                auto& ch = pb.channels[names[c]];
                ch.first = h.channels().findChannel(names[c])->type;
                ch.second.assign(total, 0);
                size_t k = 0;
                for (size_t p = 0; p < pixels; k += pb.counts[p], ++p)
                    ptrs[c][p] = reinterpret_cast<char*>(ch.second.data() + k);
            }
            part.readPixels(dw.min.y, dw.max.y);
        } else {
            Imf::InputPart part(in, i);
            Imf::FrameBuffer fb;
            for (auto c = h.channels().begin(); c != h.channels().end(); ++c) {
                auto& ch = pb.channels[c.name()];
                ch.first = c.channel().type;
                ch.second.assign(pixels, 0);
                fb.insert(
                    c.name(),
                    Imf::Slice(ch.first, reinterpret_cast<char*>(ch.second.data()) - origin(4), 4,
                               4 * w));
            }
            part.setFrameBuffer(fb);
            part.readPixels(dw.min.y, dw.max.y);
        }
        out.push_back(std::move(pb));
    }
    return out;
}

/// Expects two files' parts to hold the same names, types, counts and bits.
void expectSameParts(const std::string& a, const std::string& b) {
    const std::vector<PartBits> pa = readAllParts(a), pb = readAllParts(b);
    ASSERT_EQ(pa.size(), pb.size());
    for (size_t i = 0; i < pa.size(); ++i) {
        EXPECT_EQ(pa[i].name, pb[i].name);
        EXPECT_EQ(pa[i].type, pb[i].type) << pa[i].name;
        EXPECT_EQ(pa[i].counts, pb[i].counts) << pa[i].name;
        ASSERT_EQ(pa[i].channels.size(), pb[i].channels.size()) << pa[i].name;
        for (const auto& [name, values] : pa[i].channels) {
            ASSERT_TRUE(pb[i].channels.count(name)) << pa[i].name << "." << name;
            EXPECT_EQ(values.first, pb[i].channels.at(name).first) << pa[i].name << "." << name;
            EXPECT_TRUE(values.second == pb[i].channels.at(name).second)
                << pa[i].name << "." << name;
        }
    }
}

/// The bits of `values` (floats or words) as 32-bit patterns.
template <class T>
std::vector<uint32_t> bitsOf(const std::vector<T>& values, size_t first = 0, size_t stride = 1) {
    std::vector<uint32_t> out;
    for (size_t i = first; i < values.size(); i += stride) {
        uint32_t u;
        std::memcpy(&u, &values[i], sizeof u);
        out.push_back(u);
    }
    return out;
}

float fromBits(uint32_t u) {
    float f;
    std::memcpy(&f, &u, sizeof f);
    return f;
}

/// Runs `f` with every part written through the C++ API (MCSTAT_EXR_WRITER=cpp).
template <class F>
void withCppWriter(F f) {
    ::setenv("MCSTAT_EXR_WRITER", "cpp", 1);
    f();
    ::unsetenv("MCSTAT_EXR_WRITER");
}

class CoreWrite : public testing::Test {
  protected:
    void SetUp() override {
        // 37 x 21, M = 3: an odd width (ZIP's byte halves unequal), a version-4 header.
        img = renderImage(37, 21, 3, 11, [](int x, int y) { return (x * 5 + y * 3) % 7; });
        img.header.formatVersion = kStatsFormatVersionSamples;
        img.header.hasRecords = true;
        const size_t pixels = img.pixelCount();
        std::mt19937 rng(3);
        // Part pajot: FLOAT channels with special values and UINT words of every bit pattern.
        state.owner = {"pajot",
                       "delayed=64:delta=0:luma=0.2126,0.7152,0.0722:method=hybrid:n=50:t=2",
                       "pajot", "modes"};
        img.header.state = state.owner;
        state.floatChannels = {"B", "G", "R", "delayed"};
        state.uintChannels = {"sum.R.hi", "sum.R.lo"};
        for (size_t i = 0; i < pixels * 4; ++i)
            state.floats.push_back(i % 11 == 0 ? fromBits(0x7fc00000u | uint32_t(i))
                                               : float(i) * 0.5f);
        for (size_t i = 0; i < pixels * 2; ++i) state.words.push_back(uint32_t(rng()));
        // Part modes: 0..5 records a pixel, row 4 none at all.
        state.recordChannels = {"A", "R", "Z", "hi", "kind", "lo"};
        for (size_t p = 0; p < pixels; ++p) {
            const uint32_t n = p / 37 == 4 ? 0 : uint32_t((p * 7) % 6);
            state.recordCounts.push_back(n);
            for (uint32_t k = 0; k < n * 6; ++k) state.records.push_back(fromBits(uint32_t(rng())));
        }
        // Part records: by blocks of rows, 0..4 samples a pixel, R, G, B, Z and screen.
        records = dir.file("out.mcstat");
        std::string err;
        ASSERT_TRUE(rw.open(records, img.header, err, {"screen"})) << err;
        for (int y = 0; y < img.header.height; y += 8) {
            SampleBlock b;
            b.clear(y, std::min(8, img.header.height - y), img.header.width);
            b.channels = rw.channels();
            for (size_t p = 0; p < b.counts.size(); ++p)
                b.counts[p] = uint32_t((p + size_t(y)) % 5);
            for (uint32_t c : b.counts)
                for (uint32_t k = 0; k < c * b.stride(); ++k)
                    b.samples.push_back(fromBits(uint32_t(rng())));
            recordSamples.insert(recordSamples.end(), b.samples.begin(), b.samples.end());
            recordCounts.insert(recordCounts.end(), b.counts.begin(), b.counts.end());
            ASSERT_TRUE(rw.write(b, err)) << err;
        }
        ASSERT_TRUE(rw.close(err)) << err;
        extras.state = &state;
        extras.recordsFile = rw.path();
    }

    ScratchDir dir;
    StatsImage img;
    PixelStateParts state;
    SampleRecordsWriter rw;
    std::string records;
    std::vector<float> recordSamples;
    std::vector<uint32_t> recordCounts;
    StatsExtras extras;
};

TEST_F(CoreWrite, Version4PartsReadBackAsTheCppApiWritesThem) {
    const std::string core = dir.file("core.mcstat"), cpp = dir.file("cpp.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(core, img, extras, err)) << err;
    withCppWriter([&] { ASSERT_TRUE(writeStatsFile(cpp, img, extras, err)) << err; });
    EXPECT_TRUE(readBytes(core) != readBytes(cpp));  // libdeflate's streams, not zlib's
    expectSameParts(core, cpp);
    // And what the file holds is what was given.
    const std::vector<PartBits> parts = readAllParts(core);
    ASSERT_EQ(parts.size(), 7u);
    const PartBits& pajot = parts[4];
    EXPECT_EQ(pajot.name, "pajot");
    for (size_t c = 0; c < 4; ++c) {
        EXPECT_EQ(pajot.channels.at(state.floatChannels[c]).first, Imf::FLOAT);
        EXPECT_EQ(pajot.channels.at(state.floatChannels[c]).second, bitsOf(state.floats, c, 4));
    }
    for (size_t c = 0; c < 2; ++c) {
        EXPECT_EQ(pajot.channels.at(state.uintChannels[c]).first, Imf::UINT);
        EXPECT_EQ(pajot.channels.at(state.uintChannels[c]).second, bitsOf(state.words, c, 2));
    }
    const PartBits& modes = parts[5];
    EXPECT_EQ(modes.type, Imf::DEEPSCANLINE);
    EXPECT_EQ(modes.counts, state.recordCounts);
    for (size_t c = 0; c < 6; ++c)
        EXPECT_EQ(modes.channels.at(state.recordChannels[c]).second, bitsOf(state.records, c, 6))
            << state.recordChannels[c];
    const PartBits& recs = parts[6];
    EXPECT_EQ(recs.name, "records");
    EXPECT_EQ(recs.counts, recordCounts);
    const std::vector<std::string> channels = rw.channels();
    for (size_t c = 0; c < channels.size(); ++c)
        EXPECT_EQ(recs.channels.at(channels[c]).second, bitsOf(recordSamples, c, channels.size()))
            << channels[c];
    EXPECT_EQ(recs.channels.at("A").second,
              std::vector<uint32_t>(recordSamples.size() / channels.size(), 0x3f800000u));
    // mcstat's own readers: the statistics and the state as given.
    PixelStateParts back;
    ASSERT_TRUE(readPixelStateParts(core, back, err)) << err;
    EXPECT_EQ(bitsOf(back.floats), bitsOf(state.floats));
    EXPECT_EQ(back.words, state.words);
    EXPECT_EQ(back.recordCounts, state.recordCounts);
    EXPECT_EQ(bitsOf(back.records), bitsOf(state.records));
    StatsImage stats;
    ASSERT_TRUE(readStatsFile(core, stats, err)) << err;
    EXPECT_EQ(bitsOf(stats.bufferMean), bitsOf(img.bufferMean));
    EXPECT_EQ(bitsOf(stats.variance), bitsOf(img.variance));
}

TEST_F(CoreWrite, ModesWithoutAnyRecord) {
    // A render that ends learning nowhere and delays nothing still has its parts: every chunk of
    // modes is empty.
    state.recordCounts.assign(img.pixelCount(), 0);
    state.records.clear();
    const std::string core = dir.file("core.mcstat"), cpp = dir.file("cpp.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(core, img, extras, err)) << err;
    withCppWriter([&] { ASSERT_TRUE(writeStatsFile(cpp, img, extras, err)) << err; });
    expectSameParts(core, cpp);
    EXPECT_FALSE(Imf::checkOpenEXRFile(core.c_str(), false, false, true));
}

TEST_F(CoreWrite, WrittenFilesPassOpenExrsCheckerAndStockExrinfo) {
    StatsImage adaptive = adaptiveImage(
        23, 19, 9, 5, [](int x, int y) { return 1 + 2 * ((x + 2 * y) % 5); },
        [](int x, int y) { return (x * 7 + y * 5) % 12; });
    const std::string v4 = dir.file("v4.mcstat"), v2 = dir.file("v2.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(v4, img, extras, err)) << err;
    ASSERT_TRUE(writeStatsFile(v2, adaptive, err)) << err;
    for (const std::string& f : {v4, v2}) {
        // Both of the checker's memory modes, the Core's read path included.
        EXPECT_FALSE(Imf::checkOpenEXRFile(f.c_str(), false, false, true)) << f;
        EXPECT_FALSE(Imf::checkOpenEXRFile(f.c_str(), true, false, false)) << f;
        StatsCheckReport report;
        EXPECT_TRUE(checkStatsFile(f, report, err)) << err;
    }
    const std::string exrinfo = MCSTAT_EXRINFO;
    if (exrinfo.empty()) GTEST_SKIP() << "no exrinfo";
    for (const std::string& f : {v4, v2}) {
        const std::string cmd = exrinfo + " -v '" + f + "' > /dev/null 2>&1";
        EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    }
}

/// The output of `cmd` (stdout), or "" when it fails.
std::string run(const std::string& cmd) {
    std::string out;
    FILE* f = ::popen(cmd.c_str(), "r");
    if (f == nullptr) return out;
    char buf[4096];
    for (size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) out.append(buf, n);
    return ::pclose(f) == 0 ? out : std::string();
}

TEST_F(CoreWrite, StockOiiotoolReadsTheDeepAndUintParts) {
    const std::string oiiotool = MCSTAT_OIIOTOOL;
    if (oiiotool.empty()) GTEST_SKIP() << "no oiiotool";
    // Named .exr, so that OIIO's own OpenEXR reader opens it (not mcstat's plugin).
    const std::string exr = dir.file("stats.exr");
    std::string err;
    ASSERT_TRUE(writeStatsFile(exr, img, extras, err)) << err;
    const std::vector<PartBits> parts = readAllParts(exr);
    // Part pajot extracted to a file of its own, which OpenEXR's C++ API reads back: the FLOAT
    // channels bit for bit; the words as uint32 (OIIO reads a part of mixed types as float, so a
    // word beyond 2^24 is rounded), exactly as from the file the C++ API writes.
    const std::string cppExr = dir.file("cpp.exr");
    withCppWriter([&] { ASSERT_TRUE(writeStatsFile(cppExr, img, extras, err)) << err; });
    const auto extract = [&](const std::string& from, const std::string& channels,
                             const std::string& type) {
        const std::string out = from + "." + type + ".exr";
        const std::string cmd = oiiotool + " '" + from + "' --subimage pajot --ch " + channels +
                                " -d " + type + " -o '" + out + "' 2>&1";
        EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
        std::vector<PartBits> got = readAllParts(out);
        EXPECT_EQ(got.size(), 1u);
        return got.empty() ? PartBits() : got[0];
    };
    const PartBits floats = extract(exr, "B,G,R,delayed", "float");
    EXPECT_EQ(floats.channels.size(), 4u);
    for (const auto& [name, values] : floats.channels)
        EXPECT_TRUE(values.second == parts[4].channels.at(name).second) << name;
    const PartBits words = extract(exr, "sum.R.hi,sum.R.lo", "uint32"),
                   cppWords = extract(cppExr, "sum.R.hi,sum.R.lo", "uint32");
    EXPECT_EQ(words.channels.size(), 2u);
    for (const auto& [name, values] : words.channels) {
        EXPECT_EQ(values.first, Imf::UINT) << name;
        EXPECT_TRUE(values.second == cppWords.channels.at(name).second) << name;
    }
    // The deep parts: OIIO 2.4's oiiotool drops deep samples when it copies a subimage out, so
    // its statistics of the file itself say what it read: each part's samples.
    const std::string info = run(oiiotool + " --info -v --stats -a '" + exr + "'");
    ASSERT_FALSE(info.empty());
    size_t at = 0;
    for (size_t i : {size_t(5), size_t(6)}) {
        uint64_t total = 0, most = 0;
        for (uint32_t n : parts[i].counts) total += n, most = std::max<uint64_t>(most, n);
        at = info.find("oiio:subimagename: \"" + parts[i].name + "\"", at);
        ASSERT_NE(at, std::string::npos) << parts[i].name << "\n" << info;
        const size_t next = info.find("\n subimage", at);
        const std::string part = info.substr(at, next == std::string::npos ? next : next - at);
        EXPECT_TRUE(contains(part, "Total deep samples in all pixels: " + std::to_string(total)))
            << part;
        EXPECT_TRUE(contains(part, "Max deep samples in any pixel : " + std::to_string(most)))
            << part;
    }
}

TEST(CoreWriteAdaptive, DeepBuffersReadBackAsTheCppApiWritesThemWhateverTheBlocksAndThreads) {
    // m_p in 1..9 (odd), 0..11 samples: empty buffers, pixels without samples.
    const StatsImage img = adaptiveImage(
        23, 19, 9, 5, [](int x, int y) { return 1 + 2 * ((x + 2 * y) % 5); },
        [](int x, int y) { return (x * 7 + y * 5) % 12; });
    ScratchDir dir;
    const std::string core = dir.file("core.mcstat"), cpp = dir.file("cpp.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(core, img, err)) << err;
    withCppWriter([&] { ASSERT_TRUE(writeStatsFile(cpp, img, err)) << err; });
    expectSameParts(core, cpp);
    const std::vector<PartBits> parts = readAllParts(core);
    ASSERT_EQ(parts[1].name, "vbuffers");
    EXPECT_EQ(parts[1].channels.at("count").second, bitsOf(img.bufferCount));
    EXPECT_EQ(parts[1].channels.at("G").second, bitsOf(img.bufferMean, 1, 3));
    std::vector<uint32_t> z;
    for (size_t p = 0; p < img.pixelCount(); ++p)
        for (int j = 0; j < img.buffersOf(p); ++j)
            z.push_back(bitsOf(std::vector<float>{float(j)})[0]);
    EXPECT_EQ(parts[1].channels.at("Z").second, z);
    // Streamed: the deep part's chunks wait in the spill file with the flat parts'.
    const std::vector<unsigned char> whole = readBytes(core);
    const std::pair<int, int> runs[] = {{1, 1}, {7, 2}, {16, 1}, {19, 2}};
    for (const auto& [rows, threads] : runs) {
        const std::string path = dir.file("blocks.mcstat");
        writeByBlocks(path, img, rows, threads);
        EXPECT_TRUE(readBytes(path) == whole) << rows << " rows a block, " << threads << " threads";
    }
    StatsImage back;
    ASSERT_TRUE(readStatsFile(core, back, err)) << err;
    EXPECT_EQ(back.bufferOffset, img.bufferOffset);
    EXPECT_EQ(bitsOf(back.bufferMean), bitsOf(img.bufferMean));
}

TEST_F(CoreWrite, ARecordsFileOfAnotherImageIsAOneLineError) {
    // Records of a wider image: the chunks cannot be moved; the target is not created.
    StatsImage other = renderImage(38, 21, 3, 11, [](int, int) { return 1; });
    other.header.formatVersion = kStatsFormatVersionSamples;
    SampleRecordsWriter w2;
    std::string err;
    ASSERT_TRUE(w2.open(dir.file("x.mcstat"), other.header, err)) << err;
    SampleBlock b;
    b.clear(0, 21, 38);
    ASSERT_TRUE(w2.write(b, err)) << err;
    ASSERT_TRUE(w2.close(err)) << err;
    extras.recordsFile = w2.path();
    const std::string out = dir.file("bad.mcstat");
    EXPECT_FALSE(writeStatsFile(out, img, extras, err));
    EXPECT_TRUE(contains(err, out)) << err;
    EXPECT_TRUE(contains(err, w2.path())) << err;
    EXPECT_EQ(err.find('\n'), std::string::npos) << err;
    EXPECT_FALSE(std::filesystem::exists(out));
}

}  // namespace
}  // namespace mcstat::test
