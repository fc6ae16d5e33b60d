// Colour-managed renders (docs/color.md, issue 33): the working space of the inputs is read,
// kept in the statistics file, labelled on every result and used for the luminance. The same 21
// seed renders in Rec.709 and in ACEScg (built here from real renders by the ACES Rec.709 -> AP1
// matrix) give G-MoN results that agree after conversion, pixel by pixel.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "../cli/cli_support.h"
#include "mcstat/color/color.h"
#include "mcstat/core/color_space.h"
#include "mcstat/ingest/ingest.h"

namespace mcstat::testing {
namespace {

// Rec.709 -> ACEScg (AP1) as in the ACES reference configs (Bradford D65 -> ACES white).
const double kToAp1[3][3] = {{0.6130974024, 0.3395231462, 0.0473794514},
                             {0.0701937225, 0.9163538791, 0.0134523985},
                             {0.0206155929, 0.1095697729, 0.8698146342}};

std::vector<float> readRGB(const std::string& path, OIIO::ImageSpec& spec) {
    OIIO::ImageBuf in(path);
    EXPECT_TRUE(in.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << in.geterror();
    spec = in.spec();
    std::vector<float> px(size_t(spec.width) * size_t(spec.height) * 3);
    OIIO::ROI rgb = in.roi();  // the first three channels: R, G, B
    rgb.chbegin = 0;
    rgb.chend = std::min(3, spec.nchannels);
    in.get_pixels(rgb, OIIO::TypeDesc::FLOAT, px.data());
    return px;
}

void writeRGB(const std::string& path, int w, int h, const std::vector<float>& rgb,
              const std::string& space, bool tag) {
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::FLOAT);
    spec.attribute("mcstat:spp", 8);
    if (tag) {
        const WorkingSpace* ws = findWorkingSpace(space);
        const Chromaticities& c = ws->xy;
        const float xy[8] = {float(c.rx), float(c.ry), float(c.gx), float(c.gy),
                             float(c.bx), float(c.by), float(c.wx), float(c.wy)};
        spec.attribute("chromaticities", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8), xy);
        if (space == "ACEScg") spec.attribute("colorInteropID", "lin_ap1_scene");
    }
    auto out = OIIO::ImageOutput::create(path);
    ASSERT_TRUE(out && out->open(path, spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, rgb.data()));
    out->close();
}

class IngestColor : public CliFixture {
  protected:
    static constexpr int kW = 32, kH = 24, kSeeds = 21;
    /// Seed s of the default scene (8 spp), its RGB in Rec.709.
    std::vector<float> render(int s) {
        const std::string plain = path(OIIO::Strutil::fmt::format("plain{}.exr", s));
        const std::string cmd =
            std::string(MCSTAT_RENDER_EXE) +
            OIIO::Strutil::fmt::format(" --scene default --res {} {} --spp 8 --seed {} --quiet -o ",
                                       kW, kH, 1000 + s) +
            plain;
        EXPECT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
        OIIO::ImageSpec spec;
        return readRGB(plain, spec);
    }
    /// Writes every seed as rec709_sN.exr (Rec.709 chromaticities) and ap1_sN.exr (converted,
    /// AP1 chromaticities and colorInteropID lin_ap1_scene), and untagged ones untagged_sN.exr.
    void writeBoth() {
        for (int s = 1; s <= kSeeds; ++s) {
            const std::vector<float> rgb = render(s);
            std::vector<float> ap1(rgb.size());
            for (size_t p = 0; p < rgb.size() / 3; ++p)
                for (int r = 0; r < 3; ++r)
                    ap1[p * 3 + size_t(r)] =
                        float(kToAp1[r][0] * rgb[p * 3] + kToAp1[r][1] * rgb[p * 3 + 1] +
                              kToAp1[r][2] * rgb[p * 3 + 2]);
            writeRGB(path(OIIO::Strutil::fmt::format("rec709_s{}.exr", s)), kW, kH, rgb,
                     "lin_rec709", true);
            writeRGB(path(OIIO::Strutil::fmt::format("ap1_s{}.exr", s)), kW, kH, ap1, "ACEScg",
                     true);
            writeRGB(path(OIIO::Strutil::fmt::format("untagged_s{}.exr", s)), kW, kH, ap1, "",
                     false);
        }
    }
};

/// The part-0 header of a statistics file as OIIO's OpenEXR reader shows it (any EXR tool).
OIIO::ImageSpec part0(const std::string& path) {
    auto in = OIIO::ImageInput::create("openexr");
    OIIO::ImageSpec s;
    EXPECT_TRUE(in && in->open(path, s)) << path;
    in->close();
    return s;
}

void expectLabelled(const OIIO::ImageSpec& s, const char* space, const std::string& what) {
    const WorkingSpace* ws = findWorkingSpace(space);
    const OIIO::ParamValue* c = s.find_attribute("chromaticities");
    ASSERT_NE(c, nullptr) << what;
    ASSERT_EQ(c->type(), OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8)) << what;
    const float* v = static_cast<const float*>(c->data());
    EXPECT_EQ(v[0], float(ws->xy.rx)) << what;
    EXPECT_EQ(v[3], float(ws->xy.gy)) << what;
    EXPECT_EQ(v[6], float(ws->xy.wx)) << what;
    EXPECT_EQ(s.get_string_attribute("colorInteropID"), ws->interopID) << what;
}

