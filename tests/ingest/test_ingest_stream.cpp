// Ingest by blocks of rows (IngestSource): every block equals the same rows of the whole image for
// any block height and thread count, the provenance hashes arrive with the pass that reads the
// last row (and reach a file written while reading), and a render given twice or changed between
// passes is refused.
#include <OpenImageIO/filesystem.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "mcstat/ingest/ingest.h"
#include "render_files.h"

namespace mcstat {
namespace {

using testing::ExrSpec;
using testing::writeExr;

constexpr int kW = 13, kH = 37;  ///< the renders' size: blocks of 1, 5 and 16 rows end short

class IngestStream : public testing::ScratchDirTest {
  protected:
    /// File j in Cycles' naming (features and AOVs), 16 spp, with a NaN in file 1 and values
    /// that differ per file, row and column.
    std::string writeRender(int j, float shift = 0.f) {
        ExrSpec e;
        e.width = kW;
        e.height = kH;
        e.channels = testing::cyclesChannels();
        e.stringAttrs["cycles.ViewLayer.samples"] = "16";
        const std::string p = path("s" + std::to_string(j) + ".exr");
        writeExr(p, e, [&](const std::string& n, int x, int y) -> float {
            const float base = 0.01f * float(x * 7 + y * 3 + j * 11 % 5) + shift;
            if (j == 1 && x == 3 && y == 20 && n.find("Combined.G") != std::string::npos)
                return std::nanf("");
            if (n.find("Combined") != std::string::npos) return base + float(n.back() - 'A');
            if (n.find("Normal") != std::string::npos) return 0.1f * float(j) - 0.02f * float(y);
            return base * 0.5f + 0.25f;
        });
        return p;
    }

    /// ingestRenders of `paths`: the whole image the blocks are checked against.
    static StatsImage whole(const std::vector<std::string>& paths) {
        StatsImage img;
        IngestReport rep;
        std::string err;
        EXPECT_TRUE(ingestRenders(paths, IngestOptions(), img, rep, err)) << err;
        return img;
    }

