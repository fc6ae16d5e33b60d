// `mcstat A B --compare` end to end on the fixture renderer's scenes (docs/compare.md): renders of
// one scene with other seeds pass; changes a user must not miss fail (a light 2 % brighter, an
// albedo 3 % darker on one box, the glass's IOR moved the caustic, bounces missing); the exit
// status, the verdict, the maps; the extremes and the refusals. Every render has a fixed seed, so
// the outcomes (and the false-alarm count over seed pairs) are fixed: nothing here can flake.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli_support.h"

namespace {

using mcstat::testing::Result;

class CompareCli : public mcstat::testing::CliFixture {
  protected:
    /// Writes built-in scene `scene` with `edit` applied to `name`.json and returns its path.
    template <class F>
    std::string sceneVariant(const std::string& scene, const std::string& name, F edit) {
        std::ifstream in(std::string(MCSTAT_SOURCE_DIR) + "/render-fixture/scenes/" + scene +
                         ".json");
        std::stringstream text;
        text << in.rdbuf();
        nlohmann::json j = nlohmann::json::parse(text.str(), nullptr, true, /*comments*/ true);
        edit(j);
        const std::string p = path(name + ".json");
        std::ofstream(p) << j.dump(1);
        return p;
    }
    /// Renders `scene` (a built-in name or a JSON file) to `out` at 64 x 48.
    void render(const std::string& scene, const std::string& out, int seed, int spp = 256,
                int M = 16, const std::string& extra = "") {
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) + " --quiet --scene " + scene +
                                " --res 64 48 --spp " + std::to_string(spp) + " --M " +
                                std::to_string(M) + " --seed " + std::to_string(seed) + " " +
                                extra + " -o " + path(out) + " >/dev/null 2>&1";
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
    }
    Result compare(const std::string& a, const std::string& b, const std::string& mods = "") {
        return mcstat(path(a) + " " + path(b) + " --compare" + mods);
    }
};

std::string firstLine(const std::string& s) { return s.substr(0, s.find('\n')); }

TEST_F(CompareCli, SameSceneOtherSeedsPassesAndChangesAUserMustNotMissFail) {
    render("arealight", "a.mcstat", 1);
    render("arealight", "same.mcstat", 2);
    render(sceneVariant("arealight", "light",
                        [](nlohmann::json& j) {
                            // The area light is the last shape: 2 % more radiance.
                            j["shapes"].back()["emission"] = {10.71, 10.71, 10.71};
                        }),
           "light.mcstat", 2);
    render(
        sceneVariant(
            "arealight", "albedo",
            [](nlohmann::json& j) {
                // The tall box (shape 5) 3 % darker: a small region of the image.
                j["materials"]["box"] = {{"type", "diffuse"}, {"albedo", {0.7081, 0.7081, 0.7081}}};
                j["shapes"][5]["material"] = "box";
            }),
        "albedo.mcstat", 2);
    render(sceneVariant("arealight", "bounce",
                        [](nlohmann::json& j) { j["integrator"]["maxDepth"] = 3; }),
           "bounce.mcstat", 2);
    render("caustic", "ca.mcstat", 1);
    render("caustic", "ca_same.mcstat", 2);
    render(sceneVariant("caustic", "ior",
                        [](nlohmann::json& j) { j["materials"]["glass"]["ior"] = 1.45; }),
           "ca_ior.mcstat", 2);

    Result r = compare("a.mcstat", "same.mcstat", " -o " + path("same.exr"));
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    EXPECT_NE(firstLine(r.out).find("SAME"), std::string::npos) << r.out;
    // The verdict says what it could have seen; minpower holds it to a size: a 20 % change per
    // tile is well within these renders' reach (64 spp, M = 8), a 0.1 % change is not.
    EXPECT_NE(firstLine(r.out).find("in one tile"), std::string::npos) << r.out;
    r = compare("a.mcstat", "same.mcstat", ":minpower=0.2:json=" + path("power.json"));
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    const std::string json = mcstat::testing::slurp(path("power.json"));
    EXPECT_NE(json.find("\"tile_relative\""), std::string::npos) << json;
    EXPECT_NE(json.find("\"underpowered\": false"), std::string::npos) << json;
    r = compare("a.mcstat", "same.mcstat", ":minpower=0.001");
    EXPECT_EQ(r.code, 2) << r.out << r.err;
    EXPECT_NE(firstLine(r.out).find(": UNDERPOWERED: "), std::string::npos) << r.out;
    r = compare("ca.mcstat", "ca_same.mcstat");
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    for (const char* changed : {"light.mcstat", "albedo.mcstat", "bounce.mcstat"}) {
        r = compare("a.mcstat", changed);
        EXPECT_EQ(r.code, 2) << changed << "\n" << r.out << r.err;
        EXPECT_NE(firstLine(r.out).find("DIFFERENT"), std::string::npos) << r.out;
    }
    r = compare("ca.mcstat", "ca_ior.mcstat", " -o " + path("ior.exr"));
    EXPECT_EQ(r.code, 2) << r.out << r.err;
    // The maps say where: the caustic, a small spot, and nothing of the floor around it. Every
    // pixel flagged lies within a box of at most 5 % of the image.
    OIIO::ImageBuf maps(path("ior.exr"));
    ASSERT_TRUE(maps.read()) << maps.geterror();
    const int differs = maps.spec().channelindex("differs");
    ASSERT_GE(differs, 0);
    int flagged = 0, x0 = 64, x1 = -1, y0 = 48, y1 = -1;
    for (int y = 0; y < 48; ++y)
        for (int x = 0; x < 64; ++x)
            if (maps.getchannel(x, y, 0, differs) == 1.f) {
                ++flagged;
                x0 = std::min(x0, x);
                x1 = std::max(x1, x);
                y0 = std::min(y0, y);
                y1 = std::max(y1, y);
            }
    EXPECT_GT(flagged, 3);
    EXPECT_LE((x1 - x0 + 1) * (y1 - y0 + 1), 64 * 48 / 20)
        << x0 << ".." << x1 << ", " << y0 << ".." << y1;
    // Provenance on the maps; the verdict too.
    EXPECT_EQ(maps.spec().get_int_attribute("mcstat.compare.fail"), 1);
    EXPECT_NE(maps.spec().get_string_attribute("mcstat.compare.verdict").find("DIFFERENT"),
              std::string::npos);
}