TEST_F(IngestColor, AcesAndRec709VersionsOfTheSameRendersGiveTheSameGMoN) {
    writeBoth();
    // The fixture renderer labels its own output.
    OIIO::ImageSpec fixture;
    readRGB(path("plain1.exr"), fixture);
    EXPECT_EQ(fixture.get_string_attribute("colorInteropID"), "lin_rec709_scene");
    const Result a = mcstat("--ingest '" + path("rec709_s*.exr") + "' -o " + path("rec709.mcstat") +
                            " --gmon -o " + path("gmon709.exr"));
    ASSERT_EQ(a.code, 0) << a.err;
    const Result b = mcstat("--threads 1 --ingest '" + path("ap1_s*.exr") + "' -o " +
                            path("ap1.mcstat") + " --gmon -o " + path("gmonap1.exr"));
    ASSERT_EQ(b.code, 0) << b.err;
    EXPECT_EQ(b.err, "");

    // The statistics file and the result say AP1, as stock EXR tools read them.
    const Result info = mcstat(path("ap1.mcstat") + " --info");
    EXPECT_NE(info.out.find("ACEScg"), std::string::npos) << info.out;
    expectLabelled(part0(path("ap1.mcstat")), "ACEScg", "ap1.mcstat part 0");
    expectLabelled(part0(path("rec709.mcstat")), "lin_rec709", "rec709.mcstat part 0");
    OIIO::ImageSpec s709, sap1;
    const std::vector<float> g709 = readRGB(path("gmon709.exr"), s709);
    const std::vector<float> gap1 = readRGB(path("gmonap1.exr"), sap1);
    expectLabelled(sap1, "ACEScg", "gmonap1.exr");
    expectLabelled(s709, "lin_rec709", "gmon709.exr");

    // Every pixel: G-MoN of the AP1 renders = the Rec.709 G-MoN converted to AP1, up to float
    // rounding (the inputs were rounded to float once, the averages once more).
    int differing = 0;
    double worst = 0.0;
    for (size_t p = 0; p < g709.size() / 3; ++p) {
        bool same = true;
        for (int r = 0; r < 3; ++r) {
            const double want = kToAp1[r][0] * g709[p * 3] + kToAp1[r][1] * g709[p * 3 + 1] +
                                kToAp1[r][2] * g709[p * 3 + 2];
            const double d = std::abs(double(gap1[p * 3 + size_t(r)]) - want);
            const double scale = std::abs(g709[p * 3]) + std::abs(g709[p * 3 + 1]) +
                                 std::abs(g709[p * 3 + 2]) + 1e-6;
            worst = std::max(worst, d / scale);
            same = same && d <= 1e-6 * scale;
        }
        differing += !same;
    }
    EXPECT_EQ(differing, 0) << "worst difference relative to the pixel " << worst;
    std::printf("G-MoN in ACEScg against G-MoN in Rec.709 converted: worst %.3g of the pixel\n",
                worst);

    // The check can fail: the same AP1 pixels taken as Rec.709 (untagged, so Rec.709's luma on
    // AP1 values, what ingest did before it read the space) decide differently somewhere.
    const Result c =
        mcstat("--ingest '" + path("untagged_s*.exr") + "' --gmon -o " + path("gmonwrong.exr"));
    ASSERT_EQ(c.code, 0) << c.err;
    OIIO::ImageSpec sw;
    const std::vector<float> gw = readRGB(path("gmonwrong.exr"), sw);
    int wrong = 0;
    for (size_t i = 0; i < gw.size(); ++i)
        wrong += std::abs(gw[i] - gap1[i]) > 1e-5f * (1e-3f + std::abs(gap1[i]));
    std::printf("the same with Rec.709's luma on AP1 values: %d values differ\n", wrong);
    EXPECT_GT(wrong, 0);
}

