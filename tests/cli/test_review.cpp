// `mcstat` review pictures end to end (docs/review.md): the contact sheet's layout, tile pixels and
// metrics against the library and --diff; --errormap against metrics.h; --heatmap written as it is;
// the quality plot's CSV against --diff and an independent recomputation; the refusals.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/strutil.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "cli_support.h"
#include "mcstat/color/color.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/review/display.h"
#include "mcstat/review/review_pictures.h"

using namespace mcstat;

namespace {

using mcstat::testing::Result;

class ReviewCli : public mcstat::testing::CliFixture {
  protected:
    /// a.mcstat: 32x24, 40 spp in M = 5 buffers; ref.exr: a 400-spp reference of the same scene.
    void SetUp() override {
        CliFixture::SetUp();
        render("--spp 40 --M 5 -o " + path("a.mcstat"));
        render("--spp 400 --seed 9 --reference -o " + path("ref.exr"));
    }
    void render(const std::string& args) const {
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                                " --scene default --res 32 24 --quiet " + args + " >/dev/null";
        ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
    }
    /// `mcstat ARGS` run in the test's directory, so short names (and the item names built from
    /// them, e.g. "gmon(a.mcstat)") can be used.
    Result mcstat(const std::string& args) const {
        const std::string o = path("mcstat.stdout"), e = path("mcstat.stderr");
        const std::string cmd =
            "cd '" + dir + "' && " + MCSTAT_EXE + " " + args + " >'" + o + "' 2>'" + e + "'";
        Result r;
        const int status = mcstat::testing::runCommand(cmd.c_str());
        r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        r.out = mcstat::testing::slurp(o);
        r.err = mcstat::testing::slurp(e);
        return r;
    }
    StatsImage stats(const std::string& name) const {
        StatsImage s;
        std::string err;
        EXPECT_TRUE(readStatsFile(path(name), s, err)) << err;
        return s;
    }
    OIIO::ImageBuf ref() const {
        OIIO::ImageBuf r(path("ref.exr"));
        EXPECT_TRUE(r.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << r.geterror();
        return r;
    }
};

OIIO::ImageBuf run(const StatsImage& s, const std::string& est) {
    PixelKernel k;
    std::string err;
    EXPECT_TRUE(bindPixelKernel(*findEstimator(est), {}, lumaCoefficients(), k, err)) << err;
    OIIO::ImageBuf img = estimate(s, *findEstimator(est), k);
    EXPECT_FALSE(img.has_error()) << img.geterror();
    return img;
}

DiffMetrics diff(const OIIO::ImageBuf& img, const OIIO::ImageBuf& ref) {
    DiffOptions o;
    o.luma = lumaCoefficients();
    DiffMetrics m;
    std::string err;
    EXPECT_TRUE(diffImages(img, ref, o, m, err)) << err;
    return m;
}

OIIO::ImageBuf readFloat(const std::string& file) {
    OIIO::ImageBuf b(file);
    EXPECT_TRUE(b.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << b.geterror();
    return b;
}

double doubleAttr(const OIIO::ImageSpec& s, const std::string& name) {
    double v = std::nan("");
    EXPECT_TRUE(s.getattribute(name, OIIO::TypeDesc::DOUBLE, &v)) << name;
    return v;
}

/// The number after `key` in a --diff line.
double field(const std::string& line, const std::string& key) {
    const size_t at = line.find(key + " ");
    EXPECT_NE(at, std::string::npos) << key << " in " << line;
    return at == std::string::npos ? std::nan("") : std::strtod(line.c_str() + at + key.size(), 0);
}

/// The first line of `text` containing `what`.
std::string lineWith(const std::string& text, const std::string& what) {
    std::istringstream in(text);
    for (std::string l; std::getline(in, l);)
        if (l.find(what) != std::string::npos) return l;
    ADD_FAILURE() << "no line with '" << what << "' in:\n" << text;
    return "";
}

/// The first k buffers of every pixel, built here independently of the command's own code.
StatsImage firstBuffers(const StatsImage& s, int k) {
    StatsImage out;
    out.header = s.header;
    out.header.M = k;
    std::string err;
    EXPECT_TRUE(out.allocate(err)) << err;
    for (size_t p = 0; p < s.pixelCount(); ++p) {
        double n = 0, sum[3] = {0, 0, 0};
        for (int j = 0; j < k; ++j) {
            const size_t src = p * size_t(s.header.M) + size_t(j), dst = p * size_t(k) + size_t(j);
            out.bufferCount[dst] = s.bufferCount[src];
            n += s.bufferCount[src];
            for (int c = 0; c < 3; ++c) {
                out.bufferMean[dst * 3 + c] = s.bufferMean[src * 3 + c];
                sum[c] += s.bufferCount[src] * double(s.bufferMean[src * 3 + c]);
            }
        }
        out.count[p] = float(n);
        for (int c = 0; c < 3; ++c) out.beauty[p * 3 + c] = out.mean[p * 3 + c] = float(sum[c] / n);
    }
    return out;
}

struct CsvRow {
    double spp, relMSE, ssim, psnr;
    int buffers;
    long fireflies;
    std::string estimator;
    double bytesPerPixel;
};

std::vector<CsvRow> readCsv(const std::string& file) {
    std::istringstream in(mcstat::testing::slurp(file));
    std::string line;
    std::getline(in, line);
    EXPECT_EQ(line, "spp,buffers,estimator,relMSE,SSIM,PSNR,fireflies,bytesPerPixel");
    std::vector<CsvRow> rows;
    while (std::getline(in, line)) {
        const auto f = OIIO::Strutil::splits(line, ",");
        if (f.size() != 8) {
            ADD_FAILURE() << line;
            continue;
        }
        rows.push_back({std::stod(f[0]), std::stod(f[3]), std::stod(f[4]), std::stod(f[5]),
                        std::stoi(f[1]), std::stol(f[6]), f[2], std::stod(f[7])});
    }
    return rows;
}

const CsvRow* findRow(const std::vector<CsvRow>& rows, int k, const std::string& est) {
    for (const CsvRow& r : rows)
        if (r.buffers == k && r.estimator == est) return &r;
    ADD_FAILURE() << "no row k=" << k << " " << est;
    return nullptr;
}

}  // namespace

TEST_F(ReviewCli, ContactSheetTilesAndMetrics) {
    const Result r = mcstat("a.mcstat --contactsheet:estimators=mean,gmon " + path("ref.exr") +
                            " -o " + path("sheet.exr") + " -o " + path("sheet.png"));
    ASSERT_EQ(r.code, 0) << r.err;
    const OIIO::ImageBuf sheet = readFloat(path("sheet.exr"));
    const OIIO::ImageSpec& s = sheet.spec();
    // mean (listed, shown once) | G-MoN | reference | difference; 32 px tiles upscaled to 256.
    const int n = 4, scale = 8, W = 32 * scale, H = 24 * scale;
    const ReviewStyle st;
    const int m = st.margin, lineH = st.lineHeight();
    EXPECT_EQ(s.get_int_attribute("mcstat:sheet:tiles"), n);
    EXPECT_EQ(s.get_int_attribute("mcstat:sheet:scale"), scale);
    EXPECT_EQ(s.get_int_attribute("mcstat:displayReferred"), 1);
    // The label strip: three metric lines, or the colour bar under the difference tile.
    const int labelH = std::max(3 * lineH, colorBar(W, ColorScale()).spec().height);
    EXPECT_EQ(s.width, n * W + (n + 1) * m);
    EXPECT_EQ(s.height, m + lineH + H + m / 2 + labelH + m);

    // Tiles 1 (mean), 2 (G-MoN) and 3 (reference): the display transform of each image.
    const StatsImage a = stats("a.mcstat");
    const OIIO::ImageBuf refImg = ref();
    const OIIO::ImageBuf images[3] = {run(a, "mean"), run(a, "gmon"), refImg};
    const OIIO::ImageBuf png = readFloat(path("sheet.png"));
    for (int i = 0; i < 3; ++i) {
        const std::string t = "mcstat:tile" + std::to_string(i + 1) + ":";
        const int x0 = s.get_int_attribute(t + "x"), y0 = s.get_int_attribute(t + "y");
        EXPECT_EQ(x0, m + i * (W + m));
        EXPECT_EQ(y0, m + lineH);
        const OIIO::ImageBuf disp = displayTransform(images[i]);
        for (int y = 0; y < H; y += 3)
            for (int x = 0; x < W; x += 5) {
                float e[3], got[3], got8[3];
                disp.getpixel(x / scale, y / scale, e, 3);
                sheet.getpixel(x0 + x, y0 + y, got, 3);
                png.getpixel(x0 + x, y0 + y, got8, 3);
                for (int c = 0; c < 3; ++c) {
                    const float want = std::clamp(e[c], 0.f, 1.f);
                    ASSERT_NEAR(got[c], want, 1e-6) << "tile " << i + 1 << " " << x << "," << y;
                    ASSERT_NEAR(got8[c], want, 1.0 / 255.0 + 1e-6) << "tile " << i + 1;
                }
            }
    }
    // Tile 4: the heatmap of G-MoN's relerr against the reference.
    {
        DiffOptions o;
        o.luma = lumaCoefficients();
        HeatmapOptions h;
        h.colorBar = false;
        const OIIO::ImageBuf want = heatmap(errorImage(images[1], refImg, o), h);
        ASSERT_FALSE(want.has_error()) << want.geterror();
        const int x0 = s.get_int_attribute("mcstat:tile4:x"),
                  y0 = s.get_int_attribute("mcstat:tile4:y");
        for (int y = 0; y < H; y += 7)
            for (int x = 0; x < W; x += 7) {
                float e[3], got[3];
                want.getpixel(x / scale, y / scale, e, 3);
                sheet.getpixel(x0 + x, y0 + y, got, 3);
                for (int c = 0; c < 3; ++c) ASSERT_NEAR(got[c], std::clamp(e[c], 0.f, 1.f), 1e-6);
            }
    }

    // Metrics: the library's numbers, and the lines --diff prints for the same images.
    const Result d = mcstat("a.mcstat --dup --mean --diff ref.exr --pop --gmon --diff ref.exr");
    ASSERT_EQ(d.code, 0) << d.err;
    const char* names[2] = {"mean", "gmon"};
    for (int i = 0; i < 2; ++i) {
        const std::string t = "mcstat:tile" + std::to_string(i + 1) + ":";
        const DiffMetrics want = diff(images[i], refImg);
        EXPECT_EQ(s.get_string_attribute(t + "name"), std::string(names[i]) + "(a.mcstat)");
        EXPECT_NEAR(doubleAttr(s, t + "relMSE"), want.relMSE, 1e-12 * want.relMSE);
        EXPECT_NEAR(doubleAttr(s, t + "SSIM"), want.ssim, 1e-12);
        EXPECT_EQ(s.get_int_attribute(t + "fireflies", -1), int(want.fireflies));
        const std::string diffLine = lineWith(d.out, std::string(names[i]) + "(a.mcstat)");
        EXPECT_EQ(lineWith(r.out, std::string(names[i]) + "(a.mcstat)"), diffLine);
        EXPECT_NEAR(field(diffLine, "relMSE"), want.relMSE, 1e-5 * want.relMSE);
    }
    EXPECT_EQ(s.get_string_attribute("mcstat:tile4:name"), "relerr(gmon(a.mcstat))");
}

TEST_F(ReviewCli, ContactSheetRefusals) {
    Result r = mcstat(path("ref.exr") + " --contactsheet " + path("ref.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err,
              "mcstat: --contactsheet: the top of the stack must be a statistics file (.mcstat), "
              "not the image " +
                  path("ref.exr") + "\n");
    r = mcstat("a.mcstat --contactsheet:estimators=gmon,nope " + path("ref.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("unknown estimator 'nope'"), std::string::npos) << r.err;
    render("--spp 4 --res 16 12 --reference -o " + path("small.exr"));
    r = mcstat("a.mcstat --contactsheet " + path("small.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("32x24 but the reference is 16x12"), std::string::npos) << r.err;
}

TEST_F(ReviewCli, ErrorMapAndHeatmap) {
    const Result r = mcstat(
        "a.mcstat --gmon --errormap ref.exr -o err.exr --heatmap -o hm.exr -o "
        "hm.png");
    ASSERT_EQ(r.code, 0) << r.err;
    // The error map: relMSE's per-pixel term and the firefly mask of metrics.h.
    const OIIO::ImageBuf e = readFloat(path("err.exr"));
    ASSERT_EQ(e.nchannels(), 2);
    // OpenEXR sorts channels by name: read them by name.
    const int rc = e.spec().channelindex("relerr"), fc = e.spec().channelindex("firefly");
    ASSERT_GE(rc, 0);
    ASSERT_GE(fc, 0);
    const OIIO::ImageBuf gmon = run(stats("a.mcstat"), "gmon"), refImg = ref();
    std::vector<float> lin(32 * 24 * 3), rl(lin.size());
    gmon.get_pixels(OIIO::ROI(0, 32, 0, 24, 0, 1, 0, 3), OIIO::TypeDesc::FLOAT, lin.data());
    refImg.get_pixels(OIIO::ROI(0, 32, 0, 24, 0, 1, 0, 3), OIIO::TypeDesc::FLOAT, rl.data());
    DiffOptions o;
    o.luma = lumaCoefficients();
    double sum = 0.0, ff = 0.0;
    for (int p = 0; p < 32 * 24; ++p) {
        double rel = 0.0;
        for (int c = 0; c < 3; ++c) {
            const double x = lin[p * 3 + c], y = rl[p * 3 + c];
            rel += (x - y) * (x - y) / (y * y + 0.01) / 3.0;
        }
        float v[2];
        e.getpixel(p % 32, p / 32, v, 2);
        ASSERT_NEAR(v[rc], rel, 1e-6 * std::max(1.0, rel)) << p;
        sum += v[rc];
        ff += v[fc];
    }
    const DiffMetrics m = diff(gmon, refImg);
    EXPECT_NEAR(sum / (32 * 24), m.relMSE, 1e-6 * m.relMSE);
    EXPECT_EQ(ff, double(m.fireflies));

    // The heatmap is display-referred: -o writes it as it is (PNG = EXR to 8 bits).
    const OIIO::ImageBuf hm = readFloat(path("hm.exr")), hm8 = readFloat(path("hm.png"));
    EXPECT_EQ(hm.spec().get_int_attribute("mcstat:displayReferred"), 1);
    EXPECT_EQ(hm.spec().get_int_attribute("mcstat:heatmap:log"), 1);
    EXPECT_EQ(hm.spec().get_int_attribute("mcstat:heatmap:scale"), 8);  // 32 px -> 256
    ASSERT_EQ(hm8.spec().width, hm.spec().width);
    ASSERT_EQ(hm8.spec().height, hm.spec().height);
    for (int y = 0; y < hm.spec().height; y += 3)
        for (int x = 0; x < hm.spec().width; x += 3) {
            float a[3], b[3];
            hm.getpixel(x, y, a, 3);
            hm8.getpixel(x, y, b, 3);
            for (int c = 0; c < 3; ++c) ASSERT_NEAR(a[c], b[c], 1.0 / 255.0 + 1e-6);
        }

    // The caption says what the picture is of: the estimator, the file, M and spp, the reference;
    // the error map carries them (and the reference), so a heatmap of it read back says the same.
    const std::string caption = "G-MoN (gini=abs, mode=lum) of a.mcstat (M = 5, 40 spp) vs ref.exr";
    EXPECT_EQ(hm.spec().get_string_attribute("mcstat:heatmap:caption"), caption);
    EXPECT_EQ(e.spec().get_string_attribute("mcstat.operation"), "gmon");
    EXPECT_EQ(e.spec().get_string_attribute("mcstat.errormap.reference"), "ref.exr");
    Result g = mcstat("err.exr --heatmap -o hm2.exr");
    ASSERT_EQ(g.code, 0) << g.err;
    EXPECT_EQ(readFloat(path("hm2.exr")).spec().get_string_attribute("mcstat:heatmap:caption"),
              caption);
    EXPECT_GT(hm.spec().get_int_attribute("mcstat:heatmap:y"), ReviewStyle().margin);

    // Diagnostics channels by name; no reference in their caption.
    g = mcstat("a.mcstat --gmon:diag=1 --heatmap:channel=kept:map=viridis -o kept.exr");
    ASSERT_EQ(g.code, 0) << g.err;
    const OIIO::ImageSpec ks = readFloat(path("kept.exr")).spec();
    EXPECT_EQ(ks.get_string_attribute("mcstat:heatmap:channel"), "kept");
    EXPECT_EQ(ks.get_int_attribute("mcstat:heatmap:log"), 0);
    EXPECT_EQ(ks.get_string_attribute("mcstat:heatmap:caption"),
              "G-MoN (gini=abs, mode=lum) of a.mcstat (M = 5, 40 spp)");

    // The mean's firefly mask: a 0/1 legend, its swatches in the colours of the pixels.
    g = mcstat(
        "a.mcstat --mean --errormap:floor=0:ratio=1.2 ref.exr -o ferr.exr "
        "--heatmap:channel=firefly -o ff.exr");
    ASSERT_EQ(g.code, 0) << g.err;
    const OIIO::ImageBuf mask = readFloat(path("ff.exr")), ferr = readFloat(path("ferr.exr"));
    const OIIO::ImageSpec& fs = mask.spec();
    EXPECT_EQ(fs.get_int_attribute("mcstat:heatmap:binary"), 1);
    EXPECT_EQ(fs.get_int_attribute("mcstat:colorbar:width", -1), -1);
    EXPECT_EQ(fs.get_string_attribute("mcstat:heatmap:caption"),
              "mean of a.mcstat (M = 5, 40 spp) vs ref.exr");
    const int s = fs.get_int_attribute("mcstat:heatmap:scale"),
              mx = fs.get_int_attribute("mcstat:heatmap:x"),
              my = fs.get_int_attribute("mcstat:heatmap:y");
    float sw[2][3];
    for (int i = 0; i < 2; ++i) {
        const std::string p = "mcstat:legend:swatch" + std::to_string(i) + ":";
        ASSERT_GT(fs.get_int_attribute(p + "width"), 0) << i;
        mask.getpixel(fs.get_int_attribute(p + "x") + 2, fs.get_int_attribute(p + "y") + 2, sw[i],
                      3);
    }
    const int fc2 = ferr.spec().channelindex("firefly");
    int counted[2] = {0, 0};
    for (int p = 0; p < 32 * 24; ++p) {
        float v[2], c[3];
        ferr.getpixel(p % 32, p / 32, v, 2);
        mask.getpixel(mx + (p % 32) * s, my + (p / 32) * s, c, 3);
        const int k = v[fc2] == 1.f ? 1 : 0;
        ++counted[k];
        for (int ch = 0; ch < 3; ++ch) ASSERT_EQ(c[ch], sw[k][ch]) << p;
    }
    EXPECT_GT(counted[1], 0);  // ratio 1.2 with no floor: some pixels are fireflies
    EXPECT_GT(counted[0], 0);
    g = mcstat(
        "a.mcstat --gmon --errormap:floor=0:ratio=1 ref.exr --heatmap:channel=firefly:min=0:max=1 "
        "-o f.exr");
    ASSERT_EQ(g.code, 0) << g.err;
    // Refusals: one line each.
    g = mcstat("a.mcstat --heatmap");
    EXPECT_EQ(g.code, 1);
    EXPECT_NE(g.err.find("apply an estimator first"), std::string::npos) << g.err;
    g = mcstat("a.mcstat --gmon --heatmap:channel=gini");
    EXPECT_EQ(g.code, 1);
    EXPECT_NE(g.err.find("no channel 'gini' (channels: 'R', 'G', 'B')"), std::string::npos)
        << g.err;
    g = mcstat("a.mcstat --gmon --heatmap:log=2");
    EXPECT_EQ(g.code, 1);
    EXPECT_NE(g.err.find("log must be 'auto', '0' or '1', not '2'"), std::string::npos) << g.err;
}

TEST_F(ReviewCli, QualityPlotCsvMatchesDiff) {
    // Temporary files go to the test's own directory, so the test can see they are removed.
    const std::string tmp = path("tmp");
    OIIO::Filesystem::create_directory(tmp);
    setenv("TMPDIR", tmp.c_str(), 1);
    const Result r = mcstat("a.mcstat --qualityplot:estimators=mean,gmon:csv=" + path("q.csv") +
                            " ref.exr -o " + path("q.png") + " -o " + path("q.exr"));
    unsetenv("TMPDIR");
    ASSERT_EQ(r.code, 0) << r.err;
    std::vector<std::string> left;
    OIIO::Filesystem::get_directory_entries(tmp, left);
    EXPECT_TRUE(left.empty()) << left.size() << " temporary files left";

    // Default k: 1, 3, 5 (every odd k up to M = 5); 8 samples per buffer.
    const std::vector<CsvRow> rows = readCsv(path("q.csv"));
    ASSERT_EQ(rows.size(), 6u);
    for (const CsvRow& row : rows) EXPECT_EQ(row.spp, 8.0 * row.buffers) << row.estimator;

    // Two (k, estimator) rows recomputed independently: the first k buffers written as a file of
    // their own, run through `mcstat --<est> --diff` and through the library.
    const StatsImage a = stats("a.mcstat");
    const OIIO::ImageBuf refImg = ref();
    for (const auto& [k, est] :
         std::vector<std::pair<int, std::string>>{{3, "gmon"}, {1, "mean"}, {3, "mean"}}) {
        const CsvRow* row = findRow(rows, k, est);
        ASSERT_NE(row, nullptr);
        const StatsImage sub = firstBuffers(a, k);
        const DiffMetrics want = diff(run(sub, est), refImg);
        EXPECT_NEAR(row->relMSE, want.relMSE, 1e-6 * want.relMSE) << k << " " << est;
        EXPECT_NEAR(row->ssim, want.ssim, 1e-6 * want.ssim) << k << " " << est;
        EXPECT_NEAR(row->psnr, want.psnr, 1e-6 * want.psnr) << k << " " << est;
        EXPECT_EQ(row->fireflies, want.fireflies) << k << " " << est;
        std::string err;
        const std::string file = "k" + std::to_string(k) + ".mcstat";
        ASSERT_TRUE(writeStatsFile(path(file), sub, err)) << err;
        const Result d = mcstat(file + " --" + est + " --diff ref.exr");
        ASSERT_EQ(d.code, 0) << d.err;
        // --diff prints 6 significant digits.
        EXPECT_NEAR(field(d.out, "relMSE"), row->relMSE, 5e-6 * row->relMSE) << k << " " << est;
        EXPECT_NEAR(field(d.out, "SSIM"), row->ssim, 5e-5) << k << " " << est;
    }
    // k = M is the whole file: the same relMSE as --diff of the file itself.
    const Result full = mcstat("a.mcstat --gmon --diff ref.exr");
    ASSERT_EQ(full.code, 0) << full.err;
    const CsvRow* last = findRow(rows, 5, "gmon");
    ASSERT_NE(last, nullptr);
    EXPECT_NEAR(last->relMSE, diff(run(a, "gmon"), refImg).relMSE, 1e-12 * last->relMSE);
    EXPECT_NEAR(field(full.out, "relMSE"), last->relMSE, 5e-6 * last->relMSE);

    // The plot: gnuplot's PNG, display-referred, written as it is.
    const OIIO::ImageBuf plot = readFloat(path("q.exr"));
    EXPECT_EQ(plot.spec().width, 1200);
    EXPECT_EQ(plot.spec().height, 480);
    EXPECT_EQ(plot.spec().get_int_attribute("mcstat:displayReferred"), 1);
    EXPECT_EQ(readFloat(path("q.png")).spec().width, 1200);
}

TEST_F(ReviewCli, QualityPlotSeveralFilesAndChosenBuffers) {
    render("--spp 20 --M 3 --seed 2 -o " + path("b.mcstat"));
    Result r = mcstat("a.mcstat b.mcstat --qualityplot:estimators=gmon:csv=" + path("q.csv") +
                      " ref.exr --info");
    ASSERT_EQ(r.code, 0) << r.err;
    std::vector<CsvRow> rows = readCsv(path("q.csv"));
    ASSERT_EQ(rows.size(), 2u);
    const OIIO::ImageBuf refImg = ref();
    const char* files[2] = {"a.mcstat", "b.mcstat"};
    const double spp[2] = {40, 20};
    const int M[2] = {5, 3};
    for (int i = 0; i < 2; ++i) {
        EXPECT_EQ(rows[i].spp, spp[i]);
        EXPECT_EQ(rows[i].buffers, M[i]);
        const DiffMetrics want = diff(run(stats(files[i]), "gmon"), refImg);
        EXPECT_NEAR(rows[i].relMSE, want.relMSE, 1e-12 * want.relMSE);
    }
    // Both files popped, the plot pushed.
    EXPECT_NE(r.out.find("qualityplot(2 files): 1200 x 480, 3 channels"), std::string::npos)
        << r.out;
    EXPECT_EQ(rows[0].bytesPerPixel, 0.0) << "x=spp: no sizes";

    // x=bytes: each file's bytes per pixel on disk (docs/compact.md draws full against compact).
    r = mcstat("a.mcstat b.mcstat --qualityplot:x=bytes:estimators=gmon:csv=" + path("x.csv") +
               " ref.exr");
    ASSERT_EQ(r.code, 0) << r.err;
    rows = readCsv(path("x.csv"));
    ASSERT_EQ(rows.size(), 2u);
    for (int i = 0; i < 2; ++i) {
        const double px = double(ref().spec().width) * double(ref().spec().height);
        const double want = double(OIIO::Filesystem::file_size(path(files[i]))) / px;
        EXPECT_NEAR(rows[i].bytesPerPixel, want, 1e-5 * want);  // the CSV's 6 digits
    }
    r = mcstat("a.mcstat --qualityplot:x=bytes ref.exr");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("x=bytes plots files of different sizes"), std::string::npos) << r.err;

    r = mcstat("a.mcstat --qualityplot:estimators=mon:buffers=5,2:csv=" + path("k.csv") +
               " ref.exr");
    ASSERT_EQ(r.code, 0) << r.err;
    rows = readCsv(path("k.csv"));
    ASSERT_EQ(rows.size(), 2u);
    EXPECT_EQ(rows[0].buffers, 2);
    EXPECT_EQ(rows[1].buffers, 5);
    EXPECT_EQ(rows[0].spp, 16.0);
}

TEST_F(ReviewCli, QualityPlotRefusals) {
    Result r = mcstat("a.mcstat --qualityplot:buffers=0,3 ref.exr");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("--qualityplot: buffers must be an integer in [1, 999], not '0'"),
              std::string::npos)
        << r.err;
    r = mcstat("a.mcstat --qualityplot:buffers=3,6 ref.exr");  // the file has M = 5
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("buffers must be an integer in 1..5, not '6'"), std::string::npos)
        << r.err;
    r = mcstat("a.mcstat a.mcstat --qualityplot:buffers=3 ref.exr");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("buffers applies to a single statistics file"), std::string::npos)
        << r.err;
    r = mcstat("ref.exr --qualityplot ref.exr");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("must be a statistics file"), std::string::npos) << r.err;
    render("--spp 40 --adaptive-m --m-max 5 -o " + path("ad.mcstat"));
    r = mcstat("ad.mcstat --qualityplot ref.exr");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("has adaptive M"), std::string::npos) << r.err;

    // Without gnuplot on PATH: one clear line, before any work.
    const std::string out = path("nognuplot.err");
    const std::string cmd = "cd " + dir + " && env PATH=" + dir + " " + MCSTAT_EXE +
                            " a.mcstat --qualityplot ref.exr >/dev/null 2>" + out;
    const int status = mcstat::testing::runCommand(cmd.c_str());
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << status;
    EXPECT_EQ(mcstat::testing::slurp(out),
              "mcstat: --qualityplot: needs gnuplot (scripts/install-deps.sh installs "
              "gnuplot-nox)\n");
}