    std::vector<std::string> renders(int n) {
        std::vector<std::string> p;
        for (int j = 0; j < n; ++j) p.push_back(writeRender(j));
        return p;
    }
};

/// Rows [y0, y0 + rows) of `whole`'s array `a` (`per` values per pixel) against `block`'s.
void expectRows(const std::vector<float>& whole, const std::vector<float>& block, size_t per,
                int y0, int rows, const char* what) {
    ASSERT_EQ(block.size(), size_t(rows) * kW * per) << what;
    const size_t off = size_t(y0) * kW * per;
    // Bit for bit, NaN included.
    EXPECT_EQ(std::memcmp(block.data(), whole.data() + off, block.size() * sizeof(float)), 0)
        << what << " rows " << y0 << "..";
}

TEST_F(IngestStream, BlocksEqualTheWholeImageForAnyBlockHeightAndThreadCount) {
    const auto paths = renders(5);
    const StatsImage whole = IngestStream::whole(paths);
    ASSERT_FALSE(whole.bufferMean.empty());
    std::string err;
    ASSERT_NE(whole.header.seeds.find("h"), std::string::npos);
    const size_t M = 5, A = whole.header.aovs.size();
    ASSERT_GT(A, 0u);
    for (int threads : {1, 2})
        for (int rows : {1, 5, 16, kH}) {
            IngestSource src;
            ASSERT_TRUE(src.init(paths, IngestOptions(), err, threads)) << err;
            // Before the last row: a placeholder of the final length, no hash.
            EXPECT_EQ(src.header().seeds.size(), whole.header.seeds.size());
            EXPECT_NE(src.header().seeds, whole.header.seeds);
            EXPECT_FALSE(src.hashed());
            StatsImage b;
            for (int y = 0; y < kH; y += rows) {
                const int n = std::min(rows, kH - y);
                ASSERT_TRUE(src.read(y, n, kStatsAllParts, b, err)) << err;
                ASSERT_TRUE(validateStats(b, "block", err)) << err;
                EXPECT_EQ(b.header.originY, y);
                expectRows(whole.bufferMean, b.bufferMean, 3 * M, y, n, "bufferMean");
                expectRows(whole.bufferCount, b.bufferCount, M, y, n, "bufferCount");
                expectRows(whole.mean, b.mean, 3, y, n, "mean");
                expectRows(whole.variance, b.variance, 3, y, n, "variance");
                expectRows(whole.beauty, b.beauty, 3, y, n, "beauty");
                expectRows(whole.normal, b.normal, 3, y, n, "normal");
                expectRows(whole.position, b.position, 3, y, n, "position");
                expectRows(whole.depth, b.depth, 1, y, n, "depth");
                expectRows(whole.aov, b.aov, M * A, y, n, "aov");
            }
            // The block with the last row carries the hashes, as the source's header does now.
            EXPECT_TRUE(src.hashed());
            EXPECT_EQ(b.header.seeds, whole.header.seeds);
            EXPECT_EQ(src.header().seeds, whole.header.seeds);
            EXPECT_EQ(src.report().nonFiniteValues, 1);
        }
}

TEST_F(IngestStream, OverlappingBlocksAndRGBOnlyReadsHashEachRowOnce) {
    const auto paths = renders(3);
    const StatsImage whole = IngestStream::whole(paths);
    ASSERT_FALSE(whole.bufferMean.empty());
    std::string err;
    // A window filter's blocks overlap by their halo: rows 5..9 and 15..19 are read twice.
    IngestSource src;
    ASSERT_TRUE(src.init(paths, IngestOptions(), err, 2)) << err;
    StatsImage b;
    ASSERT_TRUE(src.read(0, 10, kStatsAllParts, b, err)) << err;
    ASSERT_TRUE(src.read(5, 15, kStatsAllParts, b, err)) << err;
    ASSERT_TRUE(src.read(15, kH - 15, kStatsAllParts, b, err)) << err;
    EXPECT_EQ(src.header().seeds, whole.header.seeds);
    EXPECT_EQ(src.report().nonFiniteValues, 1);  // the NaN counted once
    // Only the beauty asked for: the other parts' arrays are empty, and the hashes are the same.
    IngestSource rgb;
    ASSERT_TRUE(rgb.init(paths, IngestOptions(), err, 1)) << err;
    ASSERT_TRUE(rgb.read(0, kH, kStatsPartBeauty, b, err)) << err;
    EXPECT_TRUE(b.bufferMean.empty());
    EXPECT_TRUE(b.aov.empty());
    EXPECT_TRUE(b.normal.empty());
    expectRows(whole.beauty, b.beauty, 3, 0, kH, "beauty");
    EXPECT_EQ(b.header.seeds, whole.header.seeds);
    // A pass that skips rows hashes nothing past the gap.
    IngestSource gap;
    ASSERT_TRUE(gap.init(paths, IngestOptions(), err, 1)) << err;
    ASSERT_TRUE(gap.read(0, 10, kStatsAllParts, b, err)) << err;
    ASSERT_TRUE(gap.read(11, kH - 11, kStatsAllParts, b, err)) << err;
    EXPECT_FALSE(gap.hashed());
    EXPECT_NE(b.header.seeds, whole.header.seeds);
}

TEST_F(IngestStream, AFileWrittenWhileReadingGetsTheHashesInItsHeaders) {
    const auto paths = renders(4);
    const StatsImage whole = IngestStream::whole(paths);
    ASSERT_FALSE(whole.bufferMean.empty());
    std::string err;
    IngestSource src;
    ASSERT_TRUE(src.init(paths, IngestOptions(), err, 2)) << err;
    // A small budget: several blocks, so the header is written long before the last row is read.
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), src, err, 2, 4096)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(path("f.mcstat"), back, err)) << err;
    EXPECT_EQ(back.header.seeds, whole.header.seeds);
    EXPECT_EQ(back.bufferMean.size(), whole.bufferMean.size());
    EXPECT_EQ(std::memcmp(back.bufferMean.data(), whole.bufferMean.data(),
                          whole.bufferMean.size() * sizeof(float)),
              0);
    EXPECT_EQ(back.aov, whole.aov);
    StatsCheckReport check;
    ASSERT_TRUE(checkStatsFile(path("f.mcstat"), check, err)) << err;
    EXPECT_TRUE(check.openexrChecked);
    // A clone shares the hashes: a second write has them from its first block.
    const auto again = src.clone(1);
    EXPECT_EQ(again->header().seeds, whole.header.seeds);
    ASSERT_TRUE(writeStatsFile(path("g.mcstat"), *again, err, 1, 4096)) << err;
    ASSERT_TRUE(readStatsFile(path("g.mcstat"), back, err)) << err;
    EXPECT_EQ(back.header.seeds, whole.header.seeds);
}