TEST_F(IngestColor, UntaggedRendersTakeTheColorspaceModifier) {
    writeBoth();
    const Result r = mcstat("--ingest:colorspace=lin_ap1_scene '" + path("untagged_s*.exr") +
                            "' -o " + path("u.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    expectLabelled(part0(path("u.mcstat")), "ACEScg", "u.mcstat part 0");
    const Result bad = mcstat("--ingest:colorspace=ACEScct '" + path("untagged_s*.exr") + "' -o " +
                              path("v.mcstat"));
    EXPECT_NE(bad.code, 0);
    EXPECT_EQ(std::count(bad.err.begin(), bad.err.end(), '\n'), 1) << bad.err;
    EXPECT_NE(bad.err.find("colorspace 'ACEScct' is unknown"), std::string::npos) << bad.err;
}

TEST_F(IngestColor, MixedSpacesAndUnknownSpacesAreRefusedInOneLine) {
    writeBoth();
    // ap1_s1..s21 and rec709_s1: two spaces, both files named.
    std::string list = path("rec709_s1.exr");
    for (int s = 2; s <= 4; ++s) list += "," + path(OIIO::Strutil::fmt::format("ap1_s{}.exr", s));
    const Result mixed = mcstat("--ingest '" + list + "' -o " + path("m.mcstat"));
    EXPECT_NE(mixed.code, 0);
    EXPECT_EQ(std::count(mixed.err.begin(), mixed.err.end(), '\n'), 1) << mixed.err;
    EXPECT_NE(mixed.err.find("rec709_s1.exr is lin_rec709 (chromaticities)"), std::string::npos)
        << mixed.err;
    EXPECT_NE(mixed.err.find("ap1_s2.exr is ACEScg (colorInteropID lin_ap1_scene)"),
              std::string::npos)
        << mixed.err;

    // An unknown colorInteropID and chromaticities of no known space.
    std::vector<float> rgb(size_t(kW) * kH * 3, 0.5f);
    OIIO::ImageSpec spec(kW, kH, 3, OIIO::TypeDesc::FLOAT);
    spec.attribute("mcstat:spp", 8);
    spec.attribute("colorInteropID", "lin_adobergb_scene");
    auto out = OIIO::ImageOutput::create(path("odd.exr"));
    ASSERT_TRUE(out && out->open(path("odd.exr"), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, rgb.data()));
    out->close();
    // colorInteropID and chromaticities that disagree.
    {
        OIIO::ImageSpec both = spec;
        both.attribute("colorInteropID", "lin_ap1_scene");
        const Chromaticities& c = findWorkingSpace("lin_rec709")->xy;
        const float xy[8] = {float(c.rx), float(c.ry), float(c.gx), float(c.gy),
                             float(c.bx), float(c.by), float(c.wx), float(c.wy)};
        both.attribute("chromaticities", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8), xy);
        auto o2 = OIIO::ImageOutput::create(path("both.exr"));
        ASSERT_TRUE(o2 && o2->open(path("both.exr"), both));
        ASSERT_TRUE(o2->write_image(OIIO::TypeDesc::FLOAT, rgb.data()));
        o2->close();
        const Result r = mcstat("--ingest '" + path("both.exr") + "' -o " + path("b.mcstat"));
        EXPECT_NE(r.code, 0);
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_NE(r.err.find("both.exr: colorInteropID 'lin_ap1_scene' is ACEScg but the "
                             "chromaticities (R 0.64 0.33"),
                  std::string::npos)
            << r.err;
    }
    const Result odd = mcstat("--ingest '" + path("odd.exr") + "' -o " + path("o.mcstat"));
    EXPECT_NE(odd.code, 0);
    EXPECT_EQ(std::count(odd.err.begin(), odd.err.end(), '\n'), 1) << odd.err;
    EXPECT_NE(odd.err.find("odd.exr: colorInteropID 'lin_adobergb_scene' is not a scene-linear "
                           "space mcstat knows"),
              std::string::npos)
        << odd.err;
}

TEST_F(IngestColor, CompareAndMergeRefuseDifferentSpaces) {
    writeBoth();
    ASSERT_EQ(mcstat("--ingest '" + path("rec709_s*.exr") + "' -o " + path("a.mcstat")).code, 0);
    ASSERT_EQ(mcstat("--ingest '" + path("ap1_s*.exr") + "' -o " + path("b.mcstat")).code, 0);
    // The same space: the maps say which.
    ASSERT_EQ(mcstat("--ingest '" + path("ap1_s[1-9].exr") + "' -o " + path("b1.mcstat")).code, 0);
    ASSERT_EQ(mcstat("--ingest '" + path("ap1_s1[0-9].exr") + "' -o " + path("b2.mcstat")).code, 0);
    const Result same =
        mcstat(path("b1.mcstat") + " " + path("b2.mcstat") + " --compare -o " + path("maps.exr"));
    EXPECT_NE(same.code, 1) << same.err;  // 0 or 2 (differs): a comparison was made
    OIIO::ImageSpec ms;
    readRGB(path("maps.exr"), ms);
    EXPECT_EQ(ms.get_string_attribute("mcstat:colorSpace"), "ACEScg");
    const Result cmp = mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --compare");
    EXPECT_NE(cmp.code, 0);
    EXPECT_EQ(std::count(cmp.err.begin(), cmp.err.end(), '\n'), 1) << cmp.err;
    EXPECT_NE(cmp.err.find("is in lin_rec709 but"), std::string::npos) << cmp.err;
    EXPECT_NE(cmp.err.find("re-ingest one side's renders converted"), std::string::npos) << cmp.err;
    const Result merge =
        mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --merge -o " + path("c.mcstat"));
    EXPECT_NE(merge.code, 0);
    EXPECT_NE(merge.err.find("colour spaces differ ('lin_rec709' vs 'ACEScg')"), std::string::npos)
        << merge.err;
}

/// $OCIO unset while it lives, as on a stock machine; restored afterwards.
class WithoutOcio {
  public:
    WithoutOcio() {
        const char* v = std::getenv("OCIO");
        had_ = v != nullptr;
        if (had_) saved_ = v;
        ::unsetenv("OCIO");
    }
    ~WithoutOcio() {
        if (had_) ::setenv("OCIO", saved_.c_str(), 1);
    }
    WithoutOcio(const WithoutOcio&) = delete;
    WithoutOcio& operator=(const WithoutOcio&) = delete;

  private:
    bool had_ = false;
    std::string saved_;
};

/// The command a one-line message prints after `marker`, to the end of the line.
std::string printedCommand(const std::string& err, const std::string& marker) {
    const size_t at = err.find(marker);
    if (at == std::string::npos) return {};
    const size_t end = err.find('\n', at);
    return err.substr(at + marker.size(),
                      end == std::string::npos ? end : end - at - marker.size());
}

/// Runs a shell command line as a user would paste it; its exit status.
int runShell(const std::string& cmd) {
    const int status = mcstat::testing::runCommand((cmd + " >/dev/null 2>&1").c_str());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/// Largest |a - b| / max(|b|, 1e-3) over two images' RGB.
double worstRelative(const std::vector<float>& a, const std::vector<float>& b) {
    double worst = a.size() == b.size() ? 0.0 : HUGE_VAL;
    for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
        worst = std::max(worst, std::fabs(double(a[i]) - double(b[i])) /
                                    std::max(std::fabs(double(b[i])), 1e-3));
    return worst;
}

TEST_F(IngestColor, DisplayEncodedRendersAreRefusedWithAConversionThatRunsAsPrinted) {
    // A float render converted to the sRGB display encoding with stock oiiotool: the TIFF keeps
    // float pixels and says oiio:ColorSpace sRGB (taken as linear, 0.5 would be 0.735). Refused in
    // one line with the conversion to run, which must run as printed on a machine without $OCIO:
    // OIIO's own config knows "linear" and "sRGB", not lin_rec709 (which the message printed).
    WithoutOcio stock;
    const std::string exr = path("render.exr"), tif = path("s 1.tif");
    ASSERT_EQ(mcstat::testing::runCommand((std::string(MCSTAT_RENDER_EXE) +
                                           " --scene default --res 32 24 --spp 8 "
                                           "--seed 5 --reference --quiet -o " +
                                           exr)
                                              .c_str()),
              0);
    ASSERT_EQ(runShell("oiiotool " + exr + " --colorconvert linear sRGB -d float -o '" + tif + "'"),
              0);
    Result r = mcstat("--ingest:spp=8 '" + tif + "' -o " + path("p.mcstat"));
    EXPECT_NE(r.code, 0);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find("s 1.tif: oiio:ColorSpace 'sRGB' is not scene-linear"), std::string::npos)
        << r.err;
    // The file's own name in the command, quoted for the shell (it has a space).
    std::string cmd = printedCommand(r.err, "e.g. ");
    EXPECT_EQ(cmd, "oiiotool '" + tif + "' --colorconvert sRGB linear -o '" +
                       path("s 1_linear.exr") + "'")
        << r.err;
    ASSERT_EQ(runShell("env -u OCIO " + cmd), 0) << cmd;
    // What it wrote is the render again (float: the round trip loses nothing visible) and goes in.
    OIIO::ImageSpec spec;
    EXPECT_LT(worstRelative(readRGB(path("s 1_linear.exr"), spec), readRGB(exr, spec)), 1e-4);
    r = mcstat("--ingest:spp=8 '" + path("s 1_linear.exr") + "' -o " + path("p.mcstat"));
    EXPECT_EQ(r.code, 0) << r.err;

    // With $OCIO set, oiiotool reads that config: the command names its scene-linear space.
    {
        std::FILE* f = std::fopen(path("own.ocio").c_str(), "w");
        ASSERT_NE(f, nullptr);
        std::fputs(builtinOcioConfig(), f);
        std::fclose(f);
    }
    ::setenv("OCIO", path("own.ocio").c_str(), 1);
    r = mcstat("--ingest:spp=8 '" + tif + "' -o " + path("p2.mcstat"));
    cmd = printedCommand(r.err, "e.g. ");
    EXPECT_NE(cmd.find("--colorconvert sRGB lin_rec709 -o"), std::string::npos) << r.err;
    EXPECT_EQ(runShell(cmd), 0) << cmd;
    ::unsetenv("OCIO");
}

TEST_F(IngestColor, ConvertedPngsAreRefusedAsIntegerDataAndTheirTagsAsContradictory) {
    // The report: `oiiotool seed.exr --colorconvert linear sRGB -d uint8 -o seed.png` keeps the
    // EXR's colorInteropID lin_rec709_scene beside the PNG's oiio:ColorSpace sRGB, and --ingest of
    // such PNGs took them as linear light clipped at 1 (max 1.0 against the EXRs' 240.6), exit 0.
    WithoutOcio stock;
    for (int s = 1; s <= 2; ++s) {
        const std::string exr = path(OIIO::Strutil::fmt::format("seed_{}.exr", s));
        ASSERT_EQ(mcstat::testing::runCommand(
                      (std::string(MCSTAT_RENDER_EXE) +
                       OIIO::Strutil::fmt::format(" --scene default --res 32 24 --spp 8 "
                                                  "--seed {} --reference --quiet -o ",
                                                  s) +
                       exr)
                          .c_str()),
                  0);
        ASSERT_EQ(runShell("oiiotool " + exr + " --colorconvert linear sRGB -d uint8 -o " +
                           path(OIIO::Strutil::fmt::format("seed_{}.png", s))),
                  0);
    }
    ASSERT_EQ(runShell("oiiotool " + path("seed_1.exr") +
                       " --colorconvert linear sRGB -d uint16 -o " + path("wide_1.png")),
              0);
    // How OIIO shows such a PNG: 8-bit integer pixels and both tags.
    OIIO::ImageSpec png;
    {
        auto in = OIIO::ImageInput::open(path("seed_1.png"));
        ASSERT_TRUE(in);
        png = in->spec();
    }
    EXPECT_EQ(png.format, OIIO::TypeDesc::UINT8);
    EXPECT_EQ(png.get_string_attribute("colorInteropID"), "lin_rec709_scene");
    EXPECT_EQ(png.get_string_attribute("oiio:ColorSpace"), "sRGB");

    // The EXRs go in; the PNGs do not, in one line naming the file and what is wrong.
    EXPECT_EQ(mcstat("--ingest '" + path("seed_*.exr") + "' -o " + path("a.mcstat")).code, 0);
    Result r = mcstat("--ingest '" + path("seed_*.png") + "' -o " + path("b.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --ingest: " + path("seed_1.png") +
                         ": its beauty holds 8-bit integer pixels (uint8), not a render's float "
                         "(half or float) output: as light they are quantised and clipped at 1; "
                         "ingest the renderer's own float files (EXR)\n");
    EXPECT_FALSE(OIIO::Filesystem::exists(path("b.mcstat")));
    r = mcstat("--ingest '" + path("wide_1.png") + "' -o " + path("b.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find("wide_1.png: its beauty holds 16-bit integer pixels (uint16)"),
              std::string::npos)
        << r.err;

    // The tags contradict each other, which colorSpaceOf refuses whatever the pixels: a
    // reference image of --diff (which takes 8-bit pictures) is refused for it alone.
    std::string space, source, problem;
    EXPECT_FALSE(colorSpaceOf(png, space, source, problem));
    EXPECT_EQ(problem,
              "colorInteropID 'lin_rec709_scene' says lin_rec709 but oiio:ColorSpace says 'sRGB': "
              "the file contradicts itself, and which is right cannot be told from it (a copy "
              "converted by oiiotool --colorconvert keeps its source's tags); fix its metadata, "
              "or use the file it was made from");
    r = mcstat(path("seed_2.exr") + " --diff " + path("seed_1.png"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find(path("seed_1.png") + ": colorInteropID 'lin_rec709_scene' says"),
              std::string::npos)
        << r.err;
}

TEST_F(IngestColor, TagsThatNameTwoSpacesAreRefusedAndTagsThatAgreeAreNot) {
    const WorkingSpace* ap1 = findWorkingSpace("ACEScg");
    const Chromaticities& c = ap1->xy;
    const float xy[8] = {float(c.rx), float(c.ry), float(c.gx), float(c.gy),
                         float(c.bx), float(c.by), float(c.wx), float(c.wy)};
    struct Case {
        const char* id;          // colorInteropID, or none
        bool chromaticities;     // AP1's
        const char* colorSpace;  // oiio:ColorSpace, or none
        const char* space;       // what is read; null: refused
    } cases[] = {
        {"lin_ap1_scene", false, "lin_rec709", nullptr},  // two primaries
        {"lin_ap1_scene", false, "sRGB", nullptr},        // linear and display-encoded
        {nullptr, true, "sRGB", nullptr},                 // the chromaticities, the same
        {nullptr, true, "lin_srgb", nullptr},
        {"lin_ap1_scene", true, "ACEScg", "ACEScg"},   // all three agree
        {"lin_ap1_scene", false, "Linear", "ACEScg"},  // OIIO's label of any float EXR
        {nullptr, true, "scene_linear", "ACEScg"},     // a role: no primaries
        {"lin_rec709_scene", false, "lin_srgb", "lin_rec709"},
    };
    for (const Case& k : cases) {
        OIIO::ImageSpec spec(4, 4, 3, OIIO::TypeDesc::FLOAT);
        if (k.id) spec.attribute("colorInteropID", k.id);
        if (k.chromaticities)
            spec.attribute("chromaticities", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8), xy);
        if (k.colorSpace) spec.attribute("oiio:ColorSpace", k.colorSpace);
        std::string space, source, problem;
        const std::string what = std::string(k.id ? k.id : "-") + " / " + k.colorSpace;
        EXPECT_EQ(colorSpaceOf(spec, space, source, problem), k.space != nullptr) << what;
        if (k.space) {
            EXPECT_EQ(space, k.space) << what;
        } else {
            EXPECT_NE(problem.find("but oiio:ColorSpace says '" + std::string(k.colorSpace) +
                                   "': the file contradicts itself"),
                      std::string::npos)
                << what << ": " << problem;
        }
    }
}

TEST_F(IngestColor, ColorConfigTakesAFileAndRefusesUnsupportedUrisInOneLine) {
    if (ocioVersion() >= "2.2") GTEST_SKIP() << "this OCIO has built-in configs";
    const Result uri = mcstat("--colorconfig ocio://default --threads 1");
    EXPECT_NE(uri.code, 0);
    EXPECT_EQ(std::count(uri.err.begin(), uri.err.end(), '\n'), 1) << uri.err;
    EXPECT_NE(uri.err.find("--colorconfig: 'ocio://default': ocio:// URIs (OCIO's built-in "
                           "configs) need OpenColorIO 2.2 or later"),
              std::string::npos)
        << uri.err;
    // A config file: mcstat's own, written out, is accepted.
    {
        std::FILE* f = std::fopen(path("own.ocio").c_str(), "w");
        ASSERT_NE(f, nullptr);
        std::fputs(builtinOcioConfig(), f);
        std::fclose(f);
    }
    const Result file = mcstat("--colorconfig " + path("own.ocio") + " --threads 1");
    EXPECT_EQ(file.code, 0) << file.err;
}

/// Small synthetic renders, no renderer: `n` files `stem`N.exr (N from 1) of a 16 x 12 gradient
/// with a firefly in seed 3, converted to AP1 when `ap1`, tagged with their space when `tag`.
void writeSynthetic(const std::string& stem, int n, bool ap1, bool tag) {
    const int w = 16, h = 12;
    for (int s = 1; s <= n; ++s) {
        std::vector<float> rgb(size_t(w) * h * 3);
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                float* p = &rgb[(size_t(y) * w + size_t(x)) * 3];
                const float v = 0.05f + 0.04f * float(x) + 0.01f * float(y) + 0.003f * float(s);
                p[0] = v, p[1] = 0.7f * v + 0.02f * float(y), p[2] = 0.3f + 0.5f * v * float(s % 3);
                if (s == 3 && x == 5 && y == 4) p[0] = p[1] = p[2] = 500.0f;
            }
        std::vector<float> out = rgb;
        if (ap1)
            for (size_t p = 0; p < rgb.size() / 3; ++p)
                for (int r = 0; r < 3; ++r)
                    out[p * 3 + size_t(r)] =
                        float(kToAp1[r][0] * rgb[p * 3] + kToAp1[r][1] * rgb[p * 3 + 1] +
                              kToAp1[r][2] * rgb[p * 3 + 2]);
        writeRGB(stem + std::to_string(s) + ".exr", w, h, out, ap1 ? "ACEScg" : "lin_rec709", tag);
    }
}

/// mcstat's own config with an ACEScg colour space (the ACES Rec.709 -> AP1 matrix from the
/// reference) and file rules: names with "ap1" are ACEScg, names with "disp" sRGB.
std::string configWithFileRules(const std::string& path) {
    std::string text = builtinOcioConfig();
    const std::string defaultRule = "  - !<Rule> {name: Default, colorspace: default}";
    const size_t at = text.find(defaultRule);
    EXPECT_NE(at, std::string::npos);
    text.insert(
        at,
        "  - !<Rule> {name: ap1, colorspace: ACEScg, pattern: \"*ap1*\", extension: exr}\n"
        "  - !<Rule> {name: disp, colorspace: sRGB, pattern: \"*disp*\", extension: exr}\n");
    std::string m = "[";
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c)
            m += (r == 3 && c == 3   ? std::string("1")
                  : r == 3 || c == 3 ? std::string("0")
                                     : std::to_string(kToAp1[r][c])) +
                 (r == 3 && c == 3 ? "]" : ", ");
    text +=
        "\n  - !<ColorSpace>\n    name: ACEScg\n    family: Linear\n    isdata: false\n"
        "    encoding: scene-linear\n    from_scene_reference: !<MatrixTransform> {matrix: " +
        m + "}\n";
    std::FILE* f = std::fopen(path.c_str(), "w");
    EXPECT_NE(f, nullptr);
    std::fputs(text.c_str(), f);
    std::fclose(f);
    return path;
}

TEST_F(IngestColor, TheConfigsFileRulesPlaceUntaggedRendersAfterTheModifier) {
    writeSynthetic(path("u_ap1_s"), 5, true, false);
    writeSynthetic(path("u_disp_s"), 5, false, false);
    const std::string cfg = configWithFileRules(path("rules.ocio"));
    // The file rules say ACEScg: the statistics file is labelled so.
    const Result ruled = mcstat("--colorconfig " + cfg + " --ingest '" + path("u_ap1_s*.exr") +
                                "' -o " + path("ruled.mcstat"));
    ASSERT_EQ(ruled.code, 0) << ruled.err;
    expectLabelled(part0(path("ruled.mcstat")), "ACEScg", "file rules");
    // The modifier is the user's word for this ingest: it wins over the config's rules.
    const Result said = mcstat("--colorconfig " + cfg + " --ingest:colorspace=lin_rec709 '" +
                               path("u_ap1_s*.exr") + "' -o " + path("said.mcstat"));
    ASSERT_EQ(said.code, 0) << said.err;
    expectLabelled(part0(path("said.mcstat")), "lin_rec709", "modifier");
    // Without the rules (mcstat's own config has only the Default one): lin_rec709.
    const Result plain =
        mcstat("--ingest '" + path("u_ap1_s*.exr") + "' -o " + path("plain.mcstat"));
    ASSERT_EQ(plain.code, 0) << plain.err;
    expectLabelled(part0(path("plain.mcstat")), "lin_rec709", "no rule");
    // A rule naming a display encoding is refused as the same tag in the file would be.
    const Result disp = mcstat("--colorconfig " + cfg + " --ingest '" + path("u_disp_s*.exr") +
                               "' -o " + path("disp.mcstat"));
    EXPECT_NE(disp.code, 0);
    EXPECT_EQ(std::count(disp.err.begin(), disp.err.end(), '\n'), 1) << disp.err;
    EXPECT_NE(disp.err.find("u_disp_s1.exr: the OCIO config's file rules say 'sRGB', which is "
                            "not scene-linear"),
              std::string::npos)
        << disp.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("disp.mcstat")));
}

