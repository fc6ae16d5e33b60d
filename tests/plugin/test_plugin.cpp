// The OIIO plugin end to end: Debian's own oiiotool, iinfo and idiff, with OIIO_LIBRARY_PATH
// pointing at the built mcstat.imageio.so, against the `mcstat` command line and the library called
// directly. Plus the ImageInput interface in process (errors, channel subsets, subimage bounds).
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <dlfcn.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "mcstat/color/color.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/version.h"

namespace {

using OIIO::Strutil::contains;

struct Result {
    int code = 0;
    std::string out, err;
};

std::string slurp(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    std::stringstream s;
    s << f.rdbuf();
    return s.str();
}

std::string quote(const std::string& s) { return "'" + s + "'"; }

/// One image read back as float: its channel names and pixels.
struct Pixels {
    std::vector<std::string> channels;
    std::vector<float> data;
    int width = 0, height = 0;
    std::string subimageName;
};

class Plugin : public ::testing::Test {
  protected:
    std::string dir;
    std::string stats;  ///< the statistics file rendered for this test
    std::string stem;

    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir = std::string(MCSTAT_BINARY_DIR) + "/tests/plugin/tmp-" + info->name();
        OIIO::Filesystem::remove_all(dir);
        ASSERT_TRUE(OIIO::Filesystem::create_directory(dir));
        stem = dir + "/run";
        stats = path("f.mcstat");
        const Result r = run(std::string(MCSTAT_RENDER_EXE) +
                             " --scene tiny --spp 16 --M 5 --quiet -o " + quote(stats));
        ASSERT_EQ(r.code, 0) << r.err;
    }
    std::string path(const std::string& name) const { return dir + "/" + name; }

    /// Runs a shell command with stdout and stderr captured. `plugin` puts the built plugin on
    /// OIIO_LIBRARY_PATH; otherwise the variable is removed so OIIO falls back to its EXR reader.
    Result run(const std::string& cmd, bool plugin = true) const {
        const std::string o = stem + ".stdout", e = stem + ".stderr";
        std::string env = plugin ? std::string("env OIIO_LIBRARY_PATH=") + MCSTAT_PLUGIN_DIR + " "
                                 : std::string("env -u OIIO_LIBRARY_PATH ");
        env += MCSTAT_TOOL_ENV;
        const std::string full = env + " " + cmd + " >" + o + " 2>" + e;
        Result r;
        const int status = std::system(full.c_str());
        r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        r.out = slurp(o);
        r.err = slurp(e);
        return r;
    }
    Result mcstat(const std::string& args) const {
        return run(std::string(MCSTAT_EXE) + " " + args, false);
    }

    /// Reads subimage `sub` of an EXR written by a tool (OIIO's own reader, no plugin needed).
    static Pixels readExr(const std::string& file, int sub = 0) {
        Pixels p;
        OIIO::ImageBuf b(file, sub, 0);
        EXPECT_TRUE(b.read(sub, 0, true, OIIO::TypeDesc::FLOAT)) << file << ": " << b.geterror();
        const OIIO::ImageSpec& s = b.spec();
        p.channels = s.channelnames;
        p.width = s.width;
        p.height = s.height;
        p.subimageName = s.get_string_attribute("oiio:subimagename");
        p.data.resize(size_t(s.width) * s.height * s.nchannels);
        if (!p.data.empty()) b.get_pixels(b.roi(), OIIO::TypeDesc::FLOAT, p.data.data());
        return p;
    }
    static int subimageCount(const std::string& file) {
        auto in = OIIO::ImageInput::open(file);
        if (!in) return -1;
        int n = 0;
        while (in->seek_subimage(n, 0)) ++n;
        return n;
    }
    mcstat::StatsImage loadStats() const {
        mcstat::StatsImage s;
        std::string err;
        EXPECT_TRUE(mcstat::readStatsFile(stats, s, err)) << err;
        return s;
    }
    /// The library's own answer, as `mcstat` computes it.
    Pixels library(const std::string& est, const std::map<std::string, std::string>& kv = {},
                   bool diag = false) const {
        const mcstat::Operation* info = mcstat::findEstimator(est);
        EXPECT_NE(info, nullptr);
        mcstat::PixelKernel kernel;
        std::string err;
        EXPECT_TRUE(mcstat::bindPixelKernel(*info, kv, mcstat::lumaCoefficients(), kernel, err))
            << err;
        OIIO::ImageBuf b = mcstat::estimate(loadStats(), *info, kernel, diag);
        Pixels p;
        p.channels = b.spec().channelnames;
        p.width = b.spec().width;
        p.height = b.spec().height;
        p.data.resize(size_t(p.width) * p.height * p.channels.size());
        b.get_pixels(b.roi(), OIIO::TypeDesc::FLOAT, p.data.data());
        return p;
    }
};

/// Bitwise equality of pixel data (NaN-safe, -0 distinct from +0), with the first difference named.
::testing::AssertionResult samePixels(const Pixels& a, const Pixels& b) {
    if (a.channels != b.channels)
        return ::testing::AssertionFailure() << "channels " << OIIO::Strutil::join(a.channels, ",")
                                             << " vs " << OIIO::Strutil::join(b.channels, ",");
    if (a.width != b.width || a.height != b.height || a.data.size() != b.data.size())
        return ::testing::AssertionFailure() << "sizes differ";
    for (size_t i = 0; i < a.data.size(); ++i)
        if (std::memcmp(&a.data[i], &b.data[i], sizeof(float)) != 0)
            return ::testing::AssertionFailure()
                   << "value " << i << " (pixel " << i / a.channels.size() << ", channel "
                   << a.channels[i % a.channels.size()] << "): " << a.data[i] << " vs "
                   << b.data[i];
    return ::testing::AssertionSuccess();
}

/// Value of channel `name` of pixel p; NaN (and a test failure) when the channel is missing.
float value(const Pixels& img, size_t p, const std::string& name) {
    for (size_t c = 0; c < img.channels.size(); ++c)
        if (img.channels[c] == name) return img.data[p * img.channels.size() + c];
    ADD_FAILURE() << "no channel " << name << " in " << OIIO::Strutil::join(img.channels, ",");
    return NAN;
}

