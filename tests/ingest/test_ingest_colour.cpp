// Colour-managed renders (docs/colour.md, issue 33): the working space of the inputs is read,
// kept in the statistics file, labelled on every result and used for the luminance. The same 21
// seed renders in Rec.709 and in ACEScg (built here from real renders by the ACES Rec.709 -> AP1
// matrix) give G-MoN results that agree after conversion, pixel by pixel.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "../cli/cli_support.h"
#include "mcstat/color.h"
#include "mcstat/core/colour_space.h"

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

class IngestColour : public CliFixture {
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
        EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
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

TEST_F(IngestColour, AcesAndRec709VersionsOfTheSameRendersGiveTheSameGMoN) {
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

TEST_F(IngestColour, UntaggedRendersTakeTheColorspaceModifier) {
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

TEST_F(IngestColour, MixedSpacesAndUnknownSpacesAreRefusedInOneLine) {
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

TEST_F(IngestColour, CompareAndMergeRefuseDifferentSpaces) {
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
    EXPECT_NE(cmp.err.find("convert one"), std::string::npos) << cmp.err;
    const Result merge =
        mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --merge -o " + path("c.mcstat"));
    EXPECT_NE(merge.code, 0);
    EXPECT_NE(merge.err.find("colour spaces differ ('lin_rec709' vs 'ACEScg')"), std::string::npos)
        << merge.err;
}

TEST_F(IngestColour, DisplayEncodedRendersAreRefusedInOneLine) {
    // An sRGB PNG holds display-encoded values, not scene-linear light: taken as linear, a value
    // of about 0.5 would become 0.735. Refused, with the conversion to do.
    std::vector<unsigned char> px(size_t(kW) * kH * 3, 188);
    OIIO::ImageSpec spec(kW, kH, 3, OIIO::TypeDesc::UINT8);
    auto out = OIIO::ImageOutput::create(path("s1.png"));
    ASSERT_TRUE(out && out->open(path("s1.png"), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
    out->close();
    const Result r = mcstat("--ingest:spp=8 '" + path("s1.png") + "' -o " + path("p.mcstat"));
    EXPECT_NE(r.code, 0);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find("s1.png: oiio:ColorSpace 'sRGB' is not scene-linear"), std::string::npos)
        << r.err;
    EXPECT_NE(r.err.find("--colorconvert sRGB lin_rec709"), std::string::npos) << r.err;
}

TEST_F(IngestColour, ColorConfigTakesAFileAndRefusesUnsupportedUrisInOneLine) {
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

}  // namespace
}  // namespace mcstat::testing