TEST_F(IngestColor, AnOcioUriInTheEnvironmentIsAOneLineErrorWhereThisOcioHasNone) {
    if (ocioVersion() >= "2.2") GTEST_SKIP() << "this OCIO has built-in configs";
    writeSynthetic(path("s"), 3, false, true);
    ASSERT_EQ(mcstat("--ingest '" + path("s*.exr") + "' -o " + path("a.mcstat")).code, 0);
    ::setenv("OCIO", "ocio://default", 1);
    const Result r = mcstat(path("a.mcstat") + " --gmon -o " + path("g.exr"));
    const Result withFile = mcstat("--colorconfig " + configWithFileRules(path("c.ocio")) + " " +
                                   path("a.mcstat") + " --gmon -o " + path("g2.exr"));
    ::unsetenv("OCIO");
    EXPECT_NE(r.code, 0);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find("$OCIO='ocio://default': ocio:// URIs (OCIO's built-in configs) need "
                         "OpenColorIO 2.2 or later"),
              std::string::npos)
        << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("g.exr")));
    // --colorconfig replaces $OCIO for the command line: the URI is never needed.
    EXPECT_EQ(withFile.code, 0) << withFile.err;
}

/// The first number after `key` in `text` (a --diff line), NaN if absent.
double diffValue(const std::string& text, const std::string& key) {
    const size_t at = text.find(key + " ");
    return at == std::string::npos ? std::nan("") : std::atof(text.c_str() + at + key.size() + 1);
}

