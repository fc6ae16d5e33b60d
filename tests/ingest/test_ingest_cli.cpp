// `mcstat --ingest` and name-true `--diff` as a user runs them: 21 seed renders in Blender/Cycles
// multilayer naming become a statistics file with one command, and G-MoN of it equals G-MoN
// computed here by hand from the files themselves.
#include <OpenImageIO/imagebuf.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numeric>

#include "../cli/cli_support.h"
#include "mcstat/color/color.h"
#include "render_files.h"

namespace mcstat::testing {
namespace {

/// Reads every channel of an EXR as floats.
std::vector<float> pixelsOf(const std::string& path, OIIO::ImageSpec& spec) {
    OIIO::ImageBuf in(path);
    EXPECT_TRUE(in.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << in.geterror();
    spec = in.spec();
    std::vector<float> px(size_t(spec.width) * spec.height * spec.nchannels);
    in.get_pixels(in.roi(), OIIO::TypeDesc::FLOAT, px.data());
    return px;
}

class IngestCli : public CliFixture {
  protected:
    static constexpr int kW = 24, kH = 16, kSeeds = 21;
    /// Renders seed s of the default scene (8 spp, plain RGB) and rewrites it in Cycles'
    /// multilayer naming with an AO pass that sorts before Combined. Returns the file's RGB.
    std::vector<float> cyclesRender(int s, const std::string& name) {
        const std::string plain = path(fmt("plain{}.exr", s));
        const std::string cmd = std::string(MCSTAT_RENDER_EXE) +
                                fmt(" --scene default --res {} {} --spp 8 --seed {} --reference "
                                    "--quiet -o ",
                                    kW, kH, 1000 + s) +
                                plain;
        EXPECT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0) << cmd;
        OIIO::ImageSpec spec;
        const std::vector<float> rgb = pixelsOf(plain, spec);
        ExrSpec e;
        e.width = kW;
        e.height = kH;
        e.channels = cyclesChannels();
        e.stringAttrs["cycles.ViewLayer.samples"] = "8";
        e.half = true;  // Blender writes half by default
        std::vector<float> stored(rgb.size());
        writeExr(path(name), e, [&](const std::string& n, int x, int y) -> float {
            const size_t p = size_t(y) * kW + size_t(x);
            const int c = n.back() == 'R' ? 0 : n.back() == 'G' ? 1 : 2;
            if (n.find("Combined.A") != std::string::npos) return 1.f;
            if (n.find("Combined") != std::string::npos) return rgb[p * 3 + size_t(c)];
            if (n.find("AO") != std::string::npos) return 0.9f;
            return 0.5f;
        });
        // What the file holds after the half rounding.
        std::vector<float> back = pixelsOf(path(name), spec);
        std::vector<float> out(size_t(kW) * kH * 3);
        const auto& ch = spec.channelnames;
        for (int c = 0; c < 3; ++c) {
            const int i =
                int(std::find(ch.begin(), ch.end(), std::string("ViewLayer.Combined.") + "RGB"[c]) -
                    ch.begin());
            for (size_t p = 0; p < out.size() / 3; ++p)
                out[p * 3 + size_t(c)] = back[p * size_t(spec.nchannels) + size_t(i)];
        }
        return out;
    }
    template <class... A>
    static std::string fmt(const char* f, A... a) {
        return OIIO::Strutil::fmt::format(f, a...);
    }
};

/// G-MoN of one pixel written out from the paper (Buisine et al. 2021): rank the buffers by
/// luminance, Gini coefficient of the sorted luminances (eq. 4, its original form), trim
/// c = floor(k - (1 - G) k) from each side with k = floor(M / 2) (section 4.3), average the rest
/// (eq. 6). Equal counts, so the plain average.
std::array<double, 3> gmonByHand(const std::vector<std::array<float, 3>>& buffers,
                                 const std::array<double, 3>& luma) {
    const int M = int(buffers.size());
    std::vector<int> order(buffers.size());
    std::iota(order.begin(), order.end(), 0);
    auto Y = [&](int j) {
        return luma[0] * buffers[size_t(j)][0] + luma[1] * buffers[size_t(j)][1] +
               luma[2] * buffers[size_t(j)][2];
    };
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return Y(a) < Y(b); });
    double sum = 0.0, weighted = 0.0;
    for (int i = 0; i < M; ++i) {
        sum += Y(order[size_t(i)]);
        weighted += double(i + 1) * Y(order[size_t(i)]);
    }
    const double G =
        sum > 0 ? std::clamp(2.0 * weighted / (M * sum) - double(M + 1) / M, 0.0, 1.0) : 0.0;
    const int k = M / 2;
    const int c = std::min(int(std::floor(k - (1.0 - G) * k)), (M - 1) / 2);
    std::array<double, 3> out{0, 0, 0};
    for (int i = c; i < M - c; ++i)
        for (int ch = 0; ch < 3; ++ch)
            out[size_t(ch)] += buffers[size_t(order[size_t(i)])][size_t(ch)];
    for (double& v : out) v /= double(M - 2 * c);
    return out;
}

