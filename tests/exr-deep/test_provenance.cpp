// Format version 3 (provenance): the attributes it adds, what older versions may not claim, and
// what a reader refuses. Files are built with the OpenEXR C++ API, independently of the writer.
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "mcstat/exr-deep/stats_file.h"
#include "raw_exr.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

void setStringOnAll(std::vector<RawPart>& parts, const char* name, const std::string& v) {
    for (RawPart& p : parts) p.header.insert(name, Imf::StringAttribute(v));
}

class Provenance : public testing::Test {
  protected:
    void SetUp() override {
        img = renderImage(4, 3, 3, 12, [](int x, int y) { return 1 + (x + y) % 3; });
        path = dir.file("v3.mcstat");
    }
    /// `img` as an ingested file would describe it: version 3, per-file buffers, variance from
    /// the buffers, only N and Z present.
    std::vector<RawPart> v3Parts() {
        std::vector<RawPart> parts = rawPartsFrom(img);
        setIntOnAll(parts, "mcstat:formatVersion", 3);
        setIntOnAll(parts, "mcstat:adaptiveM", 0);
        setStringOnAll(parts, "mcstat:assignment", "perfile");
        setStringOnAll(parts, "mcstat:variance", "buffers");
        setStringOnAll(parts, "mcstat:features", "Z,N");
        setStringOnAll(parts, "mcstat:sources", "a.exr,b.exr,c.exr");
        return parts;
    }
    std::string readError(const std::vector<RawPart>& parts) {
        writeRaw(path, parts);
        StatsImage out;
        std::string err;
        EXPECT_FALSE(readStatsFile(path, out, err)) << "accepted an invalid file";
        EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
        return err;
    }
    ScratchDir dir;
    StatsImage img;
    std::string path;
};

TEST_F(Provenance, AVersion3FileReadsWithItsAttributes) {
    writeRaw(path, v3Parts());
    StatsImage out;
    std::string err;
    ASSERT_TRUE(readStatsFile(path, out, err)) << err;
    EXPECT_EQ(out.header.formatVersion, 3);
    EXPECT_EQ(out.header.assignment, "perfile");
    EXPECT_EQ(out.header.variance, "buffers");
    EXPECT_EQ(out.header.features, unsigned(kFeatureNormal | kFeatureDepth));
    EXPECT_EQ(out.header.sources, "a.exr,b.exr,c.exr");
    // The library writes it back byte-compatibly: the same header values again.
    ASSERT_TRUE(writeStatsFile(dir.file("again.mcstat"), out, err)) << err;
    StatsHeader h;
    ASSERT_TRUE(readStatsHeader(dir.file("again.mcstat"), h, err)) << err;
    EXPECT_EQ(featureListText(h.features), "N,Z");
    EXPECT_EQ(h.variance, "buffers");
}

TEST_F(Provenance, OlderVersionsCannotClaimWhatOnlyVersion3Says) {
    std::vector<RawPart> parts = rawPartsFrom(img);  // version 1
    setStringOnAll(parts, "mcstat:assignment", "perfile");
    EXPECT_NE(readError(parts).find(
                  "mcstat:assignment = 'perfile' needs mcstat:formatVersion >= 3 (the file has 1)"),
              std::string::npos);
    // Versions 1 and 2 imply samples / all features: their attributes are not even read.
    parts = rawPartsFrom(img);
    setStringOnAll(parts, "mcstat:variance", "unknown");
    writeRaw(path, parts);
    StatsImage out;
    std::string err;
    ASSERT_TRUE(readStatsFile(path, out, err)) << err;
    EXPECT_EQ(out.header.variance, "samples");
    EXPECT_EQ(out.header.features, unsigned(kAllFeatures));
}