/// A picture of the page read back as 8-bit values (the PNG's own), R, G, B of pixel (x, y).
std::array<int, 3> pngPixel(const OIIO::ImageBuf& img, int x, int y) {
    float v[3] = {0.f, 0.f, 0.f};
    img.getpixel(x, y, v, 3);
    return {int(std::lround(v[0] * 255.f)), int(std::lround(v[1] * 255.f)),
            int(std::lround(v[2] * 255.f))};
}

bool near(const std::array<int, 3>& a, const std::array<int, 3>& b, int tol) {
    for (int c = 0; c < 3; ++c)
        if (std::abs(a[size_t(c)] - b[size_t(c)]) > tol) return false;
    return true;
}

TEST_F(CompareCli, ReportPageMapsOutlinesTheDifferingTilesAndPaintsExactChanges) {
    // The light 2 % brighter: its pixels differ exactly (no noise on either side), and some
    // tiles of the lit box differ beyond their noise.
    render("arealight", "a.mcstat", 1);
    render(sceneVariant("arealight", "light",
                        [](nlohmann::json& j) {
                            j["shapes"].back()["emission"] = {10.71, 10.71, 10.71};
                        }),
           "light.mcstat", 2);
    Result r =
        compare("a.mcstat", "light.mcstat", ":html=" + path("page") + " -o " + path("maps.exr"));
    ASSERT_EQ(r.code, 2) << r.out << r.err;
    OIIO::ImageBuf maps(path("maps.exr"));
    ASSERT_TRUE(maps.read()) << maps.geterror();
    const int differs = maps.spec().channelindex("tile.differs");
    ASSERT_GE(differs, 0);
    // Every picture of the whole image at one scale: 64 x 48 shown 8 times as large.
    const int s = 8, T = 16 * s;
    std::map<std::string, OIIO::ImageBuf> png;
    for (const char* f : {"a.png", "b.png", "heatmap.png", "outlines.png"}) {
        png[f] = OIIO::ImageBuf(path(std::string("page/") + f));
        ASSERT_TRUE(png[f].read()) << f << png[f].geterror();
        EXPECT_EQ(png[f].spec().width, 64 * s) << f;
        EXPECT_EQ(png[f].spec().height, 48 * s) << f;
    }
    // The outlines frame exactly the tiles the test rejected: a pixel just inside a tile's left
    // edge is the outline's yellow on a differing tile and A's own elsewhere; inside, A's own.
    const std::array<int, 3> yellow{255, 217, 0};
    int outlined = 0, rejected = 0;
    for (int ty = 0; ty < 3; ++ty)
        for (int tx = 0; tx < 4; ++tx) {
            const bool differ = maps.getchannel(tx * 16, ty * 16, 0, differs) == 1.f;
            if (differ) ++rejected;
            const int x = tx * T, y = ty * T + T / 2;
            const std::array<int, 3> edge = pngPixel(png["outlines.png"], x + 1, y);
            const std::array<int, 3> mid = pngPixel(png["outlines.png"], x + T / 2, y);
            if (near(edge, yellow, 1)) ++outlined;
            EXPECT_EQ(near(edge, yellow, 1), differ) << "tile " << tx << ", " << ty;
            if (!differ) {
                EXPECT_EQ(edge, pngPixel(png["a.png"], x + 1, y)) << tx << ", " << ty;
            }
            EXPECT_EQ(mid, pngPixel(png["a.png"], x + T / 2, y)) << tx << ", " << ty;
        }
    EXPECT_GT(rejected, 0) << r.out;
    EXPECT_LT(rejected, 12) << r.out;
    EXPECT_EQ(outlined, rejected);
    // The page: the verdict with its power in one line, the tile map first, every picture named.
    const std::string html = mcstat::testing::slurp(path("page/index.html"));
    const size_t verdict = html.find("<p id=\"verdict\"");
    ASSERT_NE(verdict, std::string::npos);
    const std::string line = html.substr(verdict, html.find("</p>", verdict) - verdict);
    EXPECT_NE(line.find("DIFFERENT"), std::string::npos) << line;
    EXPECT_NE(line.find("in one tile"), std::string::npos) << line;
    EXPECT_NE(line.find("in one pixel with probability 0.8"), std::string::npos) << line;
    EXPECT_EQ(line.find('\n'), std::string::npos) << line;
    EXPECT_EQ(html.find("<img"), html.find("<img id=\"map\"")) << html;
    EXPECT_NE(html.find("tile.z"), std::string::npos);
    for (const char* f : {"colorbar.png", "crop-a.png", "crop-b.png"})
        EXPECT_TRUE(OIIO::Filesystem::exists(path(std::string("page/") + f))) << f;

    // Without tiles, the pixels' map: the light's exact differences (z = +Inf) in the colour of
    // the scale's warm end, not the magenta of NaN, and no NaN/Inf count.
    r = compare("a.mcstat", "light.mcstat",
                ":tile=0:html=" + path("pixels") + " -o " + path("pixels.exr"));
    ASSERT_EQ(r.code, 2) << r.out << r.err;
    OIIO::ImageBuf z(path("pixels.exr")), heat(path("pixels/heatmap.png")),
        bar(path("pixels/colorbar.png"));
    ASSERT_TRUE(z.read() && heat.read() && bar.read())
        << z.geterror() << heat.geterror() << bar.geterror();
    const int zc = z.spec().channelindex("z");
    ASSERT_GE(zc, 0);
    // Where on the colour bar's gradient (row 4, column i at t = (i + 0.5) / width) a colour is.
    const int barW = bar.spec().width;
    auto onBar = [&](const std::array<int, 3>& c) {
        int best = 0, bestD = 1 << 30;
        for (int i = 0; i < barW; ++i) {
            const std::array<int, 3> g = pngPixel(bar, i, 4);
            int d = 0;
            for (int k = 0; k < 3; ++k)
                d += (g[size_t(k)] - c[size_t(k)]) * (g[size_t(k)] - c[size_t(k)]);
            if (d < bestD) {
                bestD = d;
                best = i;
            }
        }
        return best;
    };
    int exact = 0;
    for (int y = 0; y < 48; ++y)
        for (int x = 0; x < 64; ++x)
            if (std::isinf(z.getchannel(x, y, 0, zc))) {
                ++exact;
                EXPECT_GT(z.getchannel(x, y, 0, zc), 0.f);
                const std::array<int, 3> c = pngPixel(heat, x * s + s / 2, y * s + s / 2);
                EXPECT_NE(c, (std::array<int, 3>{255, 0, 255})) << x << ", " << y;
                EXPECT_GE(onBar(c), barW - 3)
                    << x << ", " << y << ": " << c[0] << " " << c[1] << " " << c[2];
            }
    EXPECT_GT(exact, 0);
    EXPECT_EQ(mcstat::testing::slurp(path("pixels/index.html")).find("NaN/Inf"), std::string::npos);
}

