// Files known by their content, not their name (issue 22): a statistics file named .exr is read as
// one and a plain EXR named .mcstat as the image it is (each with a note), a directory is named as
// one, --ingest refuses statistics files, a display-encoded reference (an sRGB PNG) is made
// scene-linear before it is compared, and --info prints Pajot's luma as people write it.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iterator>

#include "cli_support.h"

namespace {

class ContentCli : public mcstat::testing::CliFixture {
  protected:
    /// mcstat-render of the default scene at 40 x 30, `extra` options, written to `name`.
    void render(const std::string& extra, const std::string& name) {
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                                " --quiet --scene default --res 40 30 --spp 16 " + extra + " -o " +
                                path(name);
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
    }
    static size_t lines(const std::string& s) {
        return size_t(std::count(s.begin(), s.end(), '\n'));
    }
    /// The relMSE of `--diff`'s line in `out`, or NaN.
    static double relMse(const std::string& out) {
        const size_t at = out.find("relMSE ");
        return at == std::string::npos ? NAN : std::atof(out.c_str() + at + 7);
    }
};

TEST_F(ContentCli, StatisticsFileNamedExrIsReadAsOneWithANote) {
    // mcstat-render writes a statistics file whatever the name (an .exr only with --reference).
    render("--M 4", "stats.exr");
    auto r = mcstat(path("stats.exr") + " --info");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("mcstat statistics file, format 1"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("M = 4 sub-buffers"), std::string::npos) << r.out;
    EXPECT_EQ(r.err, "mcstat: note: " + path("stats.exr") +
                         " is a statistics file (by its content) and is read as one; name it "
                         ".mcstat for OIIO's mcstat plugin, which OIIO chooses by the name\n");
    // Every command that needs one takes it: an estimator, --check, --merge's input.
    r = mcstat(path("stats.exr") + " --check");
    EXPECT_EQ(r.code, 0) << r.err;
    r = mcstat(path("stats.exr") + " --gmon -o " + path("gmon.exr"));
    EXPECT_EQ(r.code, 0) << r.err;
    // As a reference: its beauty, the same as under its proper name.
    ASSERT_TRUE(OIIO::Filesystem::copy(path("stats.exr"), path("stats.mcstat")));
    r = mcstat(path("stats.mcstat") + " --mean --diff " + path("stats.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_LT(relMse(r.out), 1e-12) << r.out;
}

TEST_F(ContentCli, PlainExrNamedMcstatIsReadAsTheImageItIsWithANote) {
    render("--reference", "plain.exr");
    ASSERT_TRUE(OIIO::Filesystem::copy(path("plain.exr"), path("plain.mcstat")));
    const std::string note = "mcstat: note: " + path("plain.mcstat") +
                             " is a plain EXR image, not a statistics file (no part 'buffers' or "
                             "'vbuffers'; it has one unnamed part); read as an image\n";
    auto r = mcstat(path("plain.mcstat") + " --info");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.out, path("plain.mcstat") + ": 40 x 30, 3 channels (R,G,B), float\n");
    EXPECT_EQ(r.err, note);
    // Today's misreading said: "part 0 is named '', expected 'beauty'" (a damaged statistics file).
    EXPECT_EQ(r.err.find("expected 'beauty'"), std::string::npos);
    // A command that needs a statistics file refuses the image, after the note said why.
    r = mcstat(path("plain.mcstat") + " --gmon");
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(lines(r.err), 2u) << r.err;
    EXPECT_EQ(r.err.rfind(note, 0), 0u) << r.err;
    EXPECT_NE(r.err.find("is an image, not a statistics file"), std::string::npos) << r.err;
    // As an image it converts like any other.
    r = mcstat(path("plain.mcstat") + " -o " + path("copy.exr"));
    EXPECT_EQ(r.code, 0) << r.err;
}

TEST_F(ContentCli, ImageInputsGetTheHeaderChecksBeforeAnyReader) {
    // A plain EXR whose string attribute claims 2 GB: refused by the attribute-size check, before
    // OIIO's OpenEXR reader would allocate it.
    render("--reference", "plain.exr");
    std::ifstream in(path("plain.exr"), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string attr = std::string("mcstat:seeds") + '\0' + "string" + '\0';
    const size_t at = bytes.find(attr);
    ASSERT_NE(at, std::string::npos);
    const size_t sz = at + attr.size();
    bytes[sz] = '\xf0';
    bytes[sz + 1] = bytes[sz + 2] = '\xff';
    bytes[sz + 3] = '\x7f';
    std::ofstream(path("bad.exr"), std::ios::binary) << bytes;
    const auto r = mcstat(path("bad.exr") + " --info");
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_NE(r.err.find("truncated or corrupt (header 0: attribute 'mcstat:seeds' claims "
                         "2147483632 bytes"),
              std::string::npos)
        << r.err;
}

TEST_F(ContentCli, DirectoryIsNamedAsOne) {
    auto r = mcstat(dir);
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: " + dir + " is a directory\n");
    // As a reference too.
    render("--M 4", "s.mcstat");
    r = mcstat(path("s.mcstat") + " --mean --diff " + dir);
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --diff: " + dir + " is a directory\n");
}

TEST_F(ContentCli, IngestRefusesStatisticsFiles) {
    render("--M 21 --seed 1", "a.mcstat");
    render("--M 21 --seed 2", "b.mcstat");
    // Read as renders, each would be one sub-buffer (its mean): M = 2 instead of 42.
    auto r = mcstat("--ingest '" + path("a.mcstat") + "," + path("b.mcstat") + "' --info");
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --ingest: " + path("a.mcstat") +
                         " is a statistics file: combine statistics files with --merge\n");
    // By content: a statistics file named .exr among renders is refused as well.
    render("--reference --seed 3", "r3.exr");
    ASSERT_TRUE(OIIO::Filesystem::copy(path("b.mcstat"), path("r4.exr")));
    r = mcstat("--ingest '" + path("r*.exr") + "' --info");
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --ingest: " + path("r4.exr") +
                         " is a statistics file: combine statistics files with --merge\n");
    // What it says to do works.
    r = mcstat(path("a.mcstat") + " " + path("b.mcstat") + " --merge --info");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("M = 21 sub-buffers, spp = 32"), std::string::npos) << r.out;
}