TEST_F(IngestColor, DiffAndErrorMapRefuseAReferenceInAnotherSpaceAndDisplayTheirOwn) {
    writeSynthetic(path("a709_s"), 7, false, true);
    writeSynthetic(path("ap1_s"), 7, true, true);
    for (const char* k : {"a709", "ap1"}) {
        const std::string stem = k;
        ASSERT_EQ(mcstat("--ingest '" + path(stem + "_s*.exr") + "' -o " + path(stem + ".mcstat") +
                         " --mean -o " + path(stem + "_ref.exr"))
                      .code,
                  0);
    }
    // The same pictures in both spaces: the same SSIM (its display values go through a display
    // right for the space: ACEScg through a matrix to Rec.709, with a note).
    const Result d709 = mcstat(path("a709.mcstat") + " --gmon --diff " + path("a709_ref.exr"));
    const Result dap1 = mcstat(path("ap1.mcstat") + " --gmon --diff " + path("ap1_ref.exr"));
    ASSERT_EQ(d709.code, 0) << d709.err;
    ASSERT_EQ(dap1.code, 0) << dap1.err;
    const double s709 = diffValue(d709.out, "SSIM"), sap1 = diffValue(dap1.out, "SSIM");
    EXPECT_LT(s709, 0.9999) << d709.out;  // the firefly's pixel differs: a test that can fail
    EXPECT_NEAR(sap1, s709, 2e-5) << d709.out << dap1.out;
    // Review pictures of ACEScg with mcstat's own config say how they were shown.
    const Result png = mcstat(path("ap1.mcstat") + " --gmon -o " + path("g.png"));
    ASSERT_EQ(png.code, 0) << png.err;
    EXPECT_NE(png.err.find("note: ACEScg shown through a matrix to lin_rec709"), std::string::npos)
        << png.err;
    const Result png709 = mcstat(path("a709.mcstat") + " --gmon -o " + path("g709.png"));
    EXPECT_EQ(png709.err.find("through a matrix"), std::string::npos) << png709.err;
    // A reference in another space is refused by --diff and --errormap, in one line.
    for (const char* cmd : {"--diff", "--errormap"}) {
        const Result r = mcstat(path("ap1.mcstat") + " --gmon " + cmd + " " + path("a709_ref.exr") +
                                " -o " + path("e.exr"));
        EXPECT_NE(r.code, 0) << cmd;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_NE(r.err.find(std::string(cmd) + ": gmon("), std::string::npos) << r.err;
        EXPECT_NE(r.err.find("is in ACEScg but " + path("a709_ref.exr") + " is in lin_rec709"),
                  std::string::npos)
            << r.err;
    }
}