size_t countDifferent(const Pixels& a, const Pixels& b) {
    size_t n = 0;
    for (size_t i = 0; i < std::min(a.data.size(), b.data.size()); ++i)
        n += std::memcmp(&a.data[i], &b.data[i], sizeof(float)) != 0;
    return n;
}

// ---- pixels -------------------------------------------------------------------------------------

TEST_F(Plugin, DefaultIsGmonBitIdenticalToMcstatWithAnyThreadCount) {
    ASSERT_EQ(mcstat("--threads 1 " + quote(stats) + " --gmon -o " + quote(path("b.exr"))).code, 0);
    const Pixels b = readExr(path("b.exr"));
    ASSERT_TRUE(samePixels(b, library("gmon")));
    for (const char* threads : {"1", "3", "0"}) {
        SCOPED_TRACE(std::string("oiiotool --threads ") + threads);
        const std::string a = path(std::string("a") + threads + ".exr");
        const Result r = run(std::string("oiiotool --threads ") + threads + " " + quote(stats) +
                             " -o " + quote(a));
        ASSERT_EQ(r.code, 0) << r.err;
        const Pixels pa = readExr(a);
        EXPECT_EQ(pa.subimageName, "gmon");
        EXPECT_TRUE(samePixels(pa, b));
    }
    // The robust image is not just the mean: the tiny scene at 16 spp has fireflies G-MoN trims.
    EXPECT_GT(countDifferent(readExr(path("a1.exr")), library("mean")), 10u);
}

TEST_F(Plugin, AllSubimagesHoldWhatTheFileHolds) {
    const std::string a = path("all.exr");
    const Result r = run("oiiotool " + quote(stats) + " -o " + quote(a));
    ASSERT_EQ(r.code, 0) << r.err;
    ASSERT_EQ(subimageCount(a), 4);
    const mcstat::StatsImage s = loadStats();
    const size_t npix = s.pixelCount();

    const Pixels mean = readExr(a, 1);
    EXPECT_EQ(mean.subimageName, "mean");
    EXPECT_EQ(mean.channels, (std::vector<std::string>{"R", "G", "B"}));
    ASSERT_EQ(mean.data.size(), s.beauty.size());
    EXPECT_EQ(std::memcmp(mean.data.data(), s.beauty.data(), s.beauty.size() * sizeof(float)), 0);

    // Diagnostics: the estimator's own diag channels, plus the sample count. (OpenEXR stores
    // channels sorted by name, so they are looked up by name.)
    const Pixels diag = readExr(a, 2);
    EXPECT_EQ(diag.subimageName, "diagnostics");
    ASSERT_EQ(diag.channels.size(), 4u);
    const Pixels lib = library("gmon", {}, true);
    ASSERT_EQ(lib.channels, (std::vector<std::string>{"R", "G", "B", "gini", "kept", "excluded"}));
    bool someTrimmed = false;
    for (size_t p = 0; p < npix; ++p) {
        for (int c = 3; c < 6; ++c)
            ASSERT_EQ(value(diag, p, lib.channels[size_t(c)]), lib.data[p * 6 + size_t(c)]) << p;
        ASSERT_EQ(value(diag, p, "count"), s.count[p]) << p;
        const float kept = value(diag, p, "kept");
        ASSERT_GE(kept, 1.f) << p;  // at least one buffer kept
        ASSERT_LE(kept, 5.f) << p;
        someTrimmed = someTrimmed || kept < 5.f;
    }
    EXPECT_TRUE(someTrimmed);

    const Pixels feat = readExr(a, 3);
    EXPECT_EQ(feat.subimageName, "features");
    ASSERT_EQ(feat.channels.size(), 11u);
    const char* xyz[] = {"X", "Y", "Z"};
    const char* rgb[] = {"R", "G", "B"};
    for (size_t p = 0; p < npix; ++p) {
        for (size_t c = 0; c < 3; ++c) {
            ASSERT_EQ(value(feat, p, std::string("N.") + xyz[c]), s.normal[p * 3 + c]);
            ASSERT_EQ(value(feat, p, std::string("P.") + xyz[c]), s.position[p * 3 + c]);
            ASSERT_EQ(value(feat, p, std::string("Albedo.") + rgb[c]), s.albedo[p * 3 + c]);
        }
        ASSERT_EQ(value(feat, p, "Z"), s.depth[p]);
        ASSERT_EQ(value(feat, p, "A"), s.coverage[p]);
    }
}

TEST_F(Plugin, AdaptiveFilesShowTheirBufferCountMap) {
    // mcstat-render --adaptive-m, both strategies: the diagnostics subimage gains channel M, each
    // pixel's buffer count as the file stores it, and the metadata says how it was assigned.
    for (const char* strategy : {"grow", "pilot"}) {
        SCOPED_TRACE(strategy);
        const std::string f = path(std::string(strategy) + ".mcstat");
        const Result r = run(std::string(MCSTAT_RENDER_EXE) +
                             " --scene tiny --spp 40 --adaptive-m --m-max 9 --m-strategy " +
                             strategy + " --quiet -o " + quote(f));
        ASSERT_EQ(r.code, 0) << r.err;
        mcstat::StatsImage s;
        std::string err;
        ASSERT_TRUE(mcstat::readStatsFile(f, s, err)) << err;
        ASSERT_TRUE(s.header.adaptiveM);
        EXPECT_EQ(s.header.M, 9);
        const std::string a = path(std::string(strategy) + ".exr");
        const Result o = run("oiiotool " + quote(f) + " --subimage diagnostics -o " + quote(a));
        ASSERT_EQ(o.code, 0) << o.err;
        const Pixels diag = readExr(a);
        std::map<float, int> histogram;
        for (size_t p = 0; p < s.pixelCount(); ++p) {
            ASSERT_EQ(value(diag, p, "M"), float(s.buffersOf(p))) << "pixel " << p;
            ASSERT_LE(value(diag, p, "kept"), value(diag, p, "M")) << "pixel " << p;
            ++histogram[value(diag, p, "M")];
        }
        EXPECT_GE(histogram.size(), 2u) << "the tiny scene needs more than one buffer count";
        EXPECT_GT(histogram[1.f], 0);
        const Result i = run("iinfo -v " + quote(f));
        ASSERT_EQ(i.code, 0) << i.err;
        for (const std::string& want :
             {std::string("mcstat:adaptiveM: 1"), std::string("mcstat:formatVersion: 2"),
              std::string("mcstat:assignment: \"") +
                  (strategy == std::string("grow") ? "leastcount" : "roundrobin") + "\""})
            EXPECT_TRUE(contains(i.out, want)) << "missing '" << want << "' in\n" << i.out;
    }
    // Bad adaptive options are one-line errors naming the option.
    const Result bad = run(std::string(MCSTAT_RENDER_EXE) +
                           " --scene tiny --adaptive-m --m-strategy later -o " + quote(path("x")));
    EXPECT_EQ(bad.code, 1);
    EXPECT_TRUE(contains(bad.err, "--m-strategy: expected 'grow' or 'pilot', got 'later'"))
        << bad.err;
    const Result one = run(std::string(MCSTAT_RENDER_EXE) +
                           " --scene tiny --adaptive-m --checkpoint 1 -o " + quote(path("x")));
    EXPECT_EQ(one.code, 1);
    EXPECT_TRUE(contains(one.err, "checkpoint must be at least 2")) << one.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("x")));
}