TEST_F(CompareCli, FalseAlarmsOverSeedPairsStayNearTheLevel) {
    // Ten pairs of renders of one scene with other seeds, at level 0.05 (a false alarm in about
    // one pair of twenty): at most two of ten is far outside what a calibrated test gives (the
    // chance of three or more is 1.2 %), and a variance too small by a factor of two (the classic
    // error: samples taken as independent of the buffers) alarms in nearly every pair.
    int alarms = 0;
    for (int i = 0; i < 10; ++i) {
        const int s = 100 + 2 * i;
        render("arealight", "x.mcstat", s, 64, 8);
        render("arealight", "y.mcstat", s + 1, 64, 8);
        const Result r = compare("x.mcstat", "y.mcstat", ":level=0.05");
        ASSERT_TRUE(r.code == 0 || r.code == 2) << r.err;
        if (r.code == 2) ++alarms;
    }
    EXPECT_LE(alarms, 2);
}

TEST_F(CompareCli, IdenticalFilesReferenceImagesAndRefusals) {
    render("arealight", "a.mcstat", 1, 64, 8);
    render("arealight", "b.mcstat", 2, 64, 8);
    Result r = compare("a.mcstat", "a.mcstat");
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(firstLine(r.out).find("IDENTICAL"), std::string::npos) << r.out;
    // For CI, where comparing a file with itself must not pass.
    r = compare("a.mcstat", "a.mcstat", ":identical=fail:junit=" + path("identical.xml"));
    EXPECT_EQ(r.code, 2) << r.out << r.err;
    EXPECT_NE(firstLine(r.out).find("IDENTICAL"), std::string::npos) << r.out;
    EXPECT_NE(mcstat::testing::slurp(path("identical.xml")).find("<failure"), std::string::npos);
    // json= and junit= create their folders, as html= does.
    r = compare("a.mcstat", "a.mcstat",
                ":json=" + path("new/json/r.json") + ":junit=" + path("new/junit/r.xml"));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(OIIO::Filesystem::exists(path("new/json/r.json")));
    EXPECT_TRUE(OIIO::Filesystem::exists(path("new/junit/r.xml")));

    // A high-spp reference image (no sub-buffers): a one-sample test, in either stack order. A
    // render that has not yet seen a pixel's rare paths has a lower mean and a smaller spread
    // there, so against a converged reference a few heavy-tailed pixels are flagged
    // (docs/compare.md, "Against a reference image"): under 1 % of them; a 10 % brighter light
    // is flagged in most tiles.
    auto reference = [&](const std::string& scene, const std::string& out) {
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) + " --quiet --scene " + scene +
                                " --res 64 48 --spp 2048 --seed 9 --reference -o " + path(out);
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0);
    };
    reference("arealight", "ref.exr");
    reference(sceneVariant("arealight", "bright",
                           [](nlohmann::json& j) {
                               j["shapes"].back()["emission"] = {11.55, 11.55, 11.55};
                           }),
              "bright.exr");
    auto flaggedPixels = [](const std::string& out) {
        const size_t at = out.find("pixels: ");
        if (at == std::string::npos) return -1L;
        const size_t comma = out.find(", ", at);
        return std::stol(out.substr(comma + 2));
    };
    auto flaggedTiles = [](const std::string& out) {
        const size_t at = out.find("tiles 16x16: ");
        if (at == std::string::npos) return -1L;
        const size_t comma = out.find(", ", at);
        return std::stol(out.substr(comma + 2));
    };
    r = mcstat(path("ref.exr") + " " + path("b.mcstat") + " --compare:refspp=2048");
    EXPECT_NE(r.out.find("against the reference"), std::string::npos) << r.out;
    const long sameFlagged = flaggedPixels(r.out);
    EXPECT_GE(sameFlagged, 0) << r.out;
    EXPECT_LT(sameFlagged, 64 * 48 / 100) << r.out;
    r = mcstat(path("b.mcstat") + " " + path("bright.exr") + " --compare:refspp=2048");
    EXPECT_EQ(r.code, 2) << r.out << r.err;
    EXPECT_GE(flaggedTiles(r.out), 9) << r.out;  // of 12
    // Yuen's trimmed mean is not the mean a reference image holds.
    r = mcstat(path("ref.exr") + " " + path("b.mcstat") + " --compare:test=yuen");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("yuen"), std::string::npos) << r.err;

    // M = 1: no variance. One line naming the file, exit 1.
    render("arealight", "one.mcstat", 3, 16, 1);
    r = compare("a.mcstat", "one.mcstat");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("one.mcstat"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("M = 1"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    // Different sizes.
    const std::string small = std::string(MCSTAT_RENDER_EXE) +
                              " --quiet --scene arealight --res 32 24 --spp 16 --M 4 -o " +
                              path("small.mcstat");
    ASSERT_EQ(mcstat::testing::runCommand(small.c_str()), 0);
    r = compare("a.mcstat", "small.mcstat");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("data windows"), std::string::npos) << r.err;
    // Two images: that is --diff's job.
    r = mcstat(path("ref.exr") + " " + path("ref.exr") + " --compare");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("--diff"), std::string::npos) << r.err;
    // One item only, a bad modifier, an equivalence test without a tolerance.
    EXPECT_EQ(mcstat(path("a.mcstat") + " --compare").code, 1);
    r = compare("a.mcstat", "b.mcstat", ":level=2");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("level"), std::string::npos) << r.err;
    r = compare("a.mcstat", "b.mcstat", ":equivalence=1");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("tolerance"), std::string::npos) << r.err;
    r = compare("a.mcstat", "b.mcstat", ":refspp=100");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("refspp"), std::string::npos) << r.err;
}

