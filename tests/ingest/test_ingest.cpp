// Ingest of renderer EXRs (one per seed) into a statistics file: values against hand-computed
// ones, every naming convention, and every kind of bad input.
#include <OpenImageIO/filesystem.h>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>

#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/ingest/ingest.h"
#include "render_files.h"

namespace mcstat {
namespace {

using testing::ExrSpec;
using testing::writeExr;

/// A scratch directory per test, removed afterwards.
class Ingest : public testing::ScratchDirTest {
  protected:
    /// Combined RGB of file j at (x, y): a smooth image plus a per-file offset (a seed's noise).
    static float beauty(int j, int c, int x, int y) {
        return 0.1f * float(x) + 0.05f * float(y) + 0.3f * float(c) + 0.125f * float(j * j % 7);
    }

    /// Writes file j in Blender/Cycles multilayer naming, 64 spp in its metadata.
    std::string writeCycles(int j, int width = 8, int height = 6) {
        ExrSpec e;
        e.width = width;
        e.height = height;
        e.channels = testing::cyclesChannels();
        e.stringAttrs["cycles.ViewLayer.samples"] = "64";
        e.stringAttrs["Software"] = "Blender 3.4.1";
        const std::string p = path("s" + std::to_string(j) + ".exr");
        writeExr(p, e, [&](const std::string& n, int x, int y) -> float {
            const char last = n.back();
            const int c = last == 'R' || last == 'X' ? 0 : last == 'G' || last == 'Y' ? 1 : 2;
            if (n.find("Combined.A") != std::string::npos) return 1.f;
            if (n.find("Combined") != std::string::npos) return beauty(j, c, x, y);
            if (n.find("AO") != std::string::npos) return 100.f;  // never the beauty
            if (n.find("Normal") != std::string::npos) return c == 2 ? 1.f - 0.1f * j : 0.1f * j;
            if (n.find("Albedo") != std::string::npos) return 0.5f + 0.01f * float(j + c);
            if (n.find("Denoising Depth") != std::string::npos) return 3.f + float(j);
            return -7.f;  // Depth.Z: the plain depth pass, not preferred over Denoising Depth
        });
        return p;
    }
};

TEST_F(Ingest, CyclesMultilayerValuesAgainstHandComputed) {
    std::vector<std::string> paths;
    for (int j = 0; j < 3; ++j) paths.push_back(writeCycles(j));
    StatsImage img;
    IngestReport rep;
    std::string err;
    ASSERT_TRUE(ingestRenders(paths, IngestOptions(), img, rep, err)) << err;
    const StatsHeader& h = img.header;
    // Version 5: the AO pass, alpha and the data passes are kept as AOVs under Cycles' names.
    EXPECT_EQ(h.formatVersion, kStatsFormatVersionAovs);
    EXPECT_EQ(h.beautyNames[0], "ViewLayer.Combined.R");
    EXPECT_EQ(h.M, 3);
    EXPECT_EQ(h.spp, 192);
    EXPECT_EQ(h.assignment, "perfile");
    EXPECT_EQ(h.variance, "buffers");
    EXPECT_EQ(featureListText(h.features), "N,Albedo,Z");
    EXPECT_EQ(h.sources, "s0.exr,s1.exr,s2.exr");
    EXPECT_EQ(h.renderer, "Blender 3.4.1 via mcstat --ingest");
    EXPECT_EQ(rep.beauty.layer, "ViewLayer.Combined");
    EXPECT_TRUE(rep.warnings.empty());
    ASSERT_TRUE(validateStats(img, "ingested", err)) << err;
    for (int y = 0; y < 6; ++y)
        for (int x = 0; x < 8; ++x) {
            const size_t p = size_t(y) * 8 + size_t(x);
            EXPECT_EQ(img.count[p], 192.f);
            for (int c = 0; c < 3; ++c) {
                double mean = 0.0;
                for (int j = 0; j < 3; ++j) {
                    EXPECT_EQ(img.bufferMean[(p * 3 + size_t(j)) * 3 + size_t(c)],
                              beauty(j, c, x, y));
                    EXPECT_EQ(img.bufferCount[p * 3 + size_t(j)], 64.f);
                    mean += beauty(j, c, x, y) / 3.0;
                }
                double ss = 0.0;  // between-buffer sum of squares, n = 64 each
                for (int j = 0; j < 3; ++j) ss += 64.0 * std::pow(beauty(j, c, x, y) - mean, 2);
                EXPECT_NEAR(img.mean[p * 3 + size_t(c)], mean, 1e-6);
                EXPECT_EQ(img.beauty[p * 3 + size_t(c)], img.mean[p * 3 + size_t(c)]);
                EXPECT_NEAR(img.variance[p * 3 + size_t(c)], ss / 2.0, 1e-5 * (1 + ss));
            }
            // Normals (0, 0.1, 0.2 on x/y; 1, 0.9, 0.8 on z) average to 0.1 and 0.9.
            EXPECT_NEAR(img.normal[p * 3 + 0], 0.1, 1e-7);
            EXPECT_NEAR(img.normal[p * 3 + 2], 0.9, 1e-7);
            EXPECT_NEAR(img.albedo[p * 3 + 1], 0.5 + 0.01 * (1 + 1), 1e-7);
            EXPECT_NEAR(img.depth[p], 4.0, 1e-7);          // Denoising Depth, not Depth.Z (-7)
            EXPECT_TRUE(std::isnan(img.position[p * 3]));  // absent: NaN, never 0
            EXPECT_TRUE(std::isnan(img.coverage[p]));
        }

    // Written and read back: version 3 with its attributes, NaNs and all.
    const std::string out = path("ingested.mcstat");
    ASSERT_TRUE(writeStatsFile(out, img, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(out, back, err)) << err;
    EXPECT_EQ(back.header.assignment, "perfile");
    EXPECT_EQ(back.header.variance, "buffers");
    EXPECT_EQ(back.header.features, h.features);
    EXPECT_EQ(back.header.sources, h.sources);
    EXPECT_EQ(back.header.seeds, h.seeds);
    EXPECT_EQ(back.bufferMean, img.bufferMean);
    EXPECT_TRUE(std::isnan(back.position[0]));
}

TEST_F(Ingest, BlocksOfRowsGiveTheSameImage) {
    std::vector<std::string> paths;
    for (int j = 0; j < 3; ++j) paths.push_back(writeCycles(j, 5, 37));
    StatsImage a, b;
    IngestReport rep;
    std::string err;
    IngestOptions opt;
    opt.rowsPerBlock = 128;
    ASSERT_TRUE(ingestRenders(paths, opt, a, rep, err)) << err;
    opt.rowsPerBlock = 4;  // 37 rows: 10 blocks, the last one short
    int64_t calls = 0, lastDone = 0, lastTotal = 0;
    opt.progress = [&](int64_t done, int64_t total) {
        ++calls;
        lastDone = done;
        lastTotal = total;
    };
    ASSERT_TRUE(ingestRenders(paths, opt, b, rep, err)) << err;
    EXPECT_EQ(a.bufferMean, b.bufferMean);
    EXPECT_EQ(a.mean, b.mean);
    EXPECT_EQ(a.depth, b.depth);
    EXPECT_EQ(calls, 10);  // once per block of rows of every file
    EXPECT_EQ(lastDone, 10);
    EXPECT_EQ(lastTotal, 10);
}

TEST_F(Ingest, PbrtV4AndItsSamplesPerPixel) {
    std::vector<std::string> paths;
    for (int j = 0; j < 2; ++j) {
        ExrSpec e;
        e.channels = testing::pbrtChannels();
        e.intAttrs["samplesPerPixel"] = 16 * (j + 1);  // 16 and 32: unequal, warned
        e.half = true;                                 // pbrt writes half by default
        paths.push_back(path("pbrt" + std::to_string(j) + ".exr"));
        writeExr(paths.back(), e, [&](const std::string& n, int x, int) -> float {
            if (n == "R" || n == "G" || n == "B") return 0.25f * float(j + 1) + 0.125f * float(x);
            if (n.rfind("Ns.", 0) == 0) return 0.5f;
            if (n.rfind("N.", 0) == 0) return -1.f;  // geometric normal: not used
            if (n.rfind("P.", 0) == 0) return 2.f * float(j);
            if (n.rfind("Albedo.", 0) == 0) return 0.75f;
            return 9.f;
        });
    }
    StatsImage img;
    IngestReport rep;
    std::string err;
    ASSERT_TRUE(ingestRenders(paths, IngestOptions(), img, rep, err)) << err;
    EXPECT_EQ(img.header.spp, 48);
    EXPECT_EQ(featureListText(img.header.features), "N,P,Albedo");
    ASSERT_EQ(rep.warnings.size(), 1u);
    EXPECT_NE(rep.warnings[0].find("samples per file differ (16 in"), std::string::npos);
    // Pixel x = 2: file values 0.5 and 0.75 with 16 and 32 samples.
    EXPECT_EQ(img.bufferCount[2 * 2 + 0], 16.f);
    EXPECT_EQ(img.bufferCount[2 * 2 + 1], 32.f);
    EXPECT_NEAR(img.mean[2 * 3], (16 * 0.5 + 32 * 0.75) / 48.0, 1e-7);
    EXPECT_NEAR(img.position[2 * 3], (16 * 0.0 + 32 * 2.0) / 48.0, 1e-6);  // count-weighted
    EXPECT_EQ(img.normal[2 * 3], 0.5f);                                    // Ns, not N
    EXPECT_TRUE(std::isnan(img.depth[2]));
}

TEST_F(Ingest, AovLayersWithSppGiven) {
    std::vector<std::string> paths;
    for (int j = 0; j < 2; ++j) {
        ExrSpec e;
        e.channels = testing::aovChannels();
        e.x = 10;  // a data window off the origin is kept
        e.y = -3;
        paths.push_back(path("arnold" + std::to_string(j) + ".exr"));
        writeExr(paths.back(), e, [&](const std::string& n, int, int) -> float {
            if (n.rfind("RGBA.", 0) == 0) return n == "RGBA.A" ? 1.f : 1.f + float(j);
            if (n.rfind("diffuse.", 0) == 0) return 50.f;
            return n == "Z" ? 5.f : 0.f;
        });
    }
    StatsImage img;
    IngestReport rep;
    std::string err;
    IngestOptions opt;
    ASSERT_FALSE(ingestRenders(paths, opt, img, rep, err));  // no spp anywhere
    EXPECT_EQ(err, paths[0] +
                       ": the file does not say how many samples per pixel it holds (looked for "
                       "mcstat:spp, samplesPerPixel, cycles.<ViewLayer>.samples); give "
                       "--ingest:spp=N");
    opt.spp = 4;
    ASSERT_TRUE(ingestRenders(paths, opt, img, rep, err)) << err;
    EXPECT_EQ(rep.beauty.layer, "RGBA");
    EXPECT_EQ(img.header.originX, 10);
    EXPECT_EQ(img.header.originY, -3);
    EXPECT_EQ(img.header.spp, 8);
    EXPECT_EQ(img.mean[0], 1.5f);
    EXPECT_EQ(img.depth[0], 5.f);
    EXPECT_EQ(featureListText(img.header.features), "N,P,Z");
}

TEST_F(Ingest, OneFileIsMEqualsOneWithAWarningAndUnknownVariance) {
    const std::vector<std::string> paths = {writeCycles(0)};
    StatsImage img;
    IngestReport rep;
    std::string err;
    ASSERT_TRUE(ingestRenders(paths, IngestOptions(), img, rep, err)) << err;
    EXPECT_EQ(img.header.M, 1);
    EXPECT_EQ(img.header.variance, "unknown");
    EXPECT_TRUE(std::isnan(img.variance[0]));
    ASSERT_EQ(rep.warnings.size(), 1u);
    EXPECT_NE(rep.warnings[0].find("only one file, so M = 1"), std::string::npos);
    const std::string out = path("one.mcstat");
    ASSERT_TRUE(writeStatsFile(out, img, err)) << err;
    StatsImage back;
    ASSERT_TRUE(readStatsFile(out, back, err)) << err;
    EXPECT_EQ(back.header.variance, "unknown");
}

TEST_F(Ingest, NonFiniteValuesAreKeptCountedAndReported) {
    std::vector<std::string> paths;
    for (int j = 0; j < 3; ++j) {
        ExrSpec e;
        e.channels = {"R", "G", "B"};
        e.stringAttrs["mcstat:spp"] = "8";
        paths.push_back(path("nan" + std::to_string(j) + ".exr"));
        writeExr(paths.back(), e, [&](const std::string& n, int x, int y) -> float {
            if (j == 1 && x == 1 && y == 0) return std::numeric_limits<float>::quiet_NaN();
            if (j == 1 && x == 2 && y == 0 && n == "G")
                return std::numeric_limits<float>::infinity();
            return 0.5f + 0.1f * float(j);
        });
    }
    StatsImage img;
    IngestReport rep;
    std::string err;
    ASSERT_TRUE(ingestRenders(paths, IngestOptions(), img, rep, err)) << err;
    EXPECT_EQ(rep.nonFiniteValues, 4);
    ASSERT_EQ(rep.warnings.size(), 1u);
    EXPECT_EQ(rep.warnings[0], paths[1] +
                                   ": 4 non-finite RGB values (NaN/Inf) in 2 pixels: the stored "
                                   "mean (part beauty) there is non-finite; --mean and the "
                                   "robust estimators leave that sub-buffer out");
    EXPECT_TRUE(std::isnan(img.bufferMean[(1 * 3 + 1) * 3]));
    EXPECT_TRUE(std::isnan(img.mean[1 * 3]));      // the plain mean, as a renderer's would be
    EXPECT_TRUE(std::isinf(img.mean[2 * 3 + 1]));  // +Inf stays +Inf
    EXPECT_EQ(img.mean[2 * 3 + 0], float((0.5 + 0.6 + 0.7) / 3.0));
}

TEST_F(Ingest, BadInputsNameTheFile) {
    const std::string a = writeCycles(0), b = writeCycles(1);
    StatsImage img;
    IngestReport rep;
    std::string err;
    const auto fails = [&](const std::vector<std::string>& paths, const std::string& expected) {
        err.clear();
        EXPECT_FALSE(ingestRenders(paths, IngestOptions(), img, rep, err));
        EXPECT_NE(err.find(expected), std::string::npos) << err;
    };
    // A different size.
    const std::string small = path("small.exr");
    {
        ExrSpec e;
        e.width = 7;
        e.channels = testing::cyclesChannels();
        e.stringAttrs["cycles.ViewLayer.samples"] = "64";
        writeExr(small, e, [](const std::string&, int, int) { return 1.f; });
    }
    fails({a, small},
          small + ": data window (0,0)-(6,5) (7x6) differs from " + a + "'s (0,0)-(7,5) (8x6)");
    // A shifted data window of the same size.
    const std::string shifted = path("shifted.exr");
    {
        ExrSpec e;
        e.x = 1;
        e.channels = testing::cyclesChannels();
        e.stringAttrs["cycles.ViewLayer.samples"] = "64";
        writeExr(shifted, e, [](const std::string&, int, int) { return 1.f; });
    }
    fails({a, shifted}, shifted + ": data window (1,0)-(8,5)");
    // Another channel set (a pass more).
    const std::string extra = path("extra.exr");
    {
        ExrSpec e;
        e.channels = testing::cyclesChannels();
        e.channels.push_back("ViewLayer.Emit.R");
        e.stringAttrs["cycles.ViewLayer.samples"] = "64";
        writeExr(extra, e, [](const std::string&, int, int) { return 1.f; });
    }
    fails({a, extra}, extra + ": has a channel 'ViewLayer.Emit.R' that " + a + " has not");
    fails({extra, a}, a + ": has no channel 'ViewLayer.Emit.R' that " + extra + " has");
    // No RGB.
    const std::string norgb = path("norgb.exr");
    {
        ExrSpec e;
        e.channels = {"Y", "Z"};
        writeExr(norgb, e, [](const std::string&, int, int) { return 1.f; });
    }
    fails({norgb}, norgb + ": no RGB channels");
    // Not an image; missing; the same render twice.
    const std::string junk = path("junk.exr");
    std::ofstream(junk) << "not an EXR at all";
    fails({a, junk}, junk + ": ");
    fails({a, path("missing.exr")}, path("missing.exr") + ": no such file");
    std::error_code ec;
    OIIO::Filesystem::copy(a, path("copy.exr"));
    fails({a, b, path("copy.exr")},
          path("copy.exr") + ": holds the same RGB pixels as " + a + " (the same render twice?)");
    // Limits are checked before anything is read.
    IngestOptions opt;
    opt.limits.maxPixels = 47;
    EXPECT_FALSE(ingestRenders({a, b}, opt, img, rep, err));
    EXPECT_NE(err.find("image 8x6 exceeds the limit of 47 pixels"), std::string::npos) << err;
    opt = IngestOptions();
    opt.limits.maxBytes = 1000;
    EXPECT_FALSE(ingestRenders({a, b}, opt, img, rep, err));
    EXPECT_NE(err.find("exceeding the limit of 1000 bytes"), std::string::npos) << err;
}

TEST_F(Ingest, ExpandInputsGlobsListsAndNaturalOrder) {
    for (const char* n : {"s10.exr", "s2.exr", "s1.exr", "other.exr"})
        std::ofstream(path(n)) << "x";
    std::vector<std::string> paths;
    std::string err;
    ASSERT_TRUE(expandInputs(path("s*.exr"), paths, err)) << err;
    EXPECT_EQ(paths, (std::vector<std::string>{path("s1.exr"), path("s2.exr"), path("s10.exr")}));
    ASSERT_TRUE(expandInputs(path("s10.exr") + "," + path("other.exr"), paths, err)) << err;
    EXPECT_EQ(paths, (std::vector<std::string>{path("other.exr"), path("s10.exr")}));
    EXPECT_FALSE(expandInputs(path("t*.exr"), paths, err));
    EXPECT_EQ(err, "'" + path("t*.exr") + "' matches no file");
    EXPECT_FALSE(expandInputs(path("s1.exr") + "," + path("s[1].exr"), paths, err));
    EXPECT_EQ(err, path("s1.exr") + ": named twice (its samples would count twice)");
    EXPECT_FALSE(expandInputs(path("s1.exr") + ",", paths, err));
    // A file whose name has a comma is taken as it is.
    std::ofstream(path("a,b.exr")) << "x";
    ASSERT_TRUE(expandInputs(path("a,b.exr"), paths, err)) << err;
    EXPECT_EQ(paths, std::vector<std::string>{path("a,b.exr")});
}

TEST_F(Ingest, MergingDisjointIngestsIsExactAndTheSameFilesTwiceIsRefused) {
    std::vector<std::string> p;
    for (int j = 0; j < 4; ++j) p.push_back(writeCycles(j));
    StatsImage a, b, all, merged;
    IngestReport rep;
    std::string err;
    ASSERT_TRUE(ingestRenders({p[0], p[1]}, IngestOptions(), a, rep, err)) << err;
    ASSERT_TRUE(ingestRenders({p[2], p[3]}, IngestOptions(), b, rep, err)) << err;
    ASSERT_TRUE(ingestRenders(p, IngestOptions(), all, rep, err)) << err;
    ASSERT_TRUE(mergeStats(a, b, merged, err)) << err;
    EXPECT_EQ(merged.header.M, 2);
    EXPECT_EQ(merged.header.spp, 256);
    EXPECT_EQ(merged.header.sources, "s0.exr,s1.exr,s2.exr,s3.exr");
    for (size_t p0 = 0; p0 < merged.pixelCount(); ++p0) {
        EXPECT_EQ(merged.count[p0], 256.f);
        for (size_t c = 0; c < 3; ++c) {
            // Buffer j holds files j and j + 2: their count-weighted mean.
            for (size_t j = 0; j < 2; ++j) {
                const double want = (double(a.bufferMean[(p0 * 2 + j) * 3 + c]) +
                                     double(b.bufferMean[(p0 * 2 + j) * 3 + c])) /
                                    2.0;
                EXPECT_EQ(merged.bufferMean[(p0 * 2 + j) * 3 + c], float(want));
                EXPECT_EQ(merged.bufferCount[p0 * 2 + j], 128.f);
            }
            // The mean of all four samples sets, as one ingest of the four files has it.
            EXPECT_NEAR(merged.mean[p0 * 3 + c], all.mean[p0 * 3 + c], 2e-7);
            // Variance re-estimated from the merged buffers (its definition, FORMAT.md).
            EXPECT_NEAR(merged.variance[p0 * 3 + c],
                        bufferVariance(merged, p0, c, merged.mean[p0 * 3 + c]), 1e-6);
            EXPECT_EQ(merged.normal[p0 * 3 + c], all.normal[p0 * 3 + c]);
        }
    }
    // The same renders twice: their content hashes overlap.
    EXPECT_FALSE(mergeStats(a, a, merged, err));
    EXPECT_NE(err.find("is in both inputs (the same samples would be counted twice)"),
              std::string::npos)
        << err;
    // A rendered (round-robin) file and an ingested one.
    StatsImage rr = b;
    rr.header.assignment = "roundrobin";
    rr.header.variance = "samples";
    rr.header.seeds = "7";
    EXPECT_FALSE(mergeStats(a, rr, merged, err));
    EXPECT_NE(err.find("sample assignments differ ('perfile' vs 'roundrobin')"), std::string::npos)
        << err;
}

}  // namespace
}  // namespace mcstat

namespace mcstat {
namespace {

TEST(IngestMetadata, TheRenderersSampleCountsSayTheResultsSamples) {
    // The first render's attributes go to every result; its own sample counts (pbrt-v4's int
    // samplesPerPixel, Cycles' string cycles.<ViewLayer>.samples) would then claim one seed's 16
    // samples for a result of 21 x 16: they are rewritten to the result's, in their own type.
    OIIO::ImageSpec render(4, 4, 3, OIIO::TypeDesc::FLOAT);
    render.attribute("samplesPerPixel", 16);
    render.attribute("cycles.ViewLayer.samples", "16");
    render.attribute("cycles.ViewLayer.total_time", "00:01.50");
    render.attribute("frame", 7);
    StatsHeader h;
    h.M = 21;
    h.spp = 336;
    h.sourceMetadata = sourceMetadataJson(render);
    ParamValues values;
    std::string err;
    const Operation& gmon = *findOperation("gmon");
    ASSERT_TRUE(parseOperationParams(gmon, {}, values, err)) << err;
    OIIO::ImageSpec out(4, 4, 3, OIIO::TypeDesc::FLOAT);
    describeResult(out, gmon, values, h);
    EXPECT_EQ(out.get_int_attribute("samplesPerPixel"), 336);
    EXPECT_EQ(out.get_string_attribute("cycles.ViewLayer.samples"), "336");
    EXPECT_EQ(out.get_string_attribute("cycles.ViewLayer.total_time"), "00:01.50");
    EXPECT_EQ(out.get_int_attribute("frame"), 7);
    EXPECT_EQ(out.get_int_attribute("mcstat.spp"), 336);
}

}  // namespace
}  // namespace mcstat
