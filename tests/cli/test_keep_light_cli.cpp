// `mcstat --OP:keeplight=1` end to end (docs/keep-light.md): the plain mean's light in every
// channel and AOV, light-path AOVs that still sum to the beauty, every channel kept, a compact
// file's pixels equal to the full file's, the same bits at any thread count, the 3D filters, and
// the one-line refusals.
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "cli_support.h"

namespace {

struct Channels {
    OIIO::ImageSpec spec;
    std::map<std::string, std::vector<float>> px;
    double sum(const std::string& c) const {
        double s = 0.0;
        for (float v : px.at(c)) s += v;
        return s;
    }
};

Channels readChannels(const std::string& file) {
    Channels out;
    OIIO::ImageBuf b(file);
    EXPECT_TRUE(b.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << b.geterror();
    out.spec = b.spec();
    const size_t n = size_t(out.spec.width) * size_t(out.spec.height);
    std::vector<float> all(n * size_t(out.spec.nchannels));
    b.get_pixels(b.roi(), OIIO::TypeDesc::FLOAT, all.data());
    for (int c = 0; c < out.spec.nchannels; ++c) {
        std::vector<float>& v = out.px[out.spec.channelnames[size_t(c)]];
        for (size_t p = 0; p < n; ++p) v.push_back(all[p * size_t(out.spec.nchannels) + size_t(c)]);
    }
    return out;
}

/// The plain mean, G-MoN and G-MoN with :keeplight=1 of one render.
struct MeanGmonKeepLight {
    Channels mean, gmon, kl;
};

class KeepLightCli : public mcstat::testing::CliFixture {
  protected:
    void render(const std::string& args, const std::string& out) const {
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) + " --quiet --res 48 36 --M 9 " +
                                args + " -o " + path(out);
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
    }
    /// Renders `args` and runs the three images of it.
    MeanGmonKeepLight threeImages(const std::string& args) {
        render(args, "f.mcstat");
        const mcstat::testing::Result r = mcstat(
            path("f.mcstat") + " --dup --mean -o " + path("mean.exr") + " --pop --dup --gmon -o " +
            path("gmon.exr") + " --pop --gmon:keeplight=1 -o " + path("kl.exr"));
        EXPECT_EQ(r.code, 0) << r.err;
        return {readChannels(path("mean.exr")), readChannels(path("gmon.exr")),
                readChannels(path("kl.exr"))};
    }
};

bool sameBits(const Channels& a, const Channels& b) {
    if (a.px.size() != b.px.size()) return false;
    for (const auto& [name, v] : a.px) {
        const auto it = b.px.find(name);
        if (it == b.px.end() || it->second.size() != v.size() ||
            std::memcmp(v.data(), it->second.data(), v.size() * sizeof(float)) != 0)
            return false;
    }
    return true;
}

const char* const kPaths[] = {"emission",         "background",      "diffuse_direct",
                              "diffuse_indirect", "specular_direct", "specular_indirect"};

TEST_F(KeepLightCli, ThePlainMeansLightInEveryChannelAndAovsStillSum) {
    const auto [mean, gmon, kl] = threeImages("--scene default --spp 64 --aovs --seed 3");
    EXPECT_EQ(kl.spec.channelnames, gmon.spec.channelnames);  // nothing dropped, nothing added
    // G-MoN took light (so the test can fail); keeplight gives all of it back, per channel.
    EXPECT_LT(gmon.sum("R"), 0.995 * mean.sum("R"));
    for (const std::string& c : kl.spec.channelnames) {
        if (!mean.px.count(c)) continue;
        EXPECT_NEAR(kl.sum(c), mean.sum(c), 2e-6 * std::fabs(mean.sum(c)) + 1e-6) << c;
    }
    EXPECT_GT(kl.spec.get_float_attribute("mcstat:keeplight:returned"), 0.005f);
    // The light-path AOVs summed to the beauty in every buffer: still, pixel by pixel.
    for (const char* rgb : {"R", "G", "B"})
        for (size_t p = 0; p < kl.px.at("R").size(); ++p) {
            double sum = 0.0;
            for (const char* aov : kPaths) sum += kl.px.at(std::string(aov) + "." + rgb)[p];
            const double beauty = kl.px.at(rgb)[p];
            ASSERT_NEAR(sum, beauty, 1e-5 * std::fabs(beauty) + 1e-6) << rgb << " pixel " << p;
        }
}

// Rule 5 end to end (docs/keep-light.md): at the edges of the dof scene's defocused light, pixels
// whose 3 x 3 neighbours' G-MoN median lies nearer their plain mean than their G-MoN value keep
// their light: the light-keeping image is their mean, up to the little that wide senders bring.
// Without the robust luminance in the stream (or with the wrong one) they go wide and stay near
// G-MoN's value, a whole residual away.
TEST_F(KeepLightCli, AnEdgesPixelsKeepTheirLightWhereTheirNeighboursSaySo) {
    const auto [mean, gmon, kl] = threeImages("--scene dof --spp 64 --seed 3");
    const int w = kl.spec.width, h = kl.spec.height;
    // The fixture writes linear Rec.709: its luminance.
    auto lum = [w](const Channels& c, int x, int y) {
        const size_t p = size_t(y) * size_t(w) + size_t(x);
        return 0.2126 * c.px.at("R")[p] + 0.7152 * c.px.at("G")[p] + 0.0722 * c.px.at("B")[p];
    };
    int kept = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const double m = lum(mean, x, y), g = lum(gmon, x, y), d = m - g;
            // A residual far above the light that wide senders bring (about 0.001 a pixel here).
            if (std::fabs(d) < 0.02) continue;
            std::vector<double> win;
            for (int j = std::max(0, y - 1); j <= std::min(h - 1, y + 1); ++j)
                for (int i = std::max(0, x - 1); i <= std::min(w - 1, x + 1); ++i)
                    win.push_back(lum(gmon, i, j));
            std::sort(win.begin(), win.end());
            const size_t n = win.size();
            const double median = n % 2 ? win[n / 2] : 0.5 * (win[n / 2 - 1] + win[n / 2]);
            if (!(std::fabs(m - median) < std::fabs(g - median))) continue;
            ++kept;
            EXPECT_NEAR(lum(kl, x, y), m, 0.1 * std::fabs(d)) << x << "," << y << " gmon " << g;
        }
    EXPECT_GE(kept, 2);  // the light's edges (four pixels with this seed)
}