TEST_F(CompareCli, ExitStatusOutlivesLaterCommandsAndTheMapsAreWritten) {
    render("arealight", "a.mcstat", 1, 64, 8);
    render(sceneVariant("arealight", "bounce",
                        [](nlohmann::json& j) { j["integrator"]["maxDepth"] = 1; }),
           "b.mcstat", 2, 64, 8);
    const Result r = compare(
        "a.mcstat", "b.mcstat",
        ":channels=rgb -o " + path("maps.exr") + " --heatmap:channel=z.G -o " + path("z.png"));
    EXPECT_EQ(r.code, 2) << r.err;
    OIIO::ImageBuf maps(path("maps.exr"));
    ASSERT_TRUE(maps.init_spec(path("maps.exr"), 0, 0)) << maps.geterror();
    for (const char* c : {"p.R", "z.G", "effect.B", "differs.R", "tile.p.G", "tile.differs.B"})
        EXPECT_GE(maps.spec().channelindex(c), 0) << c;
    EXPECT_EQ(maps.spec().width, 64);
    EXPECT_TRUE(OIIO::Filesystem::exists(path("z.png")));

    // The contact sheet's last tile: the comparison against another file, with its verdict.
    const Result s = mcstat(path("b.mcstat") + " --contactsheet:compare=" + path("a.mcstat") + " " +
                            path("a.mcstat") + " -o " + path("sheet.png"));
    EXPECT_EQ(s.code, 0) << s.err;
    EXPECT_NE(s.out.find("DIFFERENT"), std::string::npos) << s.out;
    ASSERT_EQ(mcstat(path("b.mcstat") + " --contactsheet " + path("a.mcstat") + " -o " +
                     path("sheet4.png"))
                  .code,
              0);
    OIIO::ImageBuf five(path("sheet.png")), four(path("sheet4.png"));
    ASSERT_TRUE(five.init_spec(path("sheet.png"), 0, 0)) << five.geterror();
    ASSERT_TRUE(four.init_spec(path("sheet4.png"), 0, 0)) << four.geterror();
    // One more tile (64 px at the default scale 4) and its margin (8 px).
    EXPECT_EQ(five.spec().width - four.spec().width, 64 * 4 + 8);
}

}  // namespace
