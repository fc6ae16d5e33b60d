// mcstat-render --aovs (docs/aovs.md): alpha and a light-path split of the beauty per sub-buffer
// and per sample. The split must sum to the beauty in every buffer and every sample, alpha must be
// the hit coverage the features part already stores, and the beauty must not change by a bit.
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "tool_test.h"

namespace mcstat {
namespace {

const char* const kLightPaths[] = {"emission",         "background",      "diffuse_direct",
                                   "diffuse_indirect", "specular_direct", "specular_indirect"};

class RenderAovs : public testing::ToolTest {
  protected:
    RenderAovs() : ToolTest("render") {}
    StatsImage renderRead(const std::string& args, const std::string& name) {
        const std::string f = path(name);
        const testing::ToolRun r = render(args + " -o " + f);
        EXPECT_EQ(r.code, 0) << r.err;
        StatsImage img;
        std::string err;
        EXPECT_TRUE(readStatsFile(f, img, err)) << err;
        return img;
    }
};

/// |a - b| within the rounding of a float sum of `terms` values of magnitude up to `scale`.
void expectSumWithinRounding(double sum, double value, double scale, const std::string& what) {
    EXPECT_LE(std::abs(sum - value), 8 * 6e-8 * scale + 1e-30) << what;
}

TEST_F(RenderAovs, LightPathsSumToTheBeautyInEveryBufferAndAlphaIsTheCoverage) {
    // The default scene: the emitter, the glass sphere (specular) and diffuse walls in view.
    const StatsImage img =
        renderRead("--scene default --res 40 30 --spp 24 --M 5 --aovs", "a.mcstat");
    const StatsHeader& h = img.header;
    ASSERT_EQ(h.formatVersion, kStatsFormatVersionAovs);
    ASSERT_EQ(h.aovs.size(), 19u);
    EXPECT_EQ(h.aovs[0].name, "A");
    EXPECT_EQ(h.aovs[0].cls, AovClass::Alpha);
    for (int i = 0; i < 6; ++i)
        for (int c = 0; c < 3; ++c) {
            const AovChannel& a = h.aovs[size_t(1 + 3 * i + c)];
            EXPECT_EQ(a.name, std::string(kLightPaths[i]) + "." + "RGB"[c]);
            EXPECT_EQ(a.cls, AovClass::Light);
        }
    const size_t A = h.aovs.size(), M = size_t(h.M);
    ASSERT_EQ(img.aov.size(), img.pixelCount() * M * A);
    std::vector<double> total(6, 0.0);
    for (size_t p = 0; p < img.pixelCount(); ++p) {
        double alphaSum = 0, n = 0;
        for (size_t j = 0; j < M; ++j) {
            const size_t k = p * M + j;
            const float* a = &img.aov[k * A];
            EXPECT_TRUE(a[0] >= 0.f && a[0] <= 1.f) << p;
            alphaSum += double(a[0]) * double(img.bufferCount[k]);
            n += double(img.bufferCount[k]);
            for (int c = 0; c < 3; ++c) {
                double sum = 0, scale = 0;
                for (int i = 0; i < 6; ++i) {
                    const double v = a[1 + 3 * i + c];
                    EXPECT_GE(v, 0.0);
                    sum += v;
                    scale += std::abs(v);
                    total[size_t(i)] += v;
                }
                expectSumWithinRounding(
                    sum, img.bufferMean[k * 3 + size_t(c)], scale,
                    "pixel " + std::to_string(p) + " buffer " + std::to_string(j));
            }
        }
        // Alpha is the coverage: its count-weighted mean over the buffers is the features' A.
        EXPECT_NEAR(alphaSum / n, double(img.coverage[p]), 1e-6) << p;
    }
    // The light paths this scene has show up: the emitter seen, diffuse direct and indirect, and
    // light through the glass (mostly indirect: the light's reflection in the sphere is tiny).
    // The scene has a black background, and nothing else may land in its AOV.
    for (int i : {0, 2, 3, 5}) EXPECT_GT(total[size_t(i)], 0.0) << kLightPaths[i];
    EXPECT_EQ(total[1], 0.0);
}

TEST_F(RenderAovs, EveryLightPathAndTheBackgroundOutsideAlpha) {
    // tiny: a mirror (specular direct), glass, both emitter kinds and a background seen.
    const StatsImage img = renderRead("--scene tiny --spp 16 --M 4 --aovs", "t.mcstat");
    const size_t A = img.header.aovs.size();
    std::vector<double> total(6, 0.0);
    size_t uncovered = 0;
    for (size_t k = 0; k < img.bufferCount.size(); ++k) {
        const float* a = &img.aov[k * A];
        for (int i = 0; i < 6; ++i) total[size_t(i)] += double(a[1 + 3 * i]);
        if (a[0] == 0.f) {
            // No camera ray of this buffer hit geometry: all of its light is the background.
            ++uncovered;
            for (int c = 0; c < 3; ++c)
                EXPECT_EQ(a[4 + c], img.bufferMean[k * 3 + size_t(c)]) << "buffer " << k;
        }
    }
    for (int i = 0; i < 6; ++i) EXPECT_GT(total[size_t(i)], 0.0) << kLightPaths[i];
    EXPECT_GT(uncovered, 0u);
    EXPECT_LT(uncovered, img.bufferCount.size());
}

TEST_F(RenderAovs, InfoListsTheAovsByLayerWithTheirClass) {
    const std::string f = path("i.mcstat");
    ASSERT_EQ(render("--scene tiny --spp 4 --M 3 --aovs -o " + f).code, 0);
    const std::string out = path("info.txt");
    ASSERT_EQ(mcstat::testing::runCommand(
                  (std::string(MCSTAT_EXE) + " " + f + " --info >" + out).c_str()),
              0);
    const std::string info = testing::slurp(out);
    EXPECT_NE(info.find("format 5"), std::string::npos) << info;
    EXPECT_NE(info.find("aovs (19 channels x 3 sub-buffers):"), std::string::npos) << info;
    EXPECT_NE(info.find("\n    A "), std::string::npos) << info;
    for (const char* l : kLightPaths)
        EXPECT_NE(info.find(std::string("\n    ") + l + " (R,G,B)"), std::string::npos) << l << "\n"
                                                                                        << info;
    EXPECT_NE(info.find("alpha"), std::string::npos) << info;
    EXPECT_NE(info.find("light"), std::string::npos) << info;
}

TEST_F(RenderAovs, TheBeautyAndEverythingElseAreBitIdenticalWithoutAovs) {
    const std::string args = "--scene caustic --res 24 20 --spp 12 --M 4";
    const StatsImage a = renderRead(args + " --aovs", "a.mcstat");
    const StatsImage b = renderRead(args, "b.mcstat");
    EXPECT_EQ(b.header.formatVersion, 1);
    EXPECT_TRUE(b.aov.empty());
    EXPECT_EQ(a.beauty, b.beauty);
    EXPECT_EQ(a.bufferMean, b.bufferMean);
    EXPECT_EQ(a.bufferCount, b.bufferCount);
    EXPECT_EQ(a.mean, b.mean);
    EXPECT_EQ(a.variance, b.variance);
    EXPECT_EQ(a.normal, b.normal);
    EXPECT_EQ(a.coverage, b.coverage);
}

TEST_F(RenderAovs, RecordsCarryEverySamplesAovsWhichSumToItsColor) {
    const std::string f = path("k.mcstat");
    testing::ToolRun r =
        render("--scene default --res 12 10 --spp 6 --M 3 --aovs --keep-samples -o " + f);
    ASSERT_EQ(r.code, 0) << r.err;
    StatsImage img;
    std::string err;
    ASSERT_TRUE(readStatsFile(f, img, err)) << err;
    SampleRecordsReader rec;
    ASSERT_TRUE(rec.open(f, err)) << err;
    EXPECT_EQ(rec.fields().back(), kRecordFieldAov);
    SampleBlock block;
    ASSERT_TRUE(rec.read(0, img.header.height, block, err)) << err;
    const size_t A = img.header.aovs.size(), M = 3;
    std::vector<int> at(A);
    for (size_t a = 0; a < A; ++a) {
        at[a] = block.channel(kRecordAovPrefix + img.header.aovs[a].name);
        ASSERT_GE(at[a], 0) << img.header.aovs[a].name;
    }
    size_t offset = 0;
    for (size_t p = 0; p < block.counts.size(); ++p) {
        ASSERT_EQ(block.counts[p], 6u);
        std::vector<double> sums(M * A, 0.0);
        for (size_t i = 0; i < 6; ++i) {
            const float* s = &block.samples[(offset + i) * block.stride()];
            for (int c = 0; c < 3; ++c) {
                double sum = 0, scale = 0;
                for (int l = 0; l < 6; ++l) {
                    sum += s[at[size_t(1 + 3 * l + c)]];
                    scale += std::abs(s[at[size_t(1 + 3 * l + c)]]);
                }
                expectSumWithinRounding(sum, s[c], scale, "sample " + std::to_string(i));
            }
            for (size_t a = 0; a < A; ++a) sums[(i % M) * A + a] += s[at[a]];
        }
        // Sample i went to buffer i mod M: the buffer's AOV means are its samples' means (the
        // records hold float samples, the buffers double sums: float rounding apart).
        for (size_t j = 0; j < M; ++j)
            for (size_t a = 0; a < A; ++a) {
                const double stored = img.aov[(p * M + j) * A + a];
                EXPECT_NEAR(sums[j * A + a] / 2.0, stored, 1e-6 * std::max(1.0, stored))
                    << "pixel " << p << " buffer " << j << " " << img.header.aovs[a].name;
            }
        offset += block.counts[p];
    }
}

TEST_F(RenderAovs, ByteIdenticalForAnyThreadCount) {
    std::string first;
    for (const char* threads : {"1", "2", "5"}) {
        const std::string f = path(std::string("t") + threads + ".mcstat");
        const testing::ToolRun r =
            render("--scene dof --res 16 34 --spp 5 --M 3 --aovs --keep-samples --threads " +
                   std::string(threads) + " -o " + f);
        ASSERT_EQ(r.code, 0) << r.err;
        const std::string bytes = testing::slurp(f);
        if (first.empty())
            first = bytes;
        else
            EXPECT_TRUE(bytes == first) << threads << " threads";
    }
}

TEST_F(RenderAovs, RefusedWhereThePartCannotHoldThem) {
    const std::string f = path("x.mcstat");
    testing::ToolRun r = render("--scene tiny --spp 4 --aovs --adaptive-m -o " + f);
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("AOVs need a fixed M"), std::string::npos) << r.err;
    r = render("--scene tiny --spp 4 --aovs --reference -o " + path("r.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("--aovs"), std::string::npos) << r.err;
    // A resumed render continues the AOVs, or refuses a mismatch.
    ASSERT_EQ(render("--scene tiny --spp 4 --M 2 --aovs -o " + f).code, 0);
    r = render("--scene tiny --spp 8 --resume " + f + " -o " + path("y.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("has AOVs: resume it with --aovs"), std::string::npos) << r.err;
    r = render("--scene tiny --spp 8 --aovs --resume " + f + " -o " + path("y.mcstat"));
    EXPECT_EQ(r.code, 0) << r.err;
    StatsImage resumed, whole;
    std::string err;
    ASSERT_TRUE(readStatsFile(path("y.mcstat"), resumed, err)) << err;
    ASSERT_EQ(render("--scene tiny --spp 8 --M 2 --aovs -o " + path("z.mcstat")).code, 0);
    ASSERT_TRUE(readStatsFile(path("z.mcstat"), whole, err)) << err;
    ASSERT_EQ(resumed.aov.size(), whole.aov.size());
    for (size_t i = 0; i < whole.aov.size(); ++i)
        EXPECT_NEAR(resumed.aov[i], whole.aov[i], 1e-6 * std::max(1.f, std::abs(whole.aov[i])))
            << i;
}

}  // namespace
}  // namespace mcstat