TEST_F(IngestColor, SpaceConversionsPrintedByARefusalRunAsPrintedWithoutAConfig) {
    // Statistics in lin_rec709 against a reference in ACEScg: the refusal prints the conversion,
    // which needs no OCIO config (stock oiiotool's own knows neither space): a matrix and tags.
    WithoutOcio stock;
    writeSynthetic(path("r"), 3, false, true);
    writeSynthetic(path("ap"), 1, true, true);
    ASSERT_EQ(mcstat("--ingest '" + path("r*.exr") + "' -o " + path("a.mcstat")).code, 0);
    Result r = mcstat(path("a.mcstat") + " --mean --diff " + path("ap1.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    const std::string cmd =
        printedCommand(r.err, "convert " + path("ap1.exr") + " to lin_rec709 first: ");
    EXPECT_EQ(cmd.rfind("oiiotool " + path("ap1.exr") + " --ccmatrix:transpose=1 ", 0), 0u)
        << r.err;
    ASSERT_EQ(runShell("env -u OCIO " + cmd), 0) << cmd;
    // Converted and labelled: the same comparison runs, and the pixels are r1.exr's again.
    r = mcstat(path("a.mcstat") + " --mean --diff " + path("ap1_lin_rec709.exr"));
    EXPECT_EQ(r.code, 0) << r.err;
    OIIO::ImageSpec converted, original;
    const std::vector<float> back = readRGB(path("ap1_lin_rec709.exr"), converted);
    EXPECT_LT(worstRelative(back, readRGB(path("r1.exr"), original)), 1e-5);
    EXPECT_EQ(converted.get_string_attribute("colorInteropID"), "lin_rec709_scene");
    EXPECT_EQ(converted.find_attribute("chromaticities"), nullptr);
}

}  // namespace
}  // namespace mcstat::testing
