// Random parameter filtering end to end: mcstat-render --keep-samples writes the fields RPF needs
// (FORMAT.md "Per-sample fields"), `mcstat f --rpf` filters them by blocks of rows with the same
// result for any block height and thread count, beats the 8-spp input on a depth-of-field scene,
// and refuses files without the fields with a line naming them.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "tool_test.h"

namespace mcstat {
namespace {

using testing::slurp;
using testing::ToolRun;

class RpfFile : public testing::ToolTest {
  protected:
    RpfFile() : ToolTest("filters/samples") {}
};

std::vector<float> rgbOf(const std::string& file, int& width, int& height) {
    OIIO::ImageBuf b(file);
    EXPECT_TRUE(b.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << b.geterror();
    width = b.spec().width;
    height = b.spec().height;
    std::vector<float> v(size_t(width) * size_t(height) * 3);
    b.get_pixels(OIIO::ROI(0, width, 0, height, 0, 1, 0, 3), OIIO::TypeDesc::FLOAT, v.data());
    return v;
}

/// relMSE as `mcstat --diff` reports it: mean of (a - r)^2 / (r^2 + 0.01) over the channels.
double relMse(const std::vector<float>& a, const std::vector<float>& r) {
    double s = 0;
    for (size_t i = 0; i < a.size(); ++i) {
        const double d = double(a[i]) - r[i];
        s += d * d / (double(r[i]) * r[i] + 0.01);
    }
    return s / double(a.size());
}

TEST_F(RpfFile, RendersTheFieldsAndTheyReadBackByName) {
    const std::string f = path("dof.mcstat");
    ASSERT_EQ(render("--scene dof --res 16 12 --spp 3 --keep-samples -o " + f).code, 0);
    SampleRecordsReader r;
    std::string err;
    ASSERT_TRUE(r.open(f, err)) << err;
    // The dof scene has a lens but nothing moves: lens yes, time no.
    const std::vector<std::string> want{"R",      "G",  "B",  "Z",  "screen", "lens", "light",
                                        "bounce", "N1", "P1", "T1", "N2",     "P2"};
    EXPECT_EQ(r.fields(), want);
    SampleBlock b;
    ASSERT_TRUE(r.select({"screen.x", "screen.y", "rand.lens.u", "rand.lens.v"}, err)) << err;
    ASSERT_TRUE(r.read(5, 2, b, err)) << err;
    ASSERT_EQ(b.stride(), 8u);
    size_t k = 0;
    for (int y = 5; y < 7; ++y)
        for (int x = 0; x < 16; ++x) {
            ASSERT_EQ(b.counts[size_t((y - 5) * 16 + x)], 3u);
            for (int i = 0; i < 3; ++i, ++k) {
                const float* s = b.samples.data() + k * b.stride();
                EXPECT_GE(s[4], float(x));  // the sample lies in its pixel
                EXPECT_LT(s[4], float(x + 1));
                EXPECT_GE(s[5], float(y));
                EXPECT_LT(s[5], float(y + 1));
                EXPECT_LE(s[6] * s[6] + s[7] * s[7], 1.0f + 1e-6f);  // unit disk
            }
        }
    EXPECT_FALSE(r.select({"rand.time"}, err));
    EXPECT_NE(err.find("rand.time"), std::string::npos) << err;
}

TEST_F(RpfFile, SameResultForAnyBlockHeightAndThreadCount) {
    const std::string f = path("m.mcstat");
    ASSERT_EQ(render("--scene motion --res 20 40 --spp 4 --keep-samples -o " + f).code, 0);
    // Blocks of 7 output rows carry a 27+17+8+3-row halo each; one thread or two.
    ASSERT_EQ(mcstat(f + " --threads 1 --rpf -o " + path("a.exr")).code, 0);
    ASSERT_EQ(mcstat(f + " --threads 2 --rpf:rows=7 -o " + path("b.exr")).code, 0);
    int w = 0, h = 0;
    const std::vector<float> a = rgbOf(path("a.exr"), w, h), b = rgbOf(path("b.exr"), w, h);
    ASSERT_EQ(w, 20);
    ASSERT_EQ(h, 40);
    EXPECT_EQ(a, b);
    // Four threads share out chunks of a few pixels (the records decoded on threads too).
    ASSERT_EQ(mcstat(f + " --threads 4 --rpf -o " + path("d.exr")).code, 0);
    EXPECT_EQ(a, rgbOf(path("d.exr"), w, h));
    // A different seed draws other neighbourhoods: a different image.
    ASSERT_EQ(mcstat(f + " --rpf:seed=5 -o " + path("c.exr")).code, 0);
    EXPECT_NE(a, rgbOf(path("c.exr"), w, h));
}

TEST_F(RpfFile, BeatsTheInputOnDepthOfField) {
    // 48 x 48 of the dof scene at 8 spp: RPF's relMSE against a 1024-spp reference is well
    // below the plain mean's (0.016 against 0.038 when this was written): it removes the noise
    // of the walls and of the out-of-focus spheres. (The absolute squared error is dominated by
    // the light's edge pixels, radiance 17, where the two are about even.)
    const std::string f = path("d.mcstat");
    ASSERT_EQ(render("--scene dof --res 48 48 --spp 8 --seed 3 --keep-samples -o " + f).code, 0);
    ASSERT_EQ(render("--scene dof --res 48 48 --spp 1024 --reference -o " + path("ref.exr")).code,
              0);
    ASSERT_EQ(mcstat(f + " --mean -o " + path("mean.exr")).code, 0);
    ASSERT_EQ(mcstat(f + " --rpf -o " + path("rpf.exr")).code, 0);
    int w = 0, h = 0;
    const std::vector<float> ref = rgbOf(path("ref.exr"), w, h);
    const double mc = relMse(rgbOf(path("mean.exr"), w, h), ref);
    const double rpf = relMse(rgbOf(path("rpf.exr"), w, h), ref);
    EXPECT_LT(rpf, 0.6 * mc) << "mean " << mc << " rpf " << rpf;
}

TEST_F(RpfFile, RefusesFilesWithoutItsFields) {
    // No records at all.
    const std::string plain = path("plain.mcstat");
    ASSERT_EQ(render("--scene tiny --res 8 6 --spp 2 -o " + plain).code, 0);
    ToolRun r = mcstat(plain + " --rpf -o " + path("o.exr"));
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find("--keep-samples"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("o.exr")));

    // Records with only R, G, B, Z (as a version-4 writer before the fields, or another tool).
    StatsImage img;
    std::string err;
    ASSERT_TRUE(readStatsFile(plain, img, err)) << err;
    img.header.formatVersion = kStatsFormatVersionSamples;
    SampleRecordsWriter w;
    const std::string base = path("base.mcstat");
    ASSERT_TRUE(w.open(base, img.header, err)) << err;
    SampleBlock b;
    b.clear(0, img.header.height, img.header.width);
    for (uint32_t& c : b.counts) c = 1;
    b.samples.assign(b.counts.size() * 4, 0.5f);
    ASSERT_TRUE(w.write(b, err)) << err;
    ASSERT_TRUE(w.close(err)) << err;
    StatsExtras extras;
    extras.recordsFile = w.path();
    ASSERT_TRUE(writeStatsFile(base, img, extras, err)) << err;
    r = mcstat(base + " --rpf -o " + path("o.exr"));
    EXPECT_NE(r.code, 0);
    for (const char* named : {"screen", "rand.", "N1"})
        EXPECT_NE(r.err.find(named), std::string::npos) << named << ": " << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("o.exr")));
    // Pajot still reads such a file.
    EXPECT_EQ(mcstat(base + " --pajot:method=rot -o " + path("p.exr")).code, 0);
}

}  // namespace
}  // namespace mcstat
