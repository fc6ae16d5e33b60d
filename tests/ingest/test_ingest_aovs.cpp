// Production renders through ingest and every per-pixel estimator (docs/aovs.md): every channel
// of Arnold-, Karma- and RenderMan-style renders is kept, AOVs keep summing to the beauty after
// a robust estimate, alpha, ID mattes, overscan and the renderer's metadata survive, and the
// result written back is laid out as one input render was.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <ostream>
#include <random>
#include <set>

#include "mcstat/color/color.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/spec/render_layout.h"
#include "mcstat/ingest/ingest.h"

namespace mcstat {
namespace {

/// One part of a render: its name and channels.
struct Part {
    std::string name;
    std::vector<std::string> channels;
};

/// A renderer's style: how it names things and where it puts them.
struct Style {
    std::string label;
    std::vector<Part> parts;
    std::array<std::string, 3> beauty;  ///< the beauty's R, G, B
    std::string alpha;
    std::vector<std::array<std::string, 3>> groups;  ///< light groups: sum to the beauty
    std::vector<std::string> ids;                    ///< labels
};

/// GoogleTest prints a style by its name, not its bytes.
void PrintTo(const Style& s, std::ostream* os) { *os << s.label; }

Style arnold() {
    Style s;
    s.label = "arnold";
    s.parts = {
        {"",
         {"RGBA.R", "RGBA.G", "RGBA.B", "RGBA.A", "RGBA_key.R", "RGBA_key.G", "RGBA_key.B",
          "RGBA_fill.R", "RGBA_fill.G", "RGBA_fill.B", "RGBA_sky.R", "RGBA_sky.G", "RGBA_sky.B",
          "N.X", "N.Y", "N.Z", "Z", "crypto_object00.R", "crypto_object00.G"}}};
    s.beauty = {"RGBA.R", "RGBA.G", "RGBA.B"};
    s.alpha = "RGBA.A";
    s.groups = {{"RGBA_key.R", "RGBA_key.G", "RGBA_key.B"},
                {"RGBA_fill.R", "RGBA_fill.G", "RGBA_fill.B"},
                {"RGBA_sky.R", "RGBA_sky.G", "RGBA_sky.B"}};
    s.ids = {"crypto_object00.R", "crypto_object00.G"};
    return s;
}

/// Karma: one part per AOV; unqualified channel names in later parts are read as
/// "<part>.<channel>" (docs/ingest.md).
Style karma() {
    Style s;
    s.label = "karma";
    s.parts = {{"C", {"R", "G", "B", "A"}}, {"key", {"R", "G", "B"}}, {"fill", {"R", "G", "B"}},
               {"sky", {"R", "G", "B"}},    {"N", {"X", "Y", "Z"}},   {"objid", {"id"}}};
    s.beauty = {"R", "G", "B"};
    s.alpha = "A";
    s.groups = {
        {"key.R", "key.G", "key.B"}, {"fill.R", "fill.G", "fill.B"}, {"sky.R", "sky.G", "sky.B"}};
    s.ids = {"objid.id"};
    return s;
}

Style renderman() {
    Style s;
    s.label = "renderman";
    s.parts = {{"",
                {"Ci.R", "Ci.G", "Ci.B", "a", "directDiffuse.R", "directDiffuse.G",
                 "directDiffuse.B", "indirectDiffuse.R", "indirectDiffuse.G", "indirectDiffuse.B",
                 "emission.R", "emission.G", "emission.B", "Nn.X", "Nn.Y", "Nn.Z", "IndexOB.X"}}};
    s.beauty = {"Ci.R", "Ci.G", "Ci.B"};
    s.alpha = "a";
    s.groups = {{"directDiffuse.R", "directDiffuse.G", "directDiffuse.B"},
                {"indirectDiffuse.R", "indirectDiffuse.G", "indirectDiffuse.B"},
                {"emission.R", "emission.G", "emission.B"}};
    s.ids = {"IndexOB.X"};
    return s;
}

constexpr int kW = 16, kH = 12, kPad = 2, kSeeds = 12;

/// The name mcstat reads a channel of part `pi` by (later parts qualify unqualified names).
std::string readName(const Style& s, size_t pi, const std::string& ch) {
    if (pi == 0 || ch.find('.') != std::string::npos) return ch;
    return s.parts[pi].name + "." + ch;
}

/// The expected (noise-free) value of light group g, channel c at (x, y).
double groupTruth(int g, int c, int x, int y) {
    return (g == 0 ? 0.6 : g == 1 ? 0.25 : 0.05) * (1.0 + 0.1 * c) * (1.0 + 0.02 * (x + y));
}

class IngestAovs : public ::testing::TestWithParam<Style> {
  protected:
    std::string dir;
    /// Per seed, per pixel (data window), per channel read name: the values written.
    std::vector<std::map<std::string, std::vector<float>>> written;