TEST_F(Provenance, Version3NeedsItsAttributesWithKnownValues) {
    std::vector<RawPart> parts = v3Parts();
    setStringOnAll(parts, "mcstat:variance", "guessed");
    EXPECT_NE(readError(parts).find("mcstat:variance: unknown variance source 'guessed'"),
              std::string::npos);
    parts = v3Parts();
    setStringOnAll(parts, "mcstat:features", "N,Velocity");
    EXPECT_NE(readError(parts).find(
                  "part 'beauty': mcstat:features: unknown feature 'Velocity' (known: N, P, "
                  "Albedo, Z, A)"),
              std::string::npos);
    parts = v3Parts();
    parts[2].header.insert("mcstat:features", Imf::StringAttribute("N"));
    EXPECT_NE(readError(parts).find("part 'moments' has mcstat:features = 'N', part 'beauty' has "
                                    "'N,Z'"),
              std::string::npos);
    parts = rawPartsFrom(img);  // version 3 with an int where a string belongs
    setIntOnAll(parts, "mcstat:formatVersion", 3);
    setIntOnAll(parts, "mcstat:adaptiveM", 0);
    setIntOnAll(parts, "mcstat:variance", 1);
    setStringOnAll(parts, "mcstat:features", "N");
    setStringOnAll(parts, "mcstat:sources", "");
    EXPECT_NE(readError(parts).find("attribute 'mcstat:variance' has type int, expected string"),
              std::string::npos);
    // Per-file buffers exist only with a fixed M.
    parts = v3Parts();
    setIntOnAll(parts, "mcstat:adaptiveM", 1);
    EXPECT_NE(readError(parts).find("part 1 is named 'buffers', expected 'vbuffers'"),
              std::string::npos);
}

TEST_F(Provenance, TheWriterRefusesAVersionTooOldForTheContent) {
    StatsImage v = img;
    v.header.assignment = "perfile";  // still formatVersion 1
    std::string err;
    EXPECT_FALSE(writeStatsFile(dir.file("w.mcstat"), v, err));
    EXPECT_NE(err.find("format version 1 cannot hold this content (assignment 'perfile'"),
              std::string::npos)
        << err;
    EXPECT_EQ(requiredFormatVersion(v.header), 3);
    v.header.formatVersion = 3;
    EXPECT_TRUE(writeStatsFile(dir.file("w.mcstat"), v, err)) << err;
    StatsHeader plain;
    EXPECT_EQ(requiredFormatVersion(plain), 1);
    plain.features = kAllFeatures & ~unsigned(kFeatureCoverage);
    EXPECT_EQ(requiredFormatVersion(plain), 3);
}

TEST_F(Provenance, MergeRecomputesABufferVarianceAndKeepsAnUnknownOneUnknown) {
    StatsImage a = img, b = img;
    for (StatsImage* s : {&a, &b}) {
        s->header.formatVersion = 3;
        s->header.assignment = "perfile";
        s->header.variance = "buffers";
    }
    a.header.seeds = "ha";
    b.header.seeds = "hb";
    for (float& m : b.bufferMean) m += 0.5f;  // another render: shifted values
    StatsImage out;
    std::string err;
    ASSERT_TRUE(mergeStats(a, b, out, err)) << err;
    for (size_t p = 0; p < out.pixelCount(); ++p)
        for (size_t c = 0; c < 3; ++c) {
            // Hand-computed: sum_j n_j (m_j - mean)^2 / (M_f - 1) over the merged buffers.
            double mean = out.mean[p * 3 + c], ss = 0.0;
            int filled = 0;
            for (int j = 0; j < 3; ++j) {
                const double n = out.bufferCount[p * 3 + size_t(j)];
                if (n == 0) continue;
                ss += n * std::pow(out.bufferMean[(p * 3 + size_t(j)) * 3 + c] - mean, 2);
                ++filled;
            }
            const double want =
                filled >= 2 ? ss / (filled - 1) : std::numeric_limits<double>::quiet_NaN();
            if (std::isnan(want))
                EXPECT_TRUE(std::isnan(out.variance[p * 3 + c]));
            else
                EXPECT_NEAR(out.variance[p * 3 + c], want, 1e-6 * (1 + want));
        }
    a.header.variance = b.header.variance = "unknown";
    ASSERT_TRUE(mergeStats(a, b, out, err)) << err;
    EXPECT_TRUE(std::isnan(out.variance[0]));
    b.header.variance = "buffers";
    EXPECT_FALSE(mergeStats(a, b, out, err));
    EXPECT_NE(err.find("variance sources differ ('unknown' vs 'buffers')"), std::string::npos);
    b.header.variance = "unknown";
    b.header.features = kFeatureNormal;
    EXPECT_FALSE(mergeStats(a, b, out, err));
    EXPECT_NE(err.find("feature sets differ ('N,P,Albedo,Z,A' vs 'N')"), std::string::npos);
}

}  // namespace
}  // namespace mcstat::test