TEST_F(KeepLightCli, ACompactFileGivesTheFullFilesPixels) {
    render("--scene caustic --spp 256 --aovs --seed 5", "f.mcstat");
    ASSERT_EQ(mcstat(path("f.mcstat") + " --compact -o " + path("c.mcstat")).code, 0);
    for (const char* f : {"f", "c"}) {
        const mcstat::testing::Result r =
            mcstat(path(std::string(f) + ".mcstat") + " --gmon:keeplight=1 -o " +
                   path(f + std::string(".exr")));
        ASSERT_EQ(r.code, 0) << r.err;
    }
    EXPECT_TRUE(sameBits(readChannels(path("f.exr")), readChannels(path("c.exr"))));
}

TEST_F(KeepLightCli, TheSameBitsForAnyThreadCount) {
    render("--scene caustic --spp 128 --seed 2", "f.mcstat");
    for (const char* t : {"1", "3"})
        ASSERT_EQ(mcstat("--threads " + std::string(t) + " " + path("f.mcstat") +
                         " --gmon:keeplight=1 -o " + path(std::string("t") + t + ".exr"))
                      .code,
                  0);
    EXPECT_TRUE(sameBits(readChannels(path("t1.exr")), readChannels(path("t3.exr"))));
}

TEST_F(KeepLightCli, The3dFiltersKeepTheLightToo) {
    render("--scene default --spp 64 --seed 4", "f.mcstat");
    const mcstat::testing::Result r = mcstat(
        path("f.mcstat") + " --dup --mean -o " + path("mean.exr") + " --pop --dup --3dwtmf -o " +
        path("f3.exr") + " --pop --3dwtmf:keeplight=1 -o " + path("kl.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    const Channels mean = readChannels(path("mean.exr")), f3 = readChannels(path("f3.exr")),
                   kl = readChannels(path("kl.exr"));
    for (const char* c : {"R", "G", "B"}) {
        EXPECT_GT(std::fabs(f3.sum(c) - mean.sum(c)), 1e-3 * mean.sum(c)) << c;
        EXPECT_NEAR(kl.sum(c), mean.sum(c), 2e-6 * mean.sum(c)) << c;
    }
}

// --contactsheet:keeplight=1: every listed estimator's tile with its light back, its --diff line
// the command's.
TEST_F(KeepLightCli, TheContactSheetShowsTheLightKept) {
    // The reference is only compared against, never judged: another 64-spp render serves (1,024
    // spp took more than every other render of this file together).
    render("--scene caustic --spp 64 --seed 6", "f.mcstat");
    render("--scene caustic --spp 64 --seed 99 --reference", "ref.exr");
    const mcstat::testing::Result one =
        mcstat(path("f.mcstat") + " --gmon:keeplight=1 --diff " + path("ref.exr"));
    ASSERT_EQ(one.code, 0) << one.err;
    const mcstat::testing::Result sheet =
        mcstat(path("f.mcstat") + " --contactsheet:estimators=gmon,tmpe:keeplight=1 " +
               path("ref.exr") + " -o " + path("sheet.png"));
    ASSERT_EQ(sheet.code, 0) << sheet.err;
    const std::string line = one.out.substr(one.out.find(" relMSE"));
    EXPECT_NE(sheet.out.find("gmon:keeplight=1(" + path("f.mcstat") + ")" + line),
              std::string::npos)
        << sheet.out << " vs " << one.out;
    EXPECT_NE(sheet.out.find("tmpe:keeplight=1("), std::string::npos) << sheet.out;
    EXPECT_NE(sheet.out.find("mean(" + path("f.mcstat") + ")"), std::string::npos) << sheet.out;
}

TEST_F(KeepLightCli, RefusalsAreOneLine) {
    render("--scene tiny --spp 16 --seed 1", "f.mcstat");
    const std::string f = path("f.mcstat");
    struct Case {
        std::string args, says;
    };
    const std::vector<Case> cases = {
        {" --gmon:keeplightgamma=2", "--gmon: keeplightgamma needs keeplight=1"},
        {" --gmon:keeplight=1:ci=0.9", "keeplight and ci"},
        {" --gmon:keeplight=1:keeplightgamma=0", "keeplightgamma"},
        {" --gmon:keeplight=1:keeplightradius=-1", "keeplightradius"},
        {" --mean --mif:keeplight=1", "has no modifier 'keeplight'"},
    };
    for (const Case& c : cases) {
        const mcstat::testing::Result r = mcstat(f + c.args + " -o " + path("x.exr"));
        EXPECT_EQ(r.code, 1) << c.args << ": " << r.err;
        EXPECT_NE(r.err.find(c.says), std::string::npos) << c.args << ": " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
}

}  // namespace
