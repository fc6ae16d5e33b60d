// `mcstat --compact` and `mcstat-render --compact` as a user runs them (docs/compact.md): G-MoN of
// the compact file equals the full file's bit for bit, with AOVs; --info and --check describe it;
// --compare full against compact finds them the same; --merge and --compare:aovs= refuse compact
// files with one line; the command stays on the stack (frame patterns, an ingest compacted on the
// fly).
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "cli_support.h"
#include "mcstat/exr-deep/stats_file.h"

using namespace mcstat;

namespace {

class CompactCli : public mcstat::testing::CliFixture {
  protected:
    /// Renders the default scene small, fixed M = 9, with AOVs, into `name`.
    void render(const std::string& name, const std::string& extra = "") const {
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                                " --res 40 30 --spp 90 --M 9 --aovs --seed 3 --quiet " + extra +
                                " -o " + path(name);
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
    }
};

/// Whether two images have the same channels and the same bits in every one.
bool sameBits(const std::string& a, const std::string& b, std::string& why) {
    OIIO::ImageBuf A(a), B(b);
    if (!A.read(0, 0, true, OIIO::TypeFloat) || !B.read(0, 0, true, OIIO::TypeFloat)) {
        why = A.geterror() + B.geterror();
        return false;
    }
    if (A.spec().channelnames != B.spec().channelnames || A.roi() != B.roi()) {
        why = "channels or windows differ";
        return false;
    }
    const size_t n = A.spec().image_bytes();
    if (std::memcmp(A.localpixels(), B.localpixels(), n) != 0) {
        why = "pixels differ";
        return false;
    }
    return true;
}

TEST_F(CompactCli, GMoNOfTheCompactFileIsTheFullFilesBitForBit) {
    render("full.mcstat");
    auto r = mcstat(path("full.mcstat") + " --compact -o " + path("small.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_LT(OIIO::Filesystem::file_size(path("small.mcstat")),
              OIIO::Filesystem::file_size(path("full.mcstat")));
    for (const char* op : {"--gmon", "--gmon:mode=channel"}) {
        // mode=channel refuses AOVs (no one weight per buffer): tested on a render without below.
        const bool channel = std::strchr(op, '=') != nullptr;
        r = mcstat(path("full.mcstat") + " " + op + " -o " + path("a.exr"));
        if (channel) {
            EXPECT_NE(r.code, 0);
            continue;
        }
        ASSERT_EQ(r.code, 0) << r.err;
        r = mcstat(path("small.mcstat") + " " + op + " -o " + path("b.exr"));
        ASSERT_EQ(r.code, 0) << r.err;
        std::string why;
        EXPECT_TRUE(sameBits(path("a.exr"), path("b.exr"), why)) << op << ": " << why;
    }
    // Channel mode on a render without AOVs.
    const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                            " --res 40 30 --spp 90 --M 9 --seed 4 --quiet -o " +
                            path("plain.mcstat");
    ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0);
    r = mcstat(path("plain.mcstat") + " --dup --compact --gmon:mode=channel -o " + path("c.exr") +
               " --pop --gmon:mode=channel -o " + path("d.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    std::string why;
    EXPECT_TRUE(sameBits(path("c.exr"), path("d.exr"), why)) << why;
}

TEST_F(CompactCli, TheRendererWritesTheSameCompactFile) {
    render("full.mcstat");
    render("direct.mcstat", "--compact");
    auto r = mcstat(path("full.mcstat") + " --compact -o " + path("small.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(mcstat::testing::slurp(path("direct.mcstat")),
              mcstat::testing::slurp(path("small.mcstat")));
    // Options it cannot honour are refused before rendering.
    const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                            " --res 8 8 --spp 4 --adaptive-m --compact -o " + path("x.mcstat") +
                            " 2>" + path("err.txt");
    EXPECT_NE(mcstat::testing::runCommand(cmd.c_str()), 0);
    EXPECT_NE(mcstat::testing::slurp(path("err.txt"))
                  .find("--compact cannot be combined with --adaptive-m"),
              std::string::npos);
}

TEST_F(CompactCli, InfoCheckAndCompare) {
    render("full.mcstat");
    ASSERT_EQ(mcstat(path("full.mcstat") + " --compact -o " + path("small.mcstat")).code, 0);
    auto r = mcstat(path("small.mcstat") + " --info");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("format 8"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("keep their 9 sub-buffers"), std::string::npos) << r.out;
    r = mcstat(path("small.mcstat") + " --check");
    EXPECT_EQ(r.code, 0) << r.err << r.out;
    r = mcstat(path("full.mcstat") + " " + path("small.mcstat") + " --compare");
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    EXPECT_NE(r.out.find("SAME"), std::string::npos) << r.out;
    r = mcstat(path("full.mcstat") + " " + path("small.mcstat") + " --compare:test=yuen");
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    r = mcstat(path("small.mcstat") + " " + path("full.mcstat") + " --compare:aovs=A");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("compact file"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "one line: " << r.err;
}

/// The tile z-scores of a comparison's maps (`-o maps.exr`): one value per 16 x 16 tile.
std::vector<double> tileZ(const std::string& maps) {
    OIIO::ImageBuf b(maps);
    std::vector<double> z;
    if (!b.read(0, 0, true, OIIO::TypeFloat)) return z;
    int c = -1;
    for (int i = 0; i < b.nchannels(); ++i)
        if (b.spec().channelnames[size_t(i)].rfind("tile.z", 0) == 0) c = i;
    if (c < 0) return z;
    for (int y = 0; y < b.spec().height; y += 16)
        for (int x = 0; x < b.spec().width; x += 16) z.push_back(b.getchannel(x, y, 0, c));
    return z;
}

TEST_F(CompactCli, CompareTestsTheTilesOfCompactFilesFromTheirPixelsSpreads) {
    // A tile of a compact file is tested from its pixels' estimates and variances (the stored
    // spread where the buffers were dropped), taken as independent: the detector that catches a
    // light 2 % brighter beyond its emitter pixels (docs/compare.md). Before: no tile tests.
    const std::string light = path("light.json");
    {
        std::ifstream in(std::string(MCSTAT_SOURCE_DIR) + "/render-fixture/scenes/arealight.json");
        std::stringstream text;
        text << in.rdbuf();
        nlohmann::json j = nlohmann::json::parse(text.str(), nullptr, true, true);
        j["shapes"].back()["emission"] = {10.71, 10.71, 10.71};  // the area light, 2 % brighter
        std::ofstream(light) << j.dump(1);
    }
    for (const auto& [scene, name, seed] :
         {std::tuple{std::string("arealight"), "a", 1},
          std::tuple{std::string("arealight"), "s", 2}, std::tuple{light, "l", 2}}) {
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) + " --quiet --scene " + scene +
                                " --res 96 72 --spp 128 --M 16 --seed " + std::to_string(seed) +
                                " -o " + path(std::string(name) + ".mcstat");
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
        ASSERT_EQ(mcstat(path(std::string(name) + ".mcstat") + " --compact -o " +
                         path(std::string(name) + "-c.mcstat"))
                      .code,
                  0);
    }
    auto r = mcstat(path("a-c.mcstat") + " " + path("l-c.mcstat") + " --compare");
    EXPECT_EQ(r.code, 2) << r.out << r.err;
    EXPECT_NE(r.out.find("tiles 16x16: 30 tested of 30"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("tiles 16x16: 30 tested of 30, 0 differ"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("tested from their pixels' means and variances"), std::string::npos)
        << r.out;
    // Same scene, other seeds: no tile differs, and the tile z-scores are the full files' up to
    // the noise of the variance estimates (same renders, two ways of estimating a tile's variance).
    r = mcstat(path("a.mcstat") + " " + path("s.mcstat") + " --compare -o " + path("full.exr"));
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    r = mcstat(path("a-c.mcstat") + " " + path("s-c.mcstat") + " --compare -o " + path("c.exr"));
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    EXPECT_NE(r.out.find("tiles 16x16: 30 tested of 30, 0 differ"), std::string::npos) << r.out;
    const std::vector<double> zf = tileZ(path("full.exr")), zc = tileZ(path("c.exr"));
    ASSERT_EQ(zf.size(), 30u);
    ASSERT_EQ(zc.size(), 30u);
    double mf = 0, mc = 0;
    for (size_t i = 0; i < 30; ++i) {
        mf += zf[i] / 30;
        mc += zc[i] / 30;
    }
    double sff = 0, scc = 0, sfc = 0;
    for (size_t i = 0; i < 30; ++i) {
        sff += (zf[i] - mf) * (zf[i] - mf);
        scc += (zc[i] - mc) * (zc[i] - mc);
        sfc += (zf[i] - mf) * (zc[i] - mc);
    }
    EXPECT_GT(sfc / std::sqrt(sff * scc), 0.9) << "tile z of compact against full files";
    EXPECT_GT(std::sqrt(scc / sff), 0.75);
    EXPECT_LT(std::sqrt(scc / sff), 1.33);
}

TEST_F(CompactCli, MergeAndRecompactAreRefusedWithOneLine) {
    render("a.mcstat");
    ASSERT_EQ(mcstat(path("a.mcstat") + " --compact -o " + path("small.mcstat")).code, 0);
    render("b.mcstat", "--seed 9");
    auto r =
        mcstat(path("small.mcstat") + " " + path("b.mcstat") + " --merge -o " + path("m.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("merge the full files, then --compact"), std::string::npos) << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("m.mcstat")));
    r = mcstat(path("small.mcstat") + " --compact -o " + path("again.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("already compact"), std::string::npos) << r.err;
    r = mcstat(path("a.mcstat") + " --compact:margin=2 -o " + path("x.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("margin"), std::string::npos) << r.err;
    // Adaptive M chose its buffers while rendering.
    const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                            " --res 16 12 --spp 64 --adaptive-m --quiet -o " + path("ad.mcstat");
    ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0);
    r = mcstat(path("ad.mcstat") + " --compact -o " + path("y.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("adaptive M"), std::string::npos) << r.err;
}

TEST_F(CompactCli, MergedThenCompactedMatchesTheMergeCompactedLater) {
    render("a.mcstat");
    render("b.mcstat", "--seed 9");
    auto r = mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --merge --compact -o " +
                    path("direct.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    r = mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --merge -o " + path("m.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    r = mcstat(path("m.mcstat") + " --compact -o " + path("later.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(mcstat::testing::slurp(path("direct.mcstat")),
              mcstat::testing::slurp(path("later.mcstat")));
}

}  // namespace