    void SetUp() override {
        dir = std::string(MCSTAT_BINARY_DIR) + "/tests/ingest/tmp-aovs-" + GetParam().label;
        OIIO::Filesystem::remove_all(dir);
        OIIO::Filesystem::create_directory(dir);
    }
    void TearDown() override {
        if (!HasFailure()) OIIO::Filesystem::remove_all(dir);
    }

    /// Seed j of the style: light groups with noise and key-light fireflies, the beauty their
    /// sum, alpha 1 inside a disc and 0.5 outside, normals, depth, labels; overscan of kPad
    /// pixels on every side; camera matrix, frame and a vendor attribute.
    std::string writeSeed(const Style& s, int j) {
        std::mt19937 rng(1000u + unsigned(j));
        std::uniform_real_distribution<float> u(0.f, 1.f);
        const int W = kW + 2 * kPad, H = kH + 2 * kPad;
        std::map<std::string, std::vector<float>> v;
        for (size_t pi = 0; pi < s.parts.size(); ++pi)
            for (const std::string& ch : s.parts[pi].channels)
                v[readName(s, pi, ch)].assign(size_t(W) * H, 0.f);
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
                const size_t p = size_t(y) * W + x;
                const bool firefly = u(rng) < 0.04f;
                for (int c = 0; c < 3; ++c) {
                    float sum = 0.f;
                    for (int g = 0; g < 3; ++g) {
                        float val = float(groupTruth(g, c, x, y)) * (0.5f + u(rng));
                        if (g == 0 && firefly) val *= 400.f;
                        v[s.groups[size_t(g)][size_t(c)]][p] = val;
                        sum += val;
                    }
                    v[s.beauty[size_t(c)]][p] = sum;
                }
                const int dx = x - W / 2, dy = y - H / 2;
                v[s.alpha][p] = dx * dx + dy * dy < 25 ? 1.f : 0.5f;
                for (const auto& [name, vals] : v) {
                    if (name.find(".X") != std::string::npos &&
                        name.find("Index") == std::string::npos)
                        v[name][p] = 0.6f + 0.01f * float(j);
                    if (name == "Z") v[name][p] = 4.f + u(rng);
                }
                for (size_t i = 0; i < s.ids.size(); ++i)
                    v[s.ids[i]][p] = float(1 + (x / 4 + j) % 3) + (i ? 0.25f : 0.f);
            }
        written.push_back(v);
        std::vector<OIIO::ImageSpec> specs;
        for (size_t pi = 0; pi < s.parts.size(); ++pi) {
            OIIO::ImageSpec spec(W, H, int(s.parts[pi].channels.size()), OIIO::TypeDesc::FLOAT);
            spec.x = -kPad;
            spec.y = -kPad;
            spec.full_x = 0;
            spec.full_y = 0;
            spec.full_width = kW;
            spec.full_height = kH;
            spec.channelnames = s.parts[pi].channels;
            spec.alpha_channel = -1;
            spec.z_channel = -1;
            if (s.parts.size() > 1) spec.attribute("oiio:subimagename", s.parts[pi].name);
            spec.attribute("mcstat:spp", 16);
            const float cam[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 2.5f, -1, 7, 1};
            spec.attribute("worldToCamera", OIIO::TypeMatrix44, cam);
            spec.attribute("frame", 1042);
            spec.attribute("vendor:shot", "sq010_sh020");
            specs.push_back(spec);
        }
        const std::string path = dir + "/seed_" + std::to_string(j) + ".exr";
        auto out = OIIO::ImageOutput::create(path);
        EXPECT_TRUE(out && out->open(path, int(specs.size()), specs.data())) << OIIO::geterror();
        for (size_t pi = 0; pi < s.parts.size(); ++pi) {
            if (pi > 0) {
                EXPECT_TRUE(out->open(path, specs[pi], OIIO::ImageOutput::AppendSubimage));
            }
            const auto& chans = s.parts[pi].channels;
            std::vector<float> px(size_t(W) * H * chans.size());
            for (size_t p = 0; p < size_t(W) * H; ++p)
                for (size_t c = 0; c < chans.size(); ++c)
                    px[p * chans.size() + c] = v[readName(s, pi, chans[c])][p];
            EXPECT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, px.data())) << out->geterror();
        }
        EXPECT_TRUE(out->close());
        return path;
    }
};