TEST_F(IngestStream, TheSameRenderTwiceIsRefusedAtTheLastRowAndNothingIsWritten) {
    auto paths = renders(3);
    OIIO::Filesystem::copy(paths[1], path("copy.exr"));
    paths.push_back(path("copy.exr"));
    IngestSource src;
    std::string err;
    ASSERT_TRUE(src.init(paths, IngestOptions(), err, 2)) << err;  // headers alone cannot tell
    EXPECT_FALSE(writeStatsFile(path("f.mcstat"), src, err, 2, 4096));
    EXPECT_NE(err.find("copy.exr: holds the same RGB pixels as " + paths[1]), std::string::npos)
        << err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("f.mcstat")));
    std::vector<std::string> left;
    OIIO::Filesystem::get_directory_entries(dir, left);
    for (const std::string& f : left) EXPECT_EQ(OIIO::Filesystem::extension(f), ".exr") << f;
}

TEST_F(IngestStream, ARenderChangedBetweenPassesIsRefused) {
    const auto paths = renders(3);
    IngestSource src;
    std::string err;
    ASSERT_TRUE(src.init(paths, IngestOptions(), err, 1)) << err;
    StatsImage b;
    ASSERT_TRUE(src.read(0, kH, kStatsAllParts, b, err)) << err;
    ASSERT_TRUE(src.hashed());
    writeRender(2, 0.5f);  // same layout, other pixels
    const auto again = src.clone(1);
    EXPECT_FALSE(again->read(0, kH, kStatsAllParts, b, err));
    EXPECT_NE(err.find(paths[2] + ": changed while being ingested"), std::string::npos) << err;
}

TEST_F(IngestStream, SeedsOfAnotherLengthAreRefusedByTheWriter) {
    const auto paths = renders(2);
    IngestSource src;
    std::string err;
    ASSERT_TRUE(src.init(paths, IngestOptions(), err, 1)) << err;
    StatsFileWriter w;
    ASSERT_TRUE(w.open(path("f.mcstat"), src.header(), err, 1)) << err;
    EXPECT_FALSE(w.replaceSeeds("h1234", err));
    EXPECT_NE(err.find("mcstat:seeds of 5 bytes cannot replace the 35 written"), std::string::npos)
        << err;
}

/// Every bit pattern of half (and float values around it) from the pixel index: 256 x 256 pixels
/// hold the 65,536 halfs once, NaN payloads, Infs, denormals and -0 included.
float halfPattern(int x, int y, int shift) {
    const uint16_t bits = uint16_t((y * 256 + x + shift) & 0xffff);
    // IEEE half to float by hand (the writer converts it back exactly: every half is a float).
    const uint32_t sign = uint32_t(bits >> 15) << 31, exp = (bits >> 10) & 0x1f, man = bits & 0x3ff;
    uint32_t f = 0;
    if (exp == 0x1f) {
        f = sign | 0x7f800000u | (man << 13);
    } else if (exp == 0) {
        float v = std::ldexp(float(man), -24);
        std::memcpy(&f, &v, 4);
        f |= sign;
    } else {
        f = sign | ((exp + 112) << 23) | (man << 13);
    }
    float out;
    std::memcpy(&out, &f, 4);
    return out;
}