TEST_F(Plugin, EstimatorAndParametersThroughIconfig) {
    ASSERT_EQ(mcstat(quote(stats) + " --mon:mode=channel -o " + quote(path("d.exr"))).code, 0);
    const Result r = run("oiiotool --iconfig mcstat:estimator mon --iconfig mcstat:mode channel " +
                         quote(stats) + " -o " + quote(path("c.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    const Pixels c = readExr(path("c.exr"));
    EXPECT_EQ(c.subimageName, "mon");
    EXPECT_TRUE(samePixels(c, readExr(path("d.exr"))));
    EXPECT_GT(countDifferent(c, library("mon")), 0u);  // mode=channel took effect
    EXPECT_GT(countDifferent(c, library("gmon")), 0u);

    // A number: oiiotool stores "0.3" as a float attribute; the plugin reads it back as 0.3.
    ASSERT_EQ(mcstat(quote(stats) + " --gmonb:threshold=0.3 -o " + quote(path("y.exr"))).code, 0);
    const Result r2 =
        run("oiiotool --iconfig mcstat:estimator gmonb --iconfig mcstat:threshold 0.3 " +
            quote(stats) + " -o " + quote(path("x.exr")));
    ASSERT_EQ(r2.code, 0) << r2.err;
    EXPECT_TRUE(samePixels(readExr(path("x.exr")), readExr(path("y.exr"))));
}

TEST_F(Plugin, EstimatorAndParametersThroughTheFileName) {
    ASSERT_EQ(mcstat(quote(stats) + " --mon:mode=channel -o " + quote(path("d.exr"))).code, 0);
    Result r = run("oiiotool " + quote(stats + "?estimator=mon&mode=channel") + " -o " +
                   quote(path("e.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(samePixels(readExr(path("e.exr")), readExr(path("d.exr"))));

    ASSERT_EQ(mcstat(quote(stats) + " --tmpe:alpha=0.1 -o " + quote(path("t1.exr"))).code, 0);
    r = run("oiiotool " + quote(stats + "?estimator=tmpe&alpha=0.1") + " -o " +
            quote(path("t2.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(samePixels(readExr(path("t2.exr")), readExr(path("t1.exr"))));
    // iconvert has no --iconfig: the file-name form is its way in.
    r = run("iconvert " + quote(stats + "?estimator=tmpe&alpha=0.1") + " " + quote(path("t3.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(samePixels(readExr(path("t3.exr")), readExr(path("t1.exr"))));
}

// keeplight through the file name (stock oiiotool): the command's pixels; its refusal named.
TEST_F(Plugin, KeepLightThroughTheFileName) {
    ASSERT_EQ(mcstat(quote(stats) + " --gmon:keeplight=1 -o " + quote(path("k1.exr"))).code, 0);
    Result r = run("oiiotool " + quote(stats + "?estimator=gmon&keeplight=1") + " -o " +
                   quote(path("k2.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(samePixels(readExr(path("k2.exr")), readExr(path("k1.exr"))));
    EXPECT_GT(countDifferent(readExr(path("k2.exr")), library("gmon")), 0u);
    r = run("iinfo " + quote(stats + "?estimator=gmon&keeplightgamma=2"));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "keeplightgamma needs keeplight=1")) << r.err;
}

// ci through the file name (it surfaced as "File does not exist"): subimage 0 holds the command's
// channels, R, G, B and the interval's bounds, with its pixels; the diagnostics keep theirs; ci
// with keeplight is refused by name.
TEST_F(Plugin, ConfidenceIntervalThroughTheFileName) {
    ASSERT_EQ(mcstat(quote(stats) + " --gmon:ci=0.95 -o " + quote(path("c1.exr"))).code, 0);
    Result r = run("oiiotool " + quote(stats + "?estimator=gmon&ci=0.95") + " -o " +
                   quote(path("c2.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    const Pixels c2 = readExr(path("c2.exr"));
    EXPECT_EQ(c2.channels.size(), 9u);
    EXPECT_NE(std::find(c2.channels.begin(), c2.channels.end(), "ci_low.G"), c2.channels.end());
    EXPECT_TRUE(samePixels(c2, readExr(path("c1.exr"))));
    r = run("oiiotool " + quote(stats + "?estimator=gmon&ci=0.95") + " --subimage 2 -o " +
            quote(path("c3.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    const Pixels c3 = readExr(path("c3.exr"));
    EXPECT_EQ(std::find(c3.channels.begin(), c3.channels.end(), "ci_low.R"), c3.channels.end());
    r = run("iinfo " + quote(stats + "?estimator=gmon&ci=0.95&keeplight=1"));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "keeplight and ci")) << r.err;
}

TEST_F(Plugin, UnknownParameterOrEstimatorIsNamed) {
    Result r = run("oiiotool --iconfig mcstat:m 3 " + quote(stats) + " -o " + quote(path("x.exr")));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "has no parameter 'm'")) << r.err;
    EXPECT_TRUE(contains(r.err, "accepted: mode")) << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("x.exr")));

    r = run("iinfo " + quote(stats + "?estimator=foo"));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "unknown estimator 'foo'")) << r.err;
    EXPECT_TRUE(contains(r.err, "mean, mon, gmon, gmonb")) << r.err;

    r = run("iinfo " + quote(stats + "?estimator=gmonb&threshold=2"));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "threshold must be a number in [0, 1], not '2'")) << r.err;
}

TEST_F(Plugin, IdiffComparesTwoEstimators) {
    // The same estimator twice: identical.
    Result r = run("idiff " + quote(stats) + " " + quote(stats + "?estimator=gmon"));
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    EXPECT_TRUE(contains(r.out, "PASS")) << r.out;

    // MoN against the mean: idiff's maximum error is the library's.
    const Pixels mon = library("mon"), mean = library("mean");
    double maxErr = 0.0;
    for (size_t i = 0; i < mon.data.size(); ++i)
        maxErr = std::max(maxErr, std::abs(double(mon.data[i]) - double(mean.data[i])));
    ASSERT_GT(maxErr, 0.1);
    r = run("idiff " + quote(stats + "?estimator=mon") + " " + quote(stats + "?estimator=mean"));
    EXPECT_EQ(r.code, 2) << r.out << r.err;  // idiff: 2 = FAILURE
    EXPECT_TRUE(contains(r.out, "FAILURE")) << r.out;
    const size_t at = r.out.find("Max error");
    ASSERT_NE(at, std::string::npos) << r.out;
    const double reported = std::atof(r.out.c_str() + r.out.find('=', at) + 1);
    EXPECT_NEAR(reported, maxErr, 1e-5 * maxErr) << r.out;

    // A generous threshold turns the same comparison into a pass.
    r = run("idiff -fail 1000 -warn 1000 " + quote(stats + "?estimator=mon") + " " +
            quote(stats + "?estimator=mean"));
    EXPECT_EQ(r.code, 0) << r.out << r.err;
}

TEST_F(Plugin, RandomParameterFilteringFromTheRegistry) {
    // "f.mcstat?estimator=rpf" is `mcstat f --rpf` (tolerance 0), parameters from the name; a
    // file without per-sample records is a clear error naming the flag that writes them.
    const std::string dof = path("dof.mcstat");
    ASSERT_EQ(run(std::string(MCSTAT_RENDER_EXE) +
                  " --scene dof --res 24 20 --spp 4 --keep-samples --quiet -o " + quote(dof))
                  .code,
              0);
    ASSERT_EQ(mcstat(quote(dof) + " --rpf:passes=2 -o " + quote(path("r1.exr"))).code, 0);
    Result r =
        run("oiiotool " + quote(dof + "?estimator=rpf&passes=2") + " -o " + quote(path("r2.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(samePixels(readExr(path("r2.exr")), readExr(path("r1.exr"))));
    r = run("iinfo -v " + quote(stats + "?estimator=rpf"));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.out + r.err, "--keep-samples")) << r.out << r.err;
}

TEST_F(Plugin, NeighbourhoodOperationsFromTheRegistry) {
    // idiff "f.mcstat?estimator=3dwtmf" against `mcstat f --3dwtmf`: tolerance 0.
    ASSERT_EQ(mcstat(quote(stats) + " --3dwtmf -o " + quote(path("w.exr"))).code, 0);
    Result r = run("idiff -fail 0 -warn 0 " + quote(stats + "?estimator=3dwtmf") + " " +
                   quote(path("w.exr")));
    EXPECT_EQ(r.code, 0) << r.out << r.err;
    EXPECT_TRUE(contains(r.out, "PASS")) << r.out;
    r = run("oiiotool " + quote(stats + "?estimator=3dwtmf") + " -o " + quote(path("p.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    const Pixels p = readExr(path("p.exr"));
    EXPECT_EQ(p.subimageName, "3dwtmf");
    EXPECT_TRUE(samePixels(p, readExr(path("w.exr"))));
    EXPECT_GT(countDifferent(p, library("gmon")), 0u);

    // Parameters the same way as an estimator's, from the file name or the configuration.
    ASSERT_EQ(
        mcstat(quote(stats) + " --3dwmf:size=5x3:w=2:mode=channel -o " + quote(path("m1.exr")))
            .code,
        0);
    r = run("oiiotool " + quote(stats + "?estimator=3dwmf&size=5x3&w=2&mode=channel") + " -o " +
            quote(path("m2.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(samePixels(readExr(path("m2.exr")), readExr(path("m1.exr"))));
    r = run("oiiotool --iconfig mcstat:estimator 3dmf --iconfig mcstat:size 1x1 " + quote(stats) +
            " -o " + quote(path("m3.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(samePixels(readExr(path("m3.exr")), library("median")));  // 3DMF(1x1) = MPE

    // MIF / WMIF filter the plain mean: the same as `mcstat f --mean --wmif`.
    ASSERT_EQ(mcstat(quote(stats) + " --mean --wmif:w=5 -o " + quote(path("i1.exr"))).code, 0);
    r = run("oiiotool " + quote(stats + "?estimator=wmif&w=5") + " -o " + quote(path("i2.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(samePixels(readExr(path("i2.exr")), readExr(path("i1.exr"))));

    // Their diagnostics subimage holds the sample count only; a bad value names itself.
    r = run("oiiotool -a " + quote(stats + "?estimator=3dwtmf") + " -o " + quote(path("all.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(readExr(path("all.exr"), 2).channels, (std::vector<std::string>{"count"}));
    r = run("iinfo " + quote(stats + "?estimator=3dwtmf&alpha=0.7"));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "alpha must be a number in [0, 0.5], not '0.7'")) << r.err;
    r = run("iinfo " + quote(stats + "?estimator=3dmf&w=2"));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "estimator '3dmf' has no parameter 'w' (accepted: size, mode)"))
        << r.err;
    r = run("iinfo " + quote(stats + "?estimator=foo"));
    EXPECT_TRUE(contains(r.err, "3dmf, 3dwmf, 3dwtmf")) << r.err;
}

TEST_F(Plugin, IinfoListsSubimagesAndMetadata) {
    const Result r = run("iinfo -v -a " + quote(stats));
    ASSERT_EQ(r.code, 0) << r.err;
    for (const char* s :
         {"float mcstat", "4 subimages", "channel list: R, G, B",
          "channel list: gini, kept, excluded, count",
          "channel list: N.X, N.Y, N.Z, P.X, P.Y, P.Z, Albedo.R, Albedo.G, Albedo.B, Z, A",
          "oiio:subimagename: \"gmon\"", "oiio:subimagename: \"mean\"",
          "oiio:subimagename: \"diagnostics\"", "oiio:subimagename: \"features\"",
          "mcstat:estimator: \"gmon\"", "mcstat:mode: \"lum\"", "mcstat:M: 5", "mcstat:spp: 16",
          "mcstat:formatVersion: 1", "mcstat:assignment: \"roundrobin\"",
          "mcstat:colorSpace: \"lin_rec709\"", "mcstat:renderer: \"mcstat-render", "mcstat:seeds:"})
        EXPECT_TRUE(contains(r.out, s)) << "missing '" << s << "' in\n" << r.out;

    const Result t = run("iinfo -v " + quote(stats + "?estimator=tmpe&alpha=0.1"));
    ASSERT_EQ(t.code, 0) << t.err;
    EXPECT_TRUE(contains(t.out, "mcstat:estimator: \"tmpe\"")) << t.out;
    EXPECT_TRUE(contains(t.out, "mcstat:alpha: \"0.1\"")) << t.out;
}

TEST_F(Plugin, CorruptFileIsAnErrorNamingTheFile) {
    const std::string bytes = slurp(stats);
    // Cut short: the OpenEXR headers survive, the pixel data does not.
    const std::string cut = path("cut.mcstat");
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
    // Garbage with the right extension.
    const std::string junk = path("junk.mcstat");
    std::ofstream(junk, std::ios::binary) << "this is not an image";

    Result r = run("oiiotool " + quote(cut) + " -o " + quote(path("x.exr")));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "cut.mcstat")) << r.err;
    EXPECT_FALSE(OIIO::Filesystem::exists(path("x.exr")));
    // oiiotool reads with a configuration without its image cache: the plugin's message comes
    // through whole.
    r = run("oiiotool --iconfig mcstat:estimator gmon " + quote(cut) + " -o " +
            quote(path("x.exr")));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "cut.mcstat: truncated or corrupt")) << r.err;
    r = run("idiff " + quote(cut) + " " + quote(stats));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "cut.mcstat: truncated or corrupt")) << r.err;

    r = run("oiiotool " + quote(junk) + " -o " + quote(path("x.exr")));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "junk.mcstat: not an OpenEXR file")) << r.err;

    // A valid OpenEXR file that fails mcstat's validation (a newer format version), made by
    // OIIO's own EXR reader and writer.
    const std::string newer = std::to_string(mcstat::kStatsFormatVersion + 1);
    r = run("oiiotool -a " + quote(stats) + " --attrib:type=int mcstat:formatVersion " + newer +
                " -o " + quote(path("v4.exr")),
            false);
    ASSERT_EQ(r.code, 0) << r.err;
    ASSERT_TRUE(OIIO::Filesystem::rename(path("v4.exr"), path("v4.mcstat")));
    r = run("oiiotool " + quote(path("v4.mcstat")) + " -o " + quote(path("x.exr")));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "v4.mcstat")) << r.err;
    r = run("idiff " + quote(path("v4.mcstat")) + " " + quote(stats));
    EXPECT_NE(r.code, 0);
    EXPECT_TRUE(contains(r.err, "written by a newer mcstat (format " + newer + ")")) << r.err;
}

TEST_F(Plugin, IngestedFileShowsItsProvenanceAndNoFeaturesItDoesNotHave) {
    // Three renders of one image as plain EXRs (no G-buffer AOVs), ingested: format 3, no
    // features, so no features subimage; the robust subimage equals mcstat's G-MoN.
    std::string list;
    for (int s = 1; s <= 3; ++s) {
        const std::string f = path("seed" + std::to_string(s) + ".exr");
        const Result r = run(std::string(MCSTAT_RENDER_EXE) + " --scene tiny --spp 8 --seed " +
                                 std::to_string(s) + " --reference --quiet -o " + quote(f),
                             false);
        ASSERT_EQ(r.code, 0) << r.err;
        list += (s > 1 ? "," : "") + f;
    }
    const std::string ingested = path("ingested.mcstat");
    Result r = mcstat("--ingest " + quote(list) + " -o " + quote(ingested) + " --gmon -o " +
                      quote(path("mcstat-gmon.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    r = run("oiiotool --info -v " + quote(ingested));
    ASSERT_EQ(r.code, 0) << r.err;
    // gmon, mean, diagnostics: no features subimage (the raw file has 4 parts, features NaN).
    EXPECT_TRUE(contains(r.out, "3 subimages: ")) << r.out;
    EXPECT_TRUE(contains(r.out, "mcstat:variance: \"buffers\"")) << r.out;
    EXPECT_TRUE(contains(r.out, "mcstat:assignment: \"perfile\"")) << r.out;
    EXPECT_TRUE(contains(r.out, "mcstat:sources: \"seed1.exr,seed2.exr,seed3.exr\"")) << r.out;
    r = run("oiiotool " + quote(ingested) + " -o " + quote(path("plugin-gmon.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    const Pixels a = readExr(path("plugin-gmon.exr")), b = readExr(path("mcstat-gmon.exr"));
    EXPECT_EQ(a.data, b.data);
    EXPECT_FALSE(a.data.empty());
    // A rendered file has no source files: no empty mcstat:sources (issue 34, item 8). With AOVs
    // it is format 5, which carries the provenance attributes.
    const std::string rendered = path("rendered.mcstat");
    ASSERT_EQ(run(std::string(MCSTAT_RENDER_EXE) + " --scene tiny --spp 8 --aovs --quiet -o " +
                      quote(rendered),
                  false)
                  .code,
              0);
    r = run("oiiotool --info -v " + quote(rendered));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "mcstat:formatVersion: 5")) << r.out;
    EXPECT_TRUE(contains(r.out, "mcstat:variance:")) << r.out;
    EXPECT_FALSE(contains(r.out, "mcstat:sources")) << r.out;
}

TEST_F(Plugin, AovsAlphaAndProvenanceSurviveStockOiiotool) {
    // A file with AOVs (alpha and the light-path split): subimage 0 holds the robust beauty, A as
    // OIIO's alpha channel and every AOV, as mcstat's --gmon writes them; stock oiiotool writing
    // it keeps the provenance (names without the "mcstat:" prefix OIIO would drop on output).
    const std::string f = path("aovs.mcstat");
    Result r = run(std::string(MCSTAT_RENDER_EXE) +
                       " --scene tiny --spp 16 --M 5 --aovs --quiet -o " + quote(f),
                   false);
    ASSERT_EQ(r.code, 0) << r.err;
    ASSERT_EQ(mcstat(quote(f) + " --gmon -o " + quote(path("mcstat-gmon.exr"))).code, 0);
    r = run("oiiotool " + quote(f) + " --subimage 0 -o " + quote(path("plugin-gmon.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    const Pixels a = readExr(path("plugin-gmon.exr")), b = readExr(path("mcstat-gmon.exr"));
    EXPECT_EQ(a.channels, b.channels);
    EXPECT_EQ(a.data, b.data);
    ASSERT_EQ(a.channels.size(), 22u);
    auto in = OIIO::ImageInput::open(path("plugin-gmon.exr"));
    ASSERT_TRUE(in);
    const OIIO::ImageSpec& spec = in->spec();
    ASSERT_GE(spec.alpha_channel, 0);
    EXPECT_EQ(spec.channelnames[size_t(spec.alpha_channel)], "A");
    EXPECT_EQ(spec.get_string_attribute("mcstat.operation"), "gmon");
    EXPECT_EQ(spec.get_int_attribute("mcstat.M"), 5);
    EXPECT_EQ(spec.get_int_attribute("mcstat.spp"), 16);
    // The plugin's own view: alpha on subimage 0 only; the diagnostics' count and the features'
    // positions are not alpha.
    OIIO::attribute("plugin_searchpath", std::string(MCSTAT_PLUGIN_DIR));
    auto plugin = OIIO::ImageInput::open(f);
    ASSERT_TRUE(plugin) << OIIO::geterror();
    for (int si = 0; plugin->seek_subimage(si, 0); ++si) {
        const OIIO::ImageSpec& s = plugin->spec();
        const std::string name = s.get_string_attribute("oiio:subimagename");
        if (si == 0) {
            EXPECT_EQ(s.channelnames[size_t(std::max(0, s.alpha_channel))], "A") << name;
        } else if (name != "features") {
            EXPECT_EQ(s.alpha_channel, -1) << name;
        } else if (s.alpha_channel >= 0) {
            EXPECT_EQ(s.channelnames[size_t(s.alpha_channel)], "A") << name;  // coverage
        }
    }
}

TEST_F(Plugin, CompactFilesGiveTheFullFilesGMoNWithAovs) {
    // docs/compact.md: stock oiiotool through the plugin on a compact file shows the same robust
    // image, AOVs included, bit for bit, as on the full file; the compact file is smaller.
    const std::string full = path("full.mcstat"), small = path("small.mcstat");
    Result r = run(std::string(MCSTAT_RENDER_EXE) +
                       " --scene tiny --spp 48 --M 9 --aovs --quiet -o " + quote(full),
                   false);
    ASSERT_EQ(r.code, 0) << r.err;
    ASSERT_EQ(mcstat(quote(full) + " --compact -o " + quote(small)).code, 0);
    EXPECT_LT(OIIO::Filesystem::file_size(small), OIIO::Filesystem::file_size(full));
    r = run("oiiotool " + quote(full) + " --subimage 0 -o " + quote(path("a.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    r = run("oiiotool " + quote(small) + " --subimage 0 -o " + quote(path("b.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    const Pixels a = readExr(path("a.exr")), b = readExr(path("b.exr"));
    EXPECT_EQ(a.channels, b.channels);
    EXPECT_TRUE(samePixels(a, b));
    r = run("oiiotool --info -v " + quote(small));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("mcstat:formatVersion: 8"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("mcstat:compact: \"gmon luma="), std::string::npos) << r.out;
}

TEST_F(Plugin, OverscanAndTheRendersMetadataSurviveStockOiiotool) {
    // Renders with overscan (data window 2 pixels beyond a 12x10 display window) and a frame
    // number, ingested: subimage 0, written by stock oiiotool, keeps both windows and the frame.
    std::string list;
    for (int s = 1; s <= 3; ++s) {
        const std::string plain = path("plain" + std::to_string(s) + ".exr");
        const std::string f = path("over" + std::to_string(s) + ".exr");
        Result r =
            run(std::string(MCSTAT_RENDER_EXE) + " --scene tiny --res 16 14 --spp 4 --seed " +
                    std::to_string(s) + " --reference --quiet -o " + quote(plain),
                false);
        ASSERT_EQ(r.code, 0) << r.err;
        r = run("oiiotool " + quote(plain) +
                    " --origin -2-2 --fullsize 12x10+0+0 --attrib:type=int frame 42 -o " + quote(f),
                false);
        ASSERT_EQ(r.code, 0) << r.err;
        list += (s > 1 ? "," : "") + f;
    }
    const std::string ingested = path("over.mcstat");
    Result r = mcstat("--ingest " + quote(list) + " -o " + quote(ingested));
    ASSERT_EQ(r.code, 0) << r.err;
    r = run("oiiotool " + quote(ingested) + " --subimage 0 -o " + quote(path("x.exr")));
    ASSERT_EQ(r.code, 0) << r.err;
    auto in = OIIO::ImageInput::open(path("x.exr"));
    ASSERT_TRUE(in) << OIIO::geterror();
    const OIIO::ImageSpec& spec = in->spec();
    EXPECT_EQ(spec.x, -2);
    EXPECT_EQ(spec.y, -2);
    EXPECT_EQ(spec.width, 16);
    EXPECT_EQ(spec.height, 14);
    EXPECT_EQ(spec.full_x, 0);
    EXPECT_EQ(spec.full_y, 0);
    EXPECT_EQ(spec.full_width, 12);
    EXPECT_EQ(spec.full_height, 10);
    EXPECT_EQ(spec.get_int_attribute("frame"), 42);
    EXPECT_EQ(spec.get_string_attribute("mcstat.operation"), "gmon");
    EXPECT_EQ(spec.get_int_attribute("mcstat.M"), 3);
    EXPECT_EQ(spec.get_string_attribute("mcstat.sources"), "over1.exr,over2.exr,over3.exr");
}

TEST_F(Plugin, WithoutThePluginOpenExrShowsTheRawParts) {
    const Result r = run("oiiotool --info -v -a " + quote(stats), false);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "float openexr")) << r.out;
    EXPECT_FALSE(contains(r.out, "float mcstat")) << r.out;
    EXPECT_TRUE(contains(r.out, "4 subimages")) << r.out;
    for (const char* part : {"beauty", "buffers", "moments", "features"})
        EXPECT_TRUE(contains(r.out, std::string("oiio:subimagename: \"") + part + "\""))
            << part << "\n"
            << r.out;
    EXPECT_TRUE(contains(r.out, "b004.count")) << r.out;  // M = 5 buffers
}

// ---- the ImageInput interface in process --------------------------------------------------------

class PluginApi : public Plugin {
  protected:
    void SetUp() override {
        Plugin::SetUp();
        OIIO::attribute("plugin_searchpath", std::string(MCSTAT_PLUGIN_DIR));
    }
    /// The mcstat reader itself (create without open: OIIO picks it by extension and valid_file).
    std::unique_ptr<OIIO::ImageInput> reader(const std::string& file) {
        auto in = OIIO::ImageInput::create(file, false);
        EXPECT_TRUE(in) << OIIO::geterror();
        if (in) {
            EXPECT_STREQ(in->format_name(), "mcstat");
        }
        return in;
    }
};

TEST(PluginVersion, IsTheProjectsOne) {
    // OIIO lists a plugin's <format>_imageio_library_version in "library_list"; it is the version
    // CMake defines once (mcstat/version.h), as `mcstat --version` prints it.
    void* so = dlopen((std::string(MCSTAT_PLUGIN_DIR) + "/mcstat.imageio.so").c_str(), RTLD_NOW);
    ASSERT_TRUE(so) << dlerror();
    using VersionFn = const char* (*)();
    const auto fn = reinterpret_cast<VersionFn>(dlsym(so, "mcstat_imageio_library_version"));
    ASSERT_TRUE(fn);
    EXPECT_EQ(std::string(fn()), std::string("mcstat ") + MCSTAT_VERSION);
    dlclose(so);
}

TEST_F(PluginApi, ReadsChannelSubsetsAndRejectsBadRequests) {
    auto in = reader(stats);
    ASSERT_TRUE(in);
    EXPECT_TRUE(in->valid_file(stats));
    EXPECT_TRUE(in->valid_file(stats + "?estimator=mon"));
    EXPECT_FALSE(in->valid_file(path("missing.mcstat")));
    OIIO::ImageSpec spec;
    ASSERT_TRUE(in->open(stats, spec)) << in->geterror();
    EXPECT_EQ(spec.nchannels, 3);
    EXPECT_EQ(spec.format, OIIO::TypeDesc::FLOAT);

    // Channels Z and A of the features, two rows, against the file.
    ASSERT_TRUE(in->seek_subimage(3, 0));
    EXPECT_EQ(in->current_subimage(), 3);
    const OIIO::ImageSpec fs = in->spec();
    std::vector<float> za(size_t(fs.width) * 2 * 2);
    ASSERT_TRUE(
        in->read_scanlines(3, 0, fs.y + 1, fs.y + 3, 0, 9, 11, OIIO::TypeDesc::FLOAT, za.data()))
        << in->geterror();
    const mcstat::StatsImage s = loadStats();
    for (int y = 0; y < 2; ++y)
        for (int x = 0; x < fs.width; ++x) {
            const size_t p = size_t(y + 1) * size_t(fs.width) + size_t(x);
            const size_t q = (size_t(y) * size_t(fs.width) + size_t(x)) * 2;
            ASSERT_EQ(za[q], s.depth[p]);
            ASSERT_EQ(za[q + 1], s.coverage[p]);
        }

    EXPECT_FALSE(in->seek_subimage(4, 0));
    EXPECT_FALSE(in->seek_subimage(0, 1));
    std::vector<float> row(size_t(spec.width) * 3);
    EXPECT_FALSE(in->read_native_scanline(0, 0, spec.y + spec.height, 0, row.data()));
    EXPECT_TRUE(in->has_error());
    EXPECT_TRUE(contains(in->geterror(), "outside subimage 0"));
    EXPECT_FALSE(in->read_native_scanline(7, 0, spec.y, 0, row.data()));
    EXPECT_TRUE(contains(in->geterror(), "no subimage 7"));
    EXPECT_TRUE(in->close());
    EXPECT_FALSE(in->seek_subimage(0, 0));  // closed
}

TEST_F(PluginApi, EachSubimageIsComputedOncePerProcessAndOnlyWhenRead) {
    // The plugin counts its computations; OIIO has loaded it into this process by now.
    auto probe = reader(stats);
    ASSERT_TRUE(probe);
    void* so = dlopen((std::string(MCSTAT_PLUGIN_DIR) + "/mcstat.imageio.so").c_str(),
                      RTLD_NOW | RTLD_NOLOAD);
    ASSERT_NE(so, nullptr) << "the plugin is not loaded";
    using Count = uint64_t (*)();
    const auto computations = reinterpret_cast<Count>(dlsym(so, "mcstat_imageio_computations"));
    ASSERT_NE(computations, nullptr);
    // A copy no other test has read (the cache is per process).
    const std::string file = path("once.mcstat");
    std::ofstream(file, std::ios::binary) << slurp(stats);
    const auto readAll = [&](const std::string& name, int subimage, std::vector<float>& px) {
        auto in = reader(name);
        OIIO::ImageSpec spec;
        ASSERT_TRUE(in->open(name, spec)) << in->geterror();
        ASSERT_TRUE(in->seek_subimage(subimage, 0));
        const OIIO::ImageSpec s = in->spec();
        px.resize(size_t(s.image_pixels()) * size_t(s.nchannels));
        ASSERT_TRUE(in->read_scanlines(subimage, 0, s.y, s.y + s.height, 0, 0, s.nchannels,
                                       OIIO::TypeDesc::FLOAT, px.data()))
            << in->geterror();
    };
    const uint64_t start = computations();
    {
        auto in = reader(file);
        OIIO::ImageSpec spec;
        ASSERT_TRUE(in->open(file, spec)) << in->geterror();
        EXPECT_EQ(spec.nchannels, 3);
    }
    EXPECT_EQ(computations(), start) << "open() computed pixels";
    std::vector<float> a, b;
    readAll(file, 0, a);
    EXPECT_EQ(computations(), start + 1);
    readAll(file, 0, b);  // reopened, read again: served from the cache
    EXPECT_EQ(computations(), start + 1);
    EXPECT_EQ(a, b);
    readAll(file, 1, b);  // the mean: its own computation, once
    readAll(file, 1, b);
    EXPECT_EQ(computations(), start + 2);
    readAll(file + "?estimator=mon", 0, b);  // another operation is another key
    EXPECT_EQ(computations(), start + 3);
    // The diagnostics: the estimator with its diagnostics, and the counts (part moments).
    readAll(file, 2, b);
    EXPECT_EQ(computations(), start + 5);
    // A rewritten file is a new key, with the new file's pixels.
    mcstat::StatsImage img = loadStats();
    for (float& v : img.bufferMean) v *= 2.f;
    std::string err;
    ASSERT_TRUE(mcstat::writeStatsFile(file, img, err)) << err;
    readAll(file, 0, b);
    EXPECT_EQ(computations(), start + 6);
    EXPECT_NE(a, b);
}

TEST_F(PluginApi, OpenReportsErrorsWithoutThrowing) {
    const std::string bytes = slurp(stats);
    const std::string cut = path("cut.mcstat");
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() - 100);
    auto in = reader(cut);
    ASSERT_TRUE(in);
    OIIO::ImageSpec spec;
    EXPECT_FALSE(in->open(cut, spec));
    EXPECT_TRUE(in->has_error());
    const std::string err = in->geterror();
    EXPECT_TRUE(contains(err, "cut.mcstat: truncated or corrupt")) << err;

    // Parameters from the configuration; a bad one names itself.
    auto in2 = reader(stats);
    ASSERT_TRUE(in2);
    OIIO::ImageSpec config;
    config.attribute("mcstat:estimator", "myriad");
    config.attribute("mcstat:gamma", -1.0f);
    EXPECT_FALSE(in2->open(stats, spec, config));
    EXPECT_TRUE(contains(in2->geterror(), "gamma must be a finite number > 0, not '-1'"));
    config.attribute("mcstat:gamma", 0.1f);
    config.attribute("mcstat:scale", "abs");
    ASSERT_TRUE(in2->open(stats, spec, config)) << in2->geterror();
    EXPECT_EQ(spec.get_string_attribute("mcstat:estimator"), "myriad");
    EXPECT_EQ(spec.get_string_attribute("mcstat:gamma"), "0.1");
    EXPECT_EQ(spec.get_string_attribute("mcstat:scale"), "abs");
    EXPECT_EQ(spec.get_string_attribute("oiio:subimagename"), "myriad");
    // The file name wins over the configuration.
    ASSERT_TRUE(in2->open(stats + "?estimator=mon", spec, config) == false);
    EXPECT_TRUE(contains(in2->geterror(), "estimator 'mon' has no parameter 'gamma'"));
}

/// Sets the data window's maximum of every part to (maxX, maxY) in the bytes of a file.
std::string patchDataWindow(std::string bytes, int32_t maxX, int32_t maxY) {
    const std::string key = std::string("dataWindow") + '\0' + "box2i" + '\0';
    for (size_t at = bytes.find(key); at != std::string::npos; at = bytes.find(key, at + 1)) {
        std::memcpy(&bytes[at + key.size() + 4 + 8], &maxX, 4);  // little endian here
        std::memcpy(&bytes[at + key.size() + 4 + 12], &maxY, 4);
    }
    return bytes;
}

// The plugin meets the malformed files mcstat was tried with. Each is refused, through
// the API (open or read fails, one line naming the file) and through stock oiiotool (exit status
// 1, not a crash): the fuzzers' saved findings, claims of sizes the file cannot hold, and cuts.
TEST_F(PluginApi, MalformedFilesAreRefusedWithOneLineNamingTheFile) {
    const std::string bytes = slurp(stats);
    std::vector<std::string> files;
    for (const char* t : {"stats_file", "records"}) {
        const std::string regressions =
            std::string(MCSTAT_SOURCE_DIR) + "/tests/fuzz/regressions/" + t;
        for (const auto& e : std::filesystem::directory_iterator(regressions)) {
            const std::string f = path(std::string(t) + "-" + e.path().filename().string());
            std::filesystem::copy_file(e.path(), f);
            files.push_back(f);
        }
    }
    auto add = [&](const std::string& name, const std::string& content) {
        std::ofstream(path(name), std::ios::binary) << content;
        files.push_back(path(name));
    };
    add("tall.mcstat", patchDataWindow(bytes, 15, 1000000));
    add("wide.mcstat", patchDataWindow(bytes, 999999, 15));
    for (int k = 1; k < 8; ++k)
        add("cut" + std::to_string(k) + ".mcstat", bytes.substr(0, bytes.size() * size_t(k) / 8));
    add("empty.mcstat", "");

    for (const std::string& f : files) {
        // create() itself refuses what valid_file() rejects (an empty file), with the reason.
        auto in = OIIO::ImageInput::create(f, false);
        std::string err;
        if (!in) {
            err = OIIO::geterror();
        } else {
            EXPECT_STREQ(in->format_name(), "mcstat");
            OIIO::ImageSpec spec;
            if (in->open(f, spec)) {  // headers fine: the pixels are not
                std::vector<float> px(size_t(spec.image_pixels()) * size_t(spec.nchannels));
                EXPECT_FALSE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeFloat, px.data()))
                    << f;
            }
            err = in->geterror();
        }
        EXPECT_TRUE(contains(err, f + ": ")) << f << " -> " << err;
        EXPECT_EQ(err.find('\n'), std::string::npos) << err;

        const Result r = run("oiiotool " + quote(f) + " -o " + quote(path("x.exr")));
        EXPECT_EQ(r.code, 1) << f << " -> " << r.err;
        EXPECT_TRUE(contains(r.err, f)) << r.err;
        EXPECT_FALSE(OIIO::Filesystem::exists(path("x.exr")));
    }
}

}  // namespace