TEST_P(IngestAovs, EveryChannelKeptAndStillSummingAfterEveryOperation) {
    const Style& s = GetParam();
    std::vector<std::string> paths;
    for (int j = 0; j < kSeeds; ++j) paths.push_back(writeSeed(s, j));
    StatsImage img;
    IngestReport report;
    std::string err;
    ASSERT_TRUE(ingestRenders(paths, IngestOptions(), img, report, err)) << err;
    const StatsHeader& h = img.header;
    // Every channel but the beauty's R, G, B is an AOV, with its class.
    size_t total = 0;
    for (const Part& p : s.parts) total += p.channels.size();
    ASSERT_EQ(h.aovs.size(), total - 3);
    EXPECT_EQ(h.beautyNames, s.beauty);
    ASSERT_GE(h.aovIndex(s.alpha), 0);
    EXPECT_EQ(h.aovs[size_t(h.aovIndex(s.alpha))].cls, AovClass::Alpha);
    for (const std::string& id : s.ids) {
        ASSERT_GE(h.aovIndex(id), 0) << id;
        EXPECT_EQ(h.aovs[size_t(h.aovIndex(id))].cls, AovClass::Id) << id;
    }
    for (const auto& g : s.groups) EXPECT_EQ(h.aovs[size_t(h.aovIndex(g[0]))].cls, AovClass::Light);
    EXPECT_EQ(h.displayWidth, kW);
    EXPECT_EQ(h.displayX, 0);
    EXPECT_EQ(h.originX, -kPad);
    EXPECT_NE(h.sourceMetadata.find("worldToCamera"), std::string::npos);
    EXPECT_GE(h.formatVersion, kStatsFormatVersionAovs) << h.sourceMetadata;

    const std::array<double, 3> luma = lumaCoefficients();
    const size_t npix = img.pixelCount();
    // The inputs' own residual per pixel and channel: how far each render's groups are from its
    // beauty (float rounding of the sum), the band a robust result must stay in.
    std::vector<double> band(npix * 3, 0.0);
    for (int j = 0; j < kSeeds; ++j)
        for (size_t p = 0; p < npix; ++p)
            for (int c = 0; c < 3; ++c) {
                double sum = 0.0;
                for (const auto& g : s.groups) sum += written[size_t(j)].at(g[size_t(c)])[p];
                const double r =
                    std::abs(double(written[size_t(j)].at(s.beauty[size_t(c)])[p]) - sum);
                band[p * 3 + size_t(c)] = std::max(band[p * 3 + size_t(c)], r);
            }
    // A window filter mixes the buffers of pixels up to its radius away (3 covers every default
    // window), so its band is the largest of theirs and its labels come from one of them.
    const int W = kW + 2 * kPad, H = kH + 2 * kPad, R = 3;
    std::vector<double> windowBand(npix * 3, 0.0);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
            for (int yy = std::max(0, y - R); yy <= std::min(H - 1, y + R); ++yy)
                for (int xx = std::max(0, x - R); xx <= std::min(W - 1, x + R); ++xx)
                    for (size_t c = 0; c < 3; ++c) {
                        double& b = windowBand[(size_t(y) * size_t(W) + size_t(x)) * 3 + c];
                        b = std::max(b, band[(size_t(yy) * size_t(W) + size_t(xx)) * 3 + c]);
                    }
    for (const Operation& op : operationRegistry()) {
        // Every operation but the per-sample ones (an ingest of flat renders has no samples).
        if (op.input == InputKind::Samples) continue;
        const bool window = op.input == InputKind::Neighbourhood;
        ParamValues values;
        ASSERT_TRUE(parseOperationParams(op, {}, values, err)) << err;
        OIIO::ImageBuf out;
        ASSERT_TRUE(applyOperation(out, img, op, values, luma)) << op.name << out.geterror();
        const OIIO::ImageSpec& spec = out.spec();
        ASSERT_EQ(size_t(spec.nchannels), 3 + h.aovs.size()) << op.name;
        EXPECT_EQ(spec.channelnames[size_t(spec.alpha_channel)], s.alpha) << op.name;
        EXPECT_EQ(spec.full_width, kW);
        EXPECT_EQ(spec.x, -kPad);
        const float* px = static_cast<const float*>(out.localpixels());
        const size_t nch = size_t(spec.nchannels);
        int outside = 0;
        for (size_t p = 0; p < npix; ++p)
            for (int c = 0; c < 3; ++c) {
                double sum = 0.0;
                for (const auto& g : s.groups)
                    sum += px[p * nch + size_t(spec.channelindex(g[size_t(c)]))];
                const double robust = px[p * nch + size_t(c)];
                // The inputs' band plus float rounding of a weighted sum of M values.
                const double b = (window ? windowBand : band)[p * 3 + size_t(c)];
                if (std::abs(robust - sum) > b + 4e-6 * std::abs(robust)) ++outside;
            }
        EXPECT_EQ(outside, 0) << op.name << ": pixels whose groups left the inputs' band";
        // Labels are one of the inputs' labels at that pixel (a window filter's: at one of its
        // window's pixels), never an average.
        for (const std::string& id : s.ids) {
            const int ch = spec.channelindex(id);
            for (int y = 0; y < H; ++y)
                for (int x = 0; x < W; ++x) {
                    const size_t p = size_t(y) * size_t(W) + size_t(x);
                    const int r = window ? R : 0;
                    bool found = false;
                    for (int yy = std::max(0, y - r); yy <= std::min(H - 1, y + r); ++yy)
                        for (int xx = std::max(0, x - r); xx <= std::min(W - 1, x + r); ++xx)
                            for (int j = 0; j < kSeeds; ++j)
                                found |= written[size_t(j)].at(
                                             id)[size_t(yy) * size_t(W) + size_t(xx)] ==
                                         px[p * nch + size_t(ch)];
                    ASSERT_TRUE(found) << op.name << " " << id << " pixel " << p;
                }
        }
    }

    // G-MoN removes the key light's fireflies from the key AOV as from the beauty.
    ParamValues gv;
    ASSERT_TRUE(parseOperationParams(*findOperation("gmon"), {}, gv, err));
    OIIO::ImageBuf gmon, mean;
    ASSERT_TRUE(applyOperation(gmon, img, *findOperation("gmon"), gv, luma));
    ParamValues mv;
    ASSERT_TRUE(parseOperationParams(*findOperation("mean"), {}, mv, err));
    ASSERT_TRUE(applyOperation(mean, img, *findOperation("mean"), mv, luma));
    const auto keyError = [&](const OIIO::ImageBuf& b) {
        const int ch = b.spec().channelindex(s.groups[0][0]);
        double e = 0.0;
        for (int y = 0; y < kH + 2 * kPad; ++y)
            for (int x = 0; x < kW + 2 * kPad; ++x) {
                const double t = groupTruth(0, 0, x, y);
                const double d = b.getchannel(x - kPad, y - kPad, 0, ch) - t;
                e += d * d / (t * t);
            }
        return e;
    };
    EXPECT_LT(keyError(gmon) * 20, keyError(mean));

    // The residual: robust + residual = mean for the beauty and every AOV but the labels.
    OIIO::ImageBuf withResidual = gmon;
    ASSERT_TRUE(appendResidual(withResidual, img, luma)) << withResidual.geterror();
    const OIIO::ImageSpec& rs = withResidual.spec();
    EXPECT_EQ(size_t(rs.nchannels), 2 * (3 + h.aovs.size()) - s.ids.size());
    for (const std::string& id : s.ids) EXPECT_LT(rs.channelindex("residual." + id), 0);
    for (int c = 0; c < gmon.nchannels(); ++c) {
        const std::string n = gmon.spec().channelnames[size_t(c)];
        const int rc = rs.channelindex("residual." + n);
        if (std::find(s.ids.begin(), s.ids.end(), n) != s.ids.end()) continue;
        ASSERT_GE(rc, 0) << n;
        const int mc = mean.spec().channelindex(n);
        for (int y = -kPad; y < kH + kPad; ++y)
            for (int x = -kPad; x < kW + kPad; ++x) {
                const float m = mean.getchannel(x, y, 0, mc);
                const float sum =
                    withResidual.getchannel(x, y, 0, c) + withResidual.getchannel(x, y, 0, rc);
                ASSERT_NEAR(sum, m, 2e-7f * std::abs(m) + 1e-30f) << n << " " << x << "," << y;
            }
    }

    // Written back, the result is laid out as an input render: names, parts, windows, metadata,
    // provenance.
    OIIO::ImageBuf withMeta = gmon;
    describeResult(withMeta.specmod(), *findOperation("gmon"), gv, h);
    const std::string outPath = dir + "/gmon.exr";
    ASSERT_TRUE(writeRenderLike(withMeta, h, outPath, ImageWriteOptions(), err)) << err;
    auto in = OIIO::ImageInput::open(outPath);
    ASSERT_TRUE(in);
    int nparts = 0;
    for (; in->seek_subimage(nparts, 0); ++nparts) {
        const OIIO::ImageSpec& os = in->spec();
        ASSERT_LT(size_t(nparts), s.parts.size());
        std::set<std::string> want, got(os.channelnames.begin(), os.channelnames.end());
        for (const std::string& ch : s.parts[size_t(nparts)].channels)
            want.insert(nparts == 0 ? ch : readName(s, size_t(nparts), ch));
        EXPECT_EQ(got, want) << "part " << nparts;
        if (s.parts.size() > 1) {
            EXPECT_EQ(os.get_string_attribute("oiio:subimagename"), s.parts[size_t(nparts)].name);
        }
        EXPECT_EQ(os.full_width, kW);
        EXPECT_EQ(os.full_height, kH);
        EXPECT_EQ(os.x, -kPad);
        EXPECT_EQ(os.width, kW + 2 * kPad);
        EXPECT_EQ(os.get_int_attribute("frame"), 1042);
        EXPECT_EQ(os.get_string_attribute("vendor:shot"), "sq010_sh020");
        EXPECT_EQ(os.get_string_attribute("mcstat.operation"), "gmon");
        EXPECT_EQ(os.get_int_attribute("mcstat.M"), kSeeds);
        const OIIO::ParamValue* cam = os.find_attribute("worldToCamera");
        ASSERT_TRUE(cam != nullptr);
        ASSERT_EQ(cam->type(), OIIO::TypeMatrix44);
        EXPECT_FLOAT_EQ(static_cast<const float*>(cam->data())[12], 2.5f);
    }
    EXPECT_EQ(size_t(nparts), s.parts.size());
}