TEST_F(IngestStream, OpenEXRsCoreReaderGivesOIIOsBitsForEveryCompressionAndType) {
    // Renders as pbrt writes them (half) and as Cycles does (float), in the compressions the
    // Core reader takes and in one it leaves to OIIO (B44, half only), against MCSTAT_EXR_READER=
    // cpp (OIIO's reader) on the same files.
    for (const char* compression : {"zip", "zips", "piz", "rle", "none", "pxr24", "b44"})
        for (bool half : {true, false}) {
            if (std::string(compression) == "pxr24" && !half) continue;  // lossy on float
            std::vector<std::string> paths;
            for (int j = 0; j < 2; ++j) {
                ExrSpec e;
                e.width = 256;
                e.height = 256;
                e.channels = {"R", "G", "B", "A", "P.X", "N.Y"};
                e.half = half;
                e.intAttrs["samplesPerPixel"] = 4;
                e.stringAttrs["compression"] = compression;
                paths.push_back(path(std::string(compression) + std::to_string(j) + ".exr"));
                writeExr(paths.back(), e, [&](const std::string& n, int x, int y) -> float {
                    if (n == "R") return halfPattern(x, y, j * 7);
                    if (n == "G") return halfPattern(x, y, 1000 + j);
                    return 0.001f * float(x - y) + float(n[0]) * 0.25f + float(j);
                });
            }
            StatsImage core, cpp;
            IngestReport rep;
            std::string err;
            ASSERT_TRUE(ingestRenders(paths, IngestOptions(), core, rep, err)) << err;
            ::setenv("MCSTAT_EXR_READER", "cpp", 1);
            const bool ok = ingestRenders(paths, IngestOptions(), cpp, rep, err);
            ::unsetenv("MCSTAT_EXR_READER");
            ASSERT_TRUE(ok) << err;
            const auto same = [](const std::vector<float>& a, const std::vector<float>& b) {
                return a.size() == b.size() &&
                       (a.empty() || std::memcmp(a.data(), b.data(), a.size() * 4) == 0);
            };
            EXPECT_TRUE(same(core.bufferMean, cpp.bufferMean)) << compression << " half " << half;
            EXPECT_TRUE(same(core.aov, cpp.aov)) << compression << " half " << half;
            EXPECT_TRUE(same(core.position, cpp.position)) << compression << " half " << half;
            EXPECT_TRUE(same(core.normal, cpp.normal)) << compression << " half " << half;
            EXPECT_EQ(core.header.seeds, cpp.header.seeds);
        }
}

TEST_F(IngestStream, AChannelOfAnUnknownPixelTypeIsRefusedBeforeOIIOSeesIt) {
    // Found by fuzzing: OIIO 2.4's EXR reader aborts (an assertion) on a pixel type other than
    // OpenEXR's three; the header walk refuses the file first, naming the channel's place.
    const std::string file =
        std::string(MCSTAT_SOURCE_DIR) + "/tests/fuzz/regressions/ingest/unknown-pixel-type.exr";
    StatsImage img;
    IngestReport rep;
    std::string err;
    EXPECT_FALSE(ingestRenders({file}, IngestOptions(), img, rep, err));
    EXPECT_NE(err.find("unknown-pixel-type.exr: truncated or corrupt (header 0: attribute "
                       "'channels' of type chlist: a channel at byte 54 has pixel type"),
              std::string::npos)
        << err;
}

TEST(IngestLimits, ADataWindowBeyondThePixelLimitIsRefusedBeforeOpenEXROpensIt) {
    // Found by fuzzing: a 1.4 KB file whose header claims a 4259846 x 770 data window. OpenEXR's
    // C++ reader sizes its line buffers by that width when the file is opened (8 s of page faults
    // under the sanitizer), so the header walk compares the window with the limit first; the
    // message is the one the limit check after opening gives.
    const std::string file =
        std::string(MCSTAT_SOURCE_DIR) + "/tests/fuzz/regressions/ingest/wide-data-window.exr";
    for (const int64_t limit : {int64_t(1) << 20, ReadLimits().maxPixels}) {
        IngestOptions opt;
        opt.spp = 4;
        opt.limits.maxPixels = limit;
        StatsImage img;
        IngestReport rep;
        std::string err;
        EXPECT_FALSE(ingestRenders({file}, opt, img, rep, err));
        EXPECT_NE(err.find("wide-data-window.exr: image 4259846x770 exceeds the limit of " +
                           std::to_string(limit) + " pixels"),
                  std::string::npos)
            << err;
    }
    // The walk alone, through the public check: within the limit it passes, beyond it refuses.
    std::string err;
    EXPECT_TRUE(checkExrAttributeSizes(file, err));
    EXPECT_TRUE(checkExrAttributeSizes(file, err, int64_t(4259846) * 770));
    EXPECT_FALSE(checkExrAttributeSizes(file, err, int64_t(4259846) * 770 - 1));
    EXPECT_NE(err.find("exceeds the limit of"), std::string::npos) << err;
}