TEST_F(IngestCli, TwentyOneCyclesSeedRendersGMoNEqualsTheHandComputedOne) {
    std::vector<std::vector<float>> files;
    for (int s = 1; s <= kSeeds; ++s)
        files.push_back(cyclesRender(s, fmt("scene_s{}_8spp.exr", s)));
    const Result r = mcstat("--ingest '" + path("scene_s*_8spp.exr") + "' -o " +
                            path("scene.mcstat") + " --gmon -o " + path("gmon.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.err, "");  // no warning: 21 files, equal spp, finite values

    const Result info = mcstat(path("scene.mcstat") + " --info");
    EXPECT_NE(info.out.find("M = 21 sub-buffers, spp = 168, assignment perfile"), std::string::npos)
        << info.out;
    EXPECT_NE(info.out.find("sources scene_s1_8spp.exr,scene_s2_8spp.exr,scene_s3_8spp.exr"),
              std::string::npos)
        << info.out;  // natural order: s2 before s10

    OIIO::ImageSpec spec;
    const std::vector<float> all = pixelsOf(path("gmon.exr"), spec);
    ASSERT_EQ(spec.width, kW);
    // A drop-in for one input render (docs/aovs.md): every channel under the input's name.
    ASSERT_EQ(spec.nchannels, int(cyclesChannels().size()));
    for (const std::string& n : cyclesChannels()) EXPECT_GE(spec.channelindex(n), 0) << n;
    std::vector<float> gmon(size_t(kW) * kH * 3);
    for (int c = 0; c < 3; ++c) {
        const int ch = spec.channelindex(std::string("ViewLayer.Combined.") + "RGB"[c]);
        ASSERT_GE(ch, 0);
        for (size_t p = 0; p < size_t(kW) * kH; ++p)
            gmon[p * 3 + size_t(c)] = all[p * size_t(spec.nchannels) + size_t(ch)];
    }
    EXPECT_EQ(spec.channelnames[size_t(spec.alpha_channel)], "ViewLayer.Combined.A");
    const std::array<double, 3> luma = lumaCoefficients();
    double worst = 0.0;
    int differing = 0;
    for (size_t p = 0; p < size_t(kW) * kH; ++p) {
        std::vector<std::array<float, 3>> buffers;
        for (const auto& f : files) buffers.push_back({f[p * 3], f[p * 3 + 1], f[p * 3 + 2]});
        const std::array<double, 3> want = gmonByHand(buffers, luma);
        bool same = true;
        for (int c = 0; c < 3; ++c) {
            // Tolerance: float32 storage of a double average, ~2^-24 relative.
            const double d = std::abs(gmon[p * 3 + size_t(c)] - want[size_t(c)]);
            worst = std::max(worst, d / (1e-6 + std::abs(want[size_t(c)])));
            same = same && d <= 1e-6 * (1e-3 + std::abs(want[size_t(c)]));
        }
        differing += !same;
    }
    EXPECT_EQ(differing, 0) << "worst relative difference " << worst;
    std::printf(
        "G-MoN of 21 ingested Cycles renders against the hand-computed one: worst relative "
        "difference %.3g over %d pixels\n",
        worst, kW * kH);
    // And the robust estimate is not simply the mean: the seeds' fireflies were trimmed.
    const Result diff = mcstat("--ingest '" + path("scene_s*_8spp.exr") + "' --dup --mean -o " +
                               path("mean.exr") + " --pop --gmon -o " + path("gmon2.exr"));
    ASSERT_EQ(diff.code, 0) << diff.err;
    OIIO::ImageSpec s2;
    EXPECT_EQ(pixelsOf(path("gmon2.exr"), s2), all);  // with or without the file in between
    EXPECT_NE(pixelsOf(path("mean.exr"), s2), all);
}

TEST_F(IngestCli, DiffPicksRGBByNameNotTheAOLayerThatSortsFirst) {
    // The image under test and its reference as plain RGB, and the same reference in Cycles'
    // naming with an AO layer (values 0.9) before Combined.
    const std::vector<float> img = cyclesRender(1, "img_multilayer.exr");
    cyclesRender(2, "ref_multilayer.exr");
    const Result plainRef = mcstat(path("plain2.exr") + " --info");
    ASSERT_EQ(plainRef.code, 0);
    const Result a = mcstat(path("plain1.exr") + " --diff " + path("plain2.exr"));
    const Result b = mcstat(path("plain1.exr") + " --diff " + path("ref_multilayer.exr"));
    const Result c = mcstat(path("img_multilayer.exr") + " --diff " + path("ref_multilayer.exr"));
    ASSERT_EQ(a.code, 0) << a.err;
    ASSERT_EQ(b.code, 0) << b.err;
    ASSERT_EQ(c.code, 0) << c.err;
    const auto metrics = [](const std::string& line) { return line.substr(line.find("relMSE")); };
    // The multilayer files hold half-rounded values: compare the printed metrics to the
    // plain files' within that rounding by comparing the multilayer ones with each other.
    EXPECT_EQ(metrics(b.out).substr(0, 12), metrics(a.out).substr(0, 12)) << a.out << b.out;
    EXPECT_EQ(metrics(c.out).substr(0, 12), metrics(a.out).substr(0, 12)) << a.out << c.out;
    // Asking for the AO layer does compare with AO, and gives another relMSE.
    const Result ao =
        mcstat(path("plain1.exr") + " --diff:layer=ViewLayer.AO " + path("ref_multilayer.exr"));
    ASSERT_EQ(ao.code, 0) << ao.err;
    EXPECT_NE(metrics(ao.out).substr(0, 12), metrics(a.out).substr(0, 12));
    (void)img;
}

TEST_F(IngestCli, DisplayWritesAndImageFiltersTakeRGBByName) {
    // A multilayer image written as PNG shows its Combined pass, not the AO pass before it; the
    // median image filter filters Combined too.
    ExrSpec e;
    e.width = 6;
    e.height = 4;
    e.channels = cyclesChannels();
    const auto value = [](const std::string& n, int x, int y) -> float {
        if (n.find("AO") != std::string::npos) return 0.9f;
        return 0.05f * float(x + y) + (n.back() == 'G' ? 0.2f : 0.f);
    };
    writeExr(path("ml.exr"), e, value);
    e.channels = {"R", "G", "B"};
    writeExr(path("plain.exr"), e, value);
    ASSERT_EQ(
        mcstat(path("ml.exr") + " -o " + path("ml.png") + " --mif -o " + path("ml-mif.exr")).code,
        0);
    ASSERT_EQ(mcstat(path("plain.exr") + " -o " + path("plain.png") + " --mif -o " +
                     path("plain-mif.exr"))
                  .code,
              0);
    OIIO::ImageSpec a, b;
    EXPECT_EQ(pixelsOf(path("ml.png"), a), pixelsOf(path("plain.png"), b));
    EXPECT_EQ(pixelsOf(path("ml-mif.exr"), a), pixelsOf(path("plain-mif.exr"), b));
    EXPECT_EQ(a.nchannels, 3);
}

TEST_F(IngestCli, DiffRefusesAReferenceWithoutRGBOrOfAnotherSize) {
    ExrSpec e;
    e.width = 4;
    e.height = 4;
    e.channels = {"Y", "A"};
    writeExr(path("grey.exr"), e, [](const std::string&, int, int) { return 0.5f; });
    e.channels = {"R", "G", "B"};
    e.width = 5;
    writeExr(path("rgb5.exr"), e, [](const std::string&, int, int) { return 0.5f; });
    e.width = 4;
    writeExr(path("rgb4.exr"), e, [](const std::string&, int, int) { return 0.5f; });
    Result r = mcstat(path("rgb4.exr") + " --diff " + path("grey.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --diff: " + path("grey.exr") +
                         ": no RGB channels (R, G, B or <layer>.R/G/B; channels: 'Y', 'A')\n");
    r = mcstat(path("rgb4.exr") + " --diff " + path("rgb5.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("image is 4x4 but the reference is 5x4"), std::string::npos) << r.err;
    r = mcstat(path("rgb4.exr") + " --diff " + path("rgb4.exr"));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("relMSE 0 "), std::string::npos) << r.out;
}

TEST_F(IngestCli, ErrorsAndWarningsAUserSees) {
    cyclesRender(1, "only.exr");
    // An image is not a statistics file: the message says how to make one.
    Result r = mcstat(path("only.exr") + " --gmon");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("is an image, not a statistics file (.mcstat); renders of one image "
                         "(one EXR per seed) become one with --ingest"),
              std::string::npos)
        << r.err;
    // One file: M = 1 works, with a warning.
    r = mcstat("--ingest " + path("only.exr") + " --gmon -o " + path("g.exr"));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("mcstat: warning: " + path("only.exr") + ": only one file, so M = 1"),
              std::string::npos)
        << r.err;
    r = mcstat("--ingest '" + path("nothing*.exr") + "' --gmon");
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --ingest: '" + path("nothing*.exr") + "' matches no file\n");
    r = mcstat("--ingest:spp=0 " + path("only.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: --ingest: spp must be an integer in [1, 16777216], not '0'\n");
    r = mcstat("--ingest:layer=ViewLayer.Diffuse " + path("only.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find(path("only.exr") + ": no channels 'ViewLayer.Diffuse.R'"),
              std::string::npos)
        << r.err;
    // :spp= overrides the metadata.
    r = mcstat("--ingest:spp=100 " + path("only.exr") + " --info");
    EXPECT_NE(r.out.find("spp = 100"), std::string::npos) << r.out;
}

TEST_F(IngestCli, ManyInputsNeverHoldManyFilesOpen) {
    // 100 renders under a limit of about 40 more open files: each input is open only while it
    // is read.
    for (int j = 0; j < 100; ++j) {
        ExrSpec e;
        e.width = 4;
        e.height = 3;
        e.channels = {"R", "G", "B"};
        e.stringAttrs["mcstat:spp"] = "2";
        writeExr(path(fmt("r{}.exr", j)), e,
                 [j](const std::string&, int x, int) { return 0.01f * float(j + x); });
    }
    // The limit bounds fd numbers, and the child inherits this process's open files (OIIO's
    // image cache keeps some open): allow 40 above the highest one.
    int highest = 2;
    for (const auto& e : std::filesystem::directory_iterator("/proc/self/fd"))
        highest = std::max(highest, std::atoi(e.path().filename().c_str()));
    const std::string cmd = "ulimit -n " + std::to_string(highest + 41) + " && " +
                            std::string(MCSTAT_EXE) + " --ingest '" + path("r*.exr") +
                            "' --info > " + path("out.txt") + " 2>&1";
    const int status = mcstat::testing::runCommand(("bash -c \"" + cmd + "\"").c_str());
    const std::string out = slurp(path("out.txt"));
    EXPECT_EQ(WEXITSTATUS(status), 0) << out;
    EXPECT_NE(out.find("M = 100 sub-buffers, spp = 200"), std::string::npos) << out;
}

TEST_F(IngestCli, MergeOfTwoIngestsOnTheCommandLine) {
    for (int s = 1; s <= 4; ++s) cyclesRender(s, fmt("r{}.exr", s));
    Result r = mcstat("--ingest " + path("r1.exr") + "," + path("r2.exr") + " -o " +
                      path("a.mcstat") + " --ingest " + path("r3.exr") + "," + path("r4.exr") +
                      " -o " + path("b.mcstat") + " --merge --info -o " + path("ab.mcstat"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("M = 2 sub-buffers, spp = 32, assignment perfile"), std::string::npos)
        << r.out;
    // Merging a file with itself would count its samples twice.
    r = mcstat(path("a.mcstat") + " " + path("a.mcstat") + " --merge");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("is given twice"), std::string::npos) << r.err;
    // A rendered (round-robin) file does not merge with an ingested one.
    const std::string cmd =
        std::string(MCSTAT_RENDER_EXE) +
        fmt(" --scene default --res {} {} --spp 8 --M 2 --seed 77 --quiet -o ", kW, kH) +
        path("rendered.mcstat");
    ASSERT_EQ(mcstat::testing::runCommand(cmd.c_str()), 0);
    r = mcstat(path("a.mcstat") + " " + path("rendered.mcstat") + " --merge");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("sample assignments differ ('perfile' vs 'roundrobin')"),
              std::string::npos)
        << r.err;
}

}  // namespace
}  // namespace mcstat::testing
