// Golden outputs of every operation in the registry, and the AOV guarantees of docs/aovs.md for
// each of them, on one fixture render at a fixed seed (the default scene: a caustic, glass,
// diffuse walls and a visible emitter; with --aovs and --keep-samples so that per-sample
// operations run too).
//
// - Golden: each operation's result (beauty and every AOV, by channel name) equals the EXR stored
//   in tests/golden/<operation>.exr. Tolerance: none. Every operation is deterministic for any
//   thread count (their own tests say so) and the suite runs on the machine the goldens were made
//   on, so any difference is a change of behaviour; a deliberate one regenerates the files with
//   MCSTAT_UPDATE_GOLDEN=1 build/tests/golden/test_golden (then review the diff with idiff).
// - The beauty is what it is without AOVs, bit for bit: the same operation on the same render
//   without --aovs gives the same R, G, B.
// - AOVs: every AOV channel of the file is in the result under its name, the spec's alpha is A,
//   and the light-path AOVs sum to the beauty within the float rounding of one weighted sum.
// A new registry operation fails here until it has a golden file.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>

#include <cmath>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "tool_test.h"

namespace mcstat {
namespace {

const char* const kLightPaths[] = {"emission",         "background",      "diffuse_direct",
                                   "diffuse_indirect", "specular_direct", "specular_indirect"};
const char* const kRender = "--scene default --res 24 18 --spp 64 --M 8 --seed 7 --keep-samples";

/// The mcstat arguments that apply `op` to a statistics file: image filters (MIF/WMIF) filter
/// an estimate, the median's (MPE+MIF, Jung eq. 5.15); everything else reads the file.
std::string commandOf(const Operation& op) {
    if (takesImage(op)) return "--median --" + op.name;
    return "--" + op.name;
}

/// Every channel of an EXR by name, as float.
struct Channels {
    int width = 0, height = 0, alpha = -1;
    std::vector<std::string> names;
    std::map<std::string, std::vector<float>> values;
};

bool readChannels(const std::string& path, Channels& out, std::string& err) {
    OIIO::ImageBuf buf(path);
    if (!buf.read(0, 0, true, OIIO::TypeDesc::FLOAT)) {
        err = path + ": " + buf.geterror();
        return false;
    }
    const OIIO::ImageSpec& s = buf.spec();
    out.width = s.width, out.height = s.height, out.alpha = s.alpha_channel;
    out.names = s.channelnames;
    std::vector<float> px(size_t(s.width) * size_t(s.height) * size_t(s.nchannels));
    buf.get_pixels(buf.roi(), OIIO::TypeDesc::FLOAT, px.data());
    for (int c = 0; c < s.nchannels; ++c) {
        std::vector<float>& v = out.values[s.channelnames[size_t(c)]];
        for (size_t p = 0; p < size_t(s.width) * size_t(s.height); ++p)
            v.push_back(px[p * size_t(s.nchannels) + size_t(c)]);
    }
    return true;
}

bool sameBits(float a, float b) { return a == b || (std::isnan(a) && std::isnan(b)); }

class Golden : public testing::ToolTest {
  protected:
    Golden() : ToolTest("golden") {}