TEST_F(IngestStream, AnAovsNaNIsReportedOnceEvenWhenAnRGBOnlyPassCameFirst) {
    // File 2's AO.G is NaN at one pixel and +Inf at another; its RGB is finite.
    std::vector<std::string> paths;
    for (int j = 0; j < 3; ++j) {
        ExrSpec e;
        e.width = kW;
        e.height = kH;
        e.channels = testing::cyclesChannels();
        e.stringAttrs["cycles.ViewLayer.samples"] = "16";
        paths.push_back(path("aov" + std::to_string(j) + ".exr"));
        writeExr(paths.back(), e, [&](const std::string& n, int x, int y) -> float {
            if (j == 2 && n == "ViewLayer.AO.G" && y == 30 && (x == 4 || x == 5))
                return x == 4 ? std::nanf("") : std::numeric_limits<float>::infinity();
            return 0.01f * float(x + y) + 0.1f * float(j) + 0.02f * float(n.back() - 'A');
        });
    }
    const std::string expected =
        paths[2] +
        ": 2 non-finite AOV values (NaN/Inf): each is left out of its channel alone, the other "
        "sub-buffers' weights renormalised (docs/aovs.md)";
    {
        StatsImage img;
        IngestReport rep;
        std::string err;
        ASSERT_TRUE(ingestRenders(paths, IngestOptions(), img, rep, err)) << err;
        EXPECT_EQ(rep.nonFiniteValues, 0);
        EXPECT_EQ(rep.nonFiniteAovValues, 2);
        EXPECT_EQ(std::count(rep.warnings.begin(), rep.warnings.end(), expected), 1);
    }
    std::vector<std::string> called;
    IngestOptions opt;
    opt.warning = [&](const std::string& w) { called.push_back(w); };
    std::string err;
    IngestSource src;
    ASSERT_TRUE(src.init(paths, opt, err, 2)) << err;
    StatsImage b;
    // RGB only over every row (what --info reads): the hashes are settled, the AOVs not read.
    ASSERT_TRUE(src.read(0, kH, kStatsPartBeauty, b, err)) << err;
    EXPECT_TRUE(src.hashed());
    EXPECT_TRUE(called.empty());
    EXPECT_EQ(src.report().nonFiniteAovValues, 0);
    // Then every part, by blocks, as a write does: the warning once the AOVs' pass completes.
    ASSERT_TRUE(src.read(0, 31, kStatsAllParts, b, err)) << err;
    EXPECT_TRUE(called.empty());  // row 30 read, rows 31.. not yet
    ASSERT_TRUE(src.read(31, kH - 31, kStatsAllParts, b, err)) << err;
    EXPECT_EQ(called, std::vector<std::string>{expected});
    EXPECT_EQ(src.report().nonFiniteAovValues, 2);
    // A second full pass, or a clone's, repeats nothing.
    ASSERT_TRUE(src.read(0, kH, kStatsAllParts, b, err)) << err;
    auto other = src.clone(1);
    ASSERT_TRUE(other->read(0, kH, kStatsAllParts, b, err)) << err;
    EXPECT_EQ(called.size(), 1u);
    EXPECT_EQ(src.report().nonFiniteAovValues, 2);
    EXPECT_EQ(std::count(src.report().warnings.begin(), src.report().warnings.end(), expected), 1);
}

}  // namespace
}  // namespace mcstat