TEST_P(IngestAovs, ChannelModeIsRefusedWithAovs) {
    const Style& s = GetParam();
    std::vector<std::string> paths;
    for (int j = 0; j < 4; ++j) paths.push_back(writeSeed(s, j));
    StatsImage img;
    IngestReport report;
    std::string err;
    ASSERT_TRUE(ingestRenders(paths, IngestOptions(), img, report, err)) << err;
    ParamValues values;
    ASSERT_TRUE(parseOperationParams(*findOperation("gmon"), {{"mode", "channel"}}, values, err));
    OIIO::ImageBuf out;
    EXPECT_FALSE(applyOperation(out, img, *findOperation("gmon"), values, lumaCoefficients()));
    EXPECT_NE(out.geterror().find("mode=channel"), std::string::npos) << out.geterror();
    // Leaving the AOVs out is a choice the user makes, and then channel mode works.
    IngestOptions noAovs;
    noAovs.aovs = false;
    ASSERT_TRUE(ingestRenders(paths, noAovs, img, report, err)) << err;
    EXPECT_TRUE(img.header.aovs.empty());
    EXPECT_FALSE(report.warnings.empty());
    OIIO::ImageBuf ok;
    EXPECT_TRUE(applyOperation(ok, img, *findOperation("gmon"), values, lumaCoefficients()))
        << ok.geterror();
}

INSTANTIATE_TEST_SUITE_P(Renderers, IngestAovs, ::testing::Values(arnold(), karma(), renderman()),
                         [](const auto& param) { return param.param.label; });

}  // namespace
}  // namespace mcstat