TEST_F(ContentCli, SrgbPngReferenceIsMadeSceneLinearBeforeComparing) {
    // A 16-spp render and a 256-spp reference, both within [0, 1] so that the reference's 8-bit
    // PNG differs from it only by quantisation (8 bits clip at 1; the default scene's light is
    // brighter, and its clipped pixels would dominate relMSE whatever the encoding).
    render("--reference --seed 1", "test-hdr.exr");
    render("--reference --spp 256 --seed 9", "ref-hdr.exr");
    for (const char* name : {"test", "ref"}) {
        OIIO::ImageBuf hdr(path(std::string(name) + "-hdr.exr")), ldr;
        ASSERT_TRUE(OIIO::ImageBufAlgo::clamp(ldr, hdr, 0.f, 1.f)) << ldr.geterror();
        ASSERT_TRUE(ldr.write(path(std::string(name) + ".exr"))) << ldr.geterror();
    }
    // The PNG as mcstat writes one: through the OCIO display view, sRGB-encoded, 8 bits.
    auto r = mcstat(path("ref.exr") + " -o " + path("ref.png"));
    ASSERT_EQ(r.code, 0) << r.err;
    // The same 8-bit values in a float EXR that names no colour space: taken as linear, as the PNG
    // used to be.
    OIIO::ImageBuf png(path("ref.png"));
    ASSERT_TRUE(png.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << png.geterror();
    OIIO::ImageBuf encoded(
        OIIO::ImageSpec(png.spec().width, png.spec().height, 3, OIIO::TypeDesc::FLOAT));
    ASSERT_TRUE(OIIO::ImageBufAlgo::paste(encoded, 0, 0, 0, 0, png));
    ASSERT_TRUE(encoded.write(path("encoded.exr"))) << encoded.geterror();

    r = mcstat(path("test.exr") + " --diff " + path("ref.exr") + " --diff " + path("ref.png") +
               " --diff " + path("encoded.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    const size_t l2 = r.out.find('\n') + 1, l3 = r.out.find('\n', l2) + 1;
    const double linear = relMse(r.out), fromPng = relMse(r.out.substr(l2)),
                 asIf = relMse(r.out.substr(l3));
    ASSERT_GT(linear, 0.0) << r.out;
    // 8 bits after the sRGB curve: a step of at most 1/255 of the encoded value, about 1.3 % of
    // a linear value at the top, 0.03 % of full scale near black; relMSE moves far less than 1 %.
    EXPECT_NEAR(fromPng, linear, 0.01 * linear) << r.out;
    // Compared as if linear, the metric is another number altogether.
    EXPECT_GT(std::fabs(asIf - linear), 0.2 * linear) << r.out;
    EXPECT_NE(r.err.find("mcstat: note: " + path("ref.png") +
                         " is display-encoded (sRGB); converted to scene-linear lin_rec709 "
                         "through OCIO before comparing"),
              std::string::npos)
        << r.err;
    EXPECT_EQ(lines(r.err), 1u) << r.err;  // the EXR references need no note
    // A PNG that declares linear data (stock oiiotool writes gamma 1 from an EXR): compared as
    // it is, with a note that 8 bits quantise and clip it.
    ASSERT_EQ(mcstat::testing::runCommand(
                  ("oiiotool " + path("ref.exr") + " -o " + path("linear.png")).c_str()),
              0);
    r = mcstat(path("test.exr") + " --diff " + path("linear.png"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find(path("linear.png") + " holds uint8 integer pixels (Linear): values are "
                                              "quantised and clipped at 1"),
              std::string::npos)
        << r.err;
}

TEST_F(ContentCli, ReferenceInAColorSpaceOcioDoesNotKnowIsRefused) {
    render("--M 4", "s.mcstat");
    OIIO::ImageBuf img(OIIO::ImageSpec(40, 30, 3, OIIO::TypeDesc::UINT8));
    const float grey[3] = {0.5f, 0.5f, 0.5f};
    ASSERT_TRUE(OIIO::ImageBufAlgo::fill(img, grey));
    img.specmod().attribute("oiio:ColorSpace", "GammaCorrected2.2");
    ASSERT_TRUE(img.write(path("gamma.png"))) << img.geterror();
    const auto r = mcstat(path("s.mcstat") + " --mean --diff " + path("gamma.png"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_NE(r.err.find("colour space 'GammaCorrected2.2' is not in the OCIO config"),
              std::string::npos)
        << r.err;
}

TEST_F(ContentCli, InfoPrintsPajotLumaAsWritten) {
    render("--M 4 --pajot hybrid --pajot-n 4", "pj.mcstat");
    const auto r = mcstat(path("pj.mcstat") + " --info");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("pajot (online, delayed=64:delta=0:luma=0.2126,0.7152,0.0722:"
                         "method=hybrid:n=4:t=2)"),
              std::string::npos)
        << r.out;
    EXPECT_EQ(r.out.find("0.21260000000000001"), std::string::npos) << r.out;
}

}  // namespace