    /// Renders the input twice: with and without AOVs.
    void renderInputs() {
        ASSERT_EQ(render(std::string(kRender) + " --aovs -o " + path("aovs.mcstat")).code, 0);
        ASSERT_EQ(render(std::string(kRender) + " -o " + path("plain.mcstat")).code, 0);
    }
    Channels apply(const Operation& op, const std::string& input, const std::string& out) {
        const testing::ToolRun r = mcstat(path(input) + " " + commandOf(op) + " -o " + path(out));
        EXPECT_EQ(r.code, 0) << commandOf(op) << ": " << r.err;
        Channels c;
        std::string err;
        EXPECT_TRUE(readChannels(path(out), c, err)) << err;
        return c;
    }
};

TEST_F(Golden, EveryOperationMatchesItsGoldenKeepsTheBeautyAndItsAovsSum) {
    renderInputs();
    if (HasFatalFailure()) return;
    const bool update = std::getenv("MCSTAT_UPDATE_GOLDEN") != nullptr;
    const std::string goldenDir = std::string(MCSTAT_SOURCE_DIR) + "/tests/golden/";
    for (const Operation& op : operationRegistry()) {
        SCOPED_TRACE(commandOf(op));
        const Channels a = apply(op, "aovs.mcstat", op.name + ".exr");
        const Channels b = apply(op, "plain.mcstat", op.name + "-plain.exr");
        ASSERT_FALSE(a.names.empty());

        // The golden file: the same channels, the same values.
        const std::string golden = goldenDir + op.name + ".exr";
        if (update) {
            OIIO::Filesystem::remove(golden);  // copy() does not overwrite
            ASSERT_TRUE(OIIO::Filesystem::copy(path(op.name + ".exr"), golden)) << golden;
        } else {
            Channels g;
            std::string err;
            ASSERT_TRUE(readChannels(golden, g, err))
                << err << " (a new operation needs its golden: MCSTAT_UPDATE_GOLDEN=1)";
            ASSERT_EQ(g.names, a.names);
            ASSERT_EQ(g.width, a.width);
            ASSERT_EQ(g.height, a.height);
            for (const std::string& n : a.names) {
                size_t differ = 0, first = 0;
                for (size_t p = 0; p < a.values.at(n).size(); ++p)
                    if (!sameBits(a.values.at(n)[p], g.values.at(n)[p]) && differ++ == 0) first = p;
                EXPECT_EQ(differ, 0u)
                    << "channel " << n << ": first at pixel " << first << ", "
                    << a.values.at(n)[first] << " vs golden " << g.values.at(n)[first];
            }
        }

        // The beauty does not depend on the AOVs being there.
        for (const char* c : {"R", "G", "B"}) {
            ASSERT_TRUE(b.values.count(c) && a.values.count(c)) << c;
            size_t differ = 0;
            for (size_t p = 0; p < a.values.at(c).size(); ++p)
                differ += !sameBits(a.values.at(c)[p], b.values.at(c)[p]);
            EXPECT_EQ(differ, 0u) << "beauty " << c << " changed by the AOVs";
        }
        for (const std::string& n : b.names) EXPECT_EQ(n.find("_direct"), std::string::npos);

        // Every AOV is there, alpha is the spec's alpha, and the light paths sum to the beauty.
        ASSERT_TRUE(a.values.count("A"));
        ASSERT_GE(a.alpha, 0);
        EXPECT_EQ(a.names[size_t(a.alpha)], "A");
        for (const char* l : kLightPaths)
            for (const char* c : {".R", ".G", ".B"})
                ASSERT_TRUE(a.values.count(std::string(l) + c)) << l << c;
        double worst = 0;
        for (const char* c : {"R", "G", "B"}) {
            const std::vector<float>& beauty = a.values.at(c);
            for (size_t p = 0; p < beauty.size(); ++p) {
                double sum = 0, scale = 0;
                for (const char* l : kLightPaths) {
                    const double v = a.values.at(std::string(l) + "." + c)[p];
                    sum += v;
                    scale += std::abs(v);
                }
                // Each AOV is one weighted sum rounded once to float (half an ulp, 6e-8
                // relative), the beauty another; their six-term sum adds its own rounding.
                const double off = std::abs(sum - double(beauty[p]));
                EXPECT_LE(off, 8 * 6e-8 * std::max(scale, double(std::abs(beauty[p]))) + 1e-30)
                    << c << " at pixel " << p << ": AOVs sum to " << sum << ", beauty "
                    << beauty[p];
                if (scale > 0) worst = std::max(worst, off / scale);
            }
        }
        const std::vector<float>& alpha = a.values.at("A");
        for (float v : alpha) EXPECT_TRUE(v >= 0.f && v <= 1.f) << v;
        RecordProperty(op.name + "_worst_relative_sum_error", std::to_string(worst));
    }
}

}  // namespace
}  // namespace mcstat
