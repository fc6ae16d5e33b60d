// Pajot and the per-sample records end to end: mcstat-render --pajot/--keep-samples writes format
// version 4; the records read back by blocks of rows; `mcstat --pajot` recomputes the online result
// bit for bit; a resumed render equals the straight one; 1 and N threads give the same bytes; the
// refusals are one-line errors.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "mcstat/core/params.h"
#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/filters/samples/sample_delaying.h"
#include "mcstat/filters/samples/sample_delaying_state.h"
#include "pajot_reference.h"
#include "tool_test.h"

namespace mcstat {
namespace {

using testing::slurp;
using testing::ToolRun;

class PajotFile : public testing::ToolTest {
  protected:
    PajotFile() : ToolTest("filters/samples") {}
};

/// Pixels of an EXR written by mcstat, all channels.
std::vector<float> pixelsOf(const std::string& file, int& nch) {
    OIIO::ImageBuf b(file);
    EXPECT_TRUE(b.read(0, 0, true, OIIO::TypeDesc::FLOAT)) << b.geterror();
    nch = b.nchannels();
    std::vector<float> v(size_t(b.spec().image_pixels()) * size_t(nch));
    b.get_pixels(b.roi(), OIIO::TypeDesc::FLOAT, v.data());
    return v;
}

TEST_F(PajotFile, RecordsHoldEverySampleInOrderAndReadBackByBlocks) {
    const std::string f = path("r.mcstat");
    ASSERT_EQ(render("--scene tiny --spp 9 --M 3 --keep-samples -o " + f).code, 0);
    StatsImage img;
    std::string err;
    ASSERT_TRUE(readStatsFile(f, img, err)) << err;
    EXPECT_EQ(img.header.formatVersion, 4);
    EXPECT_TRUE(img.header.hasRecords);
    EXPECT_FALSE(img.header.hasState());
    SampleRecordsReader rd;
    ASSERT_TRUE(rd.open(f, err)) << err;
    SampleBlock block;
    int worst = 0;
    for (int y0 = 0; y0 < img.header.height; y0 += 5) {  // blocks of 5 rows, the last one short
        const int rows = std::min(5, img.header.height - y0);
        ASSERT_TRUE(rd.read(y0, rows, block, err)) << err;
        ASSERT_EQ(block.counts.size(), size_t(rows * img.header.width));
        size_t k = 0;
        for (size_t i = 0; i < block.counts.size(); ++i) {
            ASSERT_EQ(block.counts[i], 9u);
            const size_t p = size_t(y0) * size_t(img.header.width) + i;
            // Sample j of the pixel went to buffer j mod 3: each buffer's mean from the records.
            for (int b = 0; b < 3; ++b) {
                double sum = 0;
                for (int j = b; j < 9; j += 3)
                    sum += block.samples[(k + size_t(j)) * block.stride() + 0];
                const double want = img.bufferMean[(p * 3 + size_t(b)) * 3 + 0];
                const double got = sum / 3;
                if (std::fabs(got - want) > 1e-6 * (1 + std::fabs(want))) ++worst;
            }
            k += 9;
        }
    }
    EXPECT_EQ(worst, 0) << "buffer means differ from the records' samples";
    EXPECT_FALSE(rd.read(10, 10, block, err));  // past the last row
}

class OnlineOffline : public PajotFile, public ::testing::WithParamInterface<const char*> {};

TEST_P(OnlineOffline, TheOfflineEstimateEqualsTheOnlineOneBitForBit) {
    const std::string f = path("o.mcstat"), off = path("off.exr");
    ASSERT_EQ(render(std::string("--res 40 30 --spp 120 --pajot ") + GetParam() +
                     " --pajot-n 20 --keep-samples -o " + f)
                  .code,
              0);
    PajotImage online;
    std::string err;
    ASSERT_TRUE(readPajotParts(f, online, err)) << err;
    EXPECT_EQ(online.params.learning, 20);
    // method=stored (the default) takes the render's parameters; the explicit ones give the same.
    for (const std::string& args :
         {std::string("--pajot"), std::string("--pajot:method=") + GetParam() + ":n=20"}) {
        const ToolRun r = mcstat(f + " " + args + " -o " + off);
        ASSERT_EQ(r.code, 0) << r.err;
        int nch = 0;
        const std::vector<float> px = pixelsOf(off, nch);
        ASSERT_EQ(nch, 4);  // R, G, B, delayed
        int differ = 0, delayedSeen = 0;
        for (size_t p = 0; p < online.pixels.size(); ++p) {
            for (size_t c = 0; c < 3; ++c)
                if (std::memcmp(&px[p * 4 + c], &online.estimate[p * 3 + c], sizeof(float)) != 0)
                    ++differ;
            if (px[p * 4 + 3] != float(online.pixels[p].delayed.size())) ++differ;
            delayedSeen += int(px[p * 4 + 3]);
        }
        EXPECT_EQ(differ, 0) << args;
        EXPECT_GT(delayedSeen, 0) << "the default scene's caustic must delay some samples";
    }
    // Other parameters recompute from the records (and differ somewhere).
    ASSERT_EQ(mcstat(f + " --pajot:method=rot:n=5 -o " + off).code, 0);
}

INSTANTIATE_TEST_SUITE_P(Methods, OnlineOffline, ::testing::Values("adr", "rot", "hybrid"));

TEST_F(PajotFile, AResumedRenderEqualsTheStraightOneBitForBit) {
    const std::string half = path("half.mcstat"), resumed = path("resumed.mcstat"),
                      straight = path("straight.mcstat");
    ASSERT_EQ(render("--res 32 24 --spp 70 --pajot hybrid --pajot-n 30 -o " + half).code, 0);
    const ToolRun r = render("--res 32 24 --spp 150 --resume " + half + " -o " + resumed);
    ASSERT_EQ(r.code, 0) << r.err;
    ASSERT_EQ(render("--res 32 24 --spp 150 --pajot hybrid --pajot-n 30 -o " + straight).code, 0);
    PajotImage a, b;
    std::string err;
    ASSERT_TRUE(readPajotParts(resumed, a, err)) << err;
    ASSERT_TRUE(readPajotParts(straight, b, err)) << err;
    ASSERT_EQ(a.estimate.size(), b.estimate.size());
    EXPECT_EQ(std::memcmp(a.estimate.data(), b.estimate.data(), a.estimate.size() * 4), 0);
    int stateDiffers = 0;
    for (size_t p = 0; p < a.pixels.size(); ++p) {
        const PajotState &x = a.pixels[p], &y = b.pixels[p];
        if (x.sum != y.sum || x.splatted != y.splatted || x.taken != y.taken ||
            x.delayed.size() != y.delayed.size() || x.modes.size() != y.modes.size() ||
            x.rotSingles != y.rotSingles || x.phase != y.phase || x.rotM2 != y.rotM2)
            ++stateDiffers;
    }
    EXPECT_EQ(stateDiffers, 0);
    // The statistics merged: every pixel holds 150 samples, sub-buffers as one render's within
    // float rounding.
    StatsImage s, t;
    ASSERT_TRUE(readStatsFile(resumed, s, err)) << err;
    ASSERT_TRUE(readStatsFile(straight, t, err)) << err;
    EXPECT_EQ(s.header.spp, 150);
    EXPECT_EQ(s.count, t.count);
    double worst = 0;
    for (size_t i = 0; i < s.bufferMean.size(); ++i)
        worst = std::max(worst, std::fabs(double(s.bufferMean[i]) - t.bufferMean[i]) /
                                    (1.0 + std::fabs(double(t.bufferMean[i]))));
    EXPECT_LT(worst, 1e-6);
}

/// Renders with --pajot METHOD and --keep-samples, replays every pixel's records through the plain
/// re-implementation of pajot_reference.h and compares the state the renderer wrote (parts pajot
/// and modes) with the replay's, bit for bit: the online estimator's speed-ups change nothing a
/// real render stores.
class OnlineReference : public PajotFile, public ::testing::WithParamInterface<const char*> {};

TEST_P(OnlineReference, TheStoredStateIsThePlainImplementationsBitForBit) {
    for (const char* scene : {"caustic", "default"}) {
        const std::string f = path(std::string(scene) + ".mcstat");
        ASSERT_EQ(render(std::string("--scene ") + scene + " --res 32 24 --spp 250 --M 2 --pajot " +
                         GetParam() + " --keep-samples --threads 2 -o " + f)
                      .code,
                  0);
        PajotImage online;
        std::string err;
        ASSERT_TRUE(readPajotParts(f, online, err)) << err;
        SampleRecordsReader rd;
        ASSERT_TRUE(rd.open(f, err)) << err;
        SampleBlock block;
        const int width = rd.header().width, height = rd.header().height;
        ASSERT_TRUE(rd.read(0, height, block, err)) << err;
        const int r = block.channel("R"), g = block.channel("G"), b = block.channel("B");
        ASSERT_GE(std::min({r, g, b}), 0);
        size_t k = 0;
        int differ = 0, records = 0;
        for (size_t p = 0; p < size_t(width) * size_t(height); ++p) {
            pajot_ref::Pixel ref;
            for (uint32_t i = 0; i < block.counts[p]; ++i, ++k) {
                const float* smp = &block.samples[k * block.stride()];
                const float rgb[3] = {smp[r], smp[g], smp[b]};
                ref.add(rgb, online.params);
            }
            const std::string d = pajot_ref::firstDifference(online.pixels[p], ref.s);
            if (!d.empty() && differ++ < 5)
                ADD_FAILURE() << scene << ", pixel " << p << ": " << d << " differs";
            const PajotState& st = online.pixels[p];
            records += int(st.modes.size() + st.rotSingles.size() + st.delayed.size());
        }
        EXPECT_EQ(differ, 0) << scene;
        EXPECT_GT(records, width * height / 4) << scene;  // modes and delayed samples to compare
    }
}

INSTANTIATE_TEST_SUITE_P(Methods, OnlineReference, ::testing::Values("adr", "rot", "hybrid"));

TEST_F(PajotFile, OneAndTwoThreadsWriteTheSameBytes) {
    const std::string a = path("t1.mcstat"), b = path("t2.mcstat");
    const std::string args = "--res 30 20 --spp 80 --pajot adr --pajot-n 25 --keep-samples ";
    ASSERT_EQ(render(args + "--threads 1 -o " + a).code, 0);
    ASSERT_EQ(render(args + "--threads 2 -o " + b).code, 0);
    EXPECT_EQ(slurp(a), slurp(b));
    const std::string c = path("t3.exr"), d = path("t4.exr");
    ASSERT_EQ(mcstat(a + " --pajot:method=rot --threads 1 -o " + c).code, 0);
    ASSERT_EQ(mcstat(a + " --pajot:method=rot --threads 2 -o " + d).code, 0);
    int n1 = 0, n2 = 0;
    EXPECT_EQ(pixelsOf(c, n1), pixelsOf(d, n2));
}

TEST_F(PajotFile, MergingOrRewritingDropsThePerSamplePartsWithAWarning) {
    const std::string a = path("a.mcstat"), b = path("b.mcstat"), ab = path("ab.mcstat");
    ASSERT_EQ(
        render("--scene tiny --spp 8 --pajot rot --pajot-n 4 --keep-samples --seed 1 -o " + a).code,
        0);
    ASSERT_EQ(render("--scene tiny --spp 8 --pajot rot --pajot-n 4 --seed 2 -o " + b).code, 0);
    const ToolRun r = mcstat(a + " " + b + " --merge -o " + ab);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("parts pajot, modes and records of merge("), std::string::npos) << r.err;
    StatsHeader h;
    std::string err;
    ASSERT_TRUE(readStatsHeader(ab, h, err)) << err;
    EXPECT_FALSE(h.hasState());
    EXPECT_FALSE(h.hasRecords);
    EXPECT_EQ(h.formatVersion, 1);  // the lowest version that holds what remains
    EXPECT_EQ(h.spp, 16);
}

TEST_F(PajotFile, RefusalsAreOneLineErrorsBeforeAnyWork) {
    // The records limit is checked before rendering: 160 x 120 x 1000 spp x 20 bytes = 384 MB.
    ToolRun r =
        render("--spp 1000 --keep-samples --max-sample-bytes 100000000 -o " + path("x.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("exceed --max-sample-bytes 100000000"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1);
    EXPECT_FALSE(OIIO::Filesystem::exists(path("x.mcstat")));
    // A file with neither part.
    ASSERT_EQ(render("--scene tiny --spp 4 -o " + path("plain.mcstat")).code, 0);
    r = mcstat(path("plain.mcstat") + " --pajot -o " + path("o.exr"));
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find("neither per-sample records nor Pajot's online state"), std::string::npos)
        << r.err;
    // It names the renderer's flags as they are (--online NAME:key=value), not deprecated ones.
    EXPECT_NE(r.err.find("--online pajot:method=hybrid"), std::string::npos) << r.err;
    // Stored result only: other parameters need the records.
    ASSERT_EQ(render("--scene tiny --spp 8 --pajot rot --pajot-n 4 -o " + path("s.mcstat")).code,
              0);
    r = mcstat(path("s.mcstat") + " --pajot:method=adr -o " + path("o.exr"));
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find("needs per-sample records"), std::string::npos) << r.err;
    EXPECT_EQ(mcstat(path("s.mcstat") + " --pajot -o " + path("o.exr")).code, 0);
    // Bad values.
    r = mcstat(path("s.mcstat") + " --pajot:n=0 -o " + path("o.exr"));
    EXPECT_NE(r.err.find("n must be"), std::string::npos) << r.err;
    r = render("--scene tiny --pajot fast -o " + path("y.mcstat"));
    EXPECT_NE(r.err.find("--pajot: method must be 'stored', 'adr', 'rot' or 'hybrid', not 'fast'"),
              std::string::npos)
        << r.err;
    // Resume: a file without Pajot's state cannot continue it; --spp is the total.
    r = render("--scene tiny --spp 8 --pajot hybrid --resume " + path("plain.mcstat") + " -o " +
               path("z.mcstat"));
    EXPECT_NE(r.err.find("has no Pajot state to continue"), std::string::npos) << r.err;
    r = render("--scene tiny --spp 8 --resume " + path("s.mcstat") + " -o " + path("z.mcstat"));
    EXPECT_NE(r.err.find("already has 8 samples per pixel"), std::string::npos) << r.err;
}

// The parameter text the state parts carry is the registry's one grammar: written by
// pajotParamText, read back through parseParamText and parseOperationParams, every double exact.
TEST(StateParams, KeyValueTextRoundTripsThroughTheRegistry) {
    PajotParams p;
    p.method = PajotMethod::ROT;
    p.learning = 17;
    p.maxDelayed = 3;
    p.T = 5;
    p.delta = 0.1 + 0.2;  // not a short decimal: the shortest exact text is longer
    p.luma = {0.3439664, 0.7281661, -0.0721325};  // ACES2065-1: a negative weight
    const std::string text = pajotParamText(p);
    EXPECT_NE(text.find("luma=0.3439664,0.7281661,-0.0721325:method=rot"), std::string::npos)
        << text;  // lists by ',', items by ':'
    std::map<std::string, std::string> kv;
    std::string err;
    ASSERT_TRUE(parseParamText(text, kv, err)) << err;
    EXPECT_EQ(paramText(kv), text);
    ParamValues values;
    ASSERT_TRUE(parseOperationParams(*findOperation("pajot"), kv, values, err)) << err;
    PajotParams back;
    ASSERT_TRUE(pajotParamsFromText(text, back, err)) << err;
    EXPECT_EQ(back.method, p.method);
    EXPECT_EQ(back.learning, p.learning);
    EXPECT_EQ(back.maxDelayed, p.maxDelayed);
    EXPECT_EQ(back.T, p.T);
    EXPECT_EQ(std::memcmp(&back.delta, &p.delta, sizeof p.delta), 0);
    EXPECT_EQ(std::memcmp(back.luma.data(), p.luma.data(), sizeof p.luma), 0);
    // One grammar, one parser: bad text is refused with the registry's own messages.
    EXPECT_FALSE(pajotParamsFromText("method=adr:n=0:delayed=1:t=1:delta=0:luma=1,0,0", back, err));
    EXPECT_NE(err.find("n must be"), std::string::npos) << err;
    EXPECT_FALSE(pajotParamsFromText("method=adr:n=5:delayed=1:t=1:delta=0", back, err));
    EXPECT_NE(err.find("no luma"), std::string::npos) << err;
    EXPECT_FALSE(pajotParamsFromText("method=adr:n=5:n=6", back, err));
    EXPECT_NE(err.find("given twice"), std::string::npos) << err;
}

// Files written before the owner was recorded (attribute mcstat:pajot, ',' between items) read
// as state parts owned by "pajot", their parameters in the one grammar, and decode.
TEST(StateParams, FilesWrittenBeforeTheOwnerAttributeStillRead) {
    const std::string file =
        std::string(MCSTAT_SOURCE_DIR) + "/tests/fuzz/corpus/records/pajot.mcstat";
    StatsHeader h;
    std::string err;
    ASSERT_TRUE(readStatsHeader(file, h, err)) << err;
    EXPECT_EQ(h.state.operation, "pajot");
    EXPECT_EQ(h.state.flatPart, "pajot");
    EXPECT_EQ(h.state.deepPart, "modes");
    EXPECT_NE(h.state.params.find("method="), std::string::npos) << h.state.params;
    EXPECT_EQ(h.state.params.find(",n="), std::string::npos) << h.state.params;
    PajotImage pj;
    ASSERT_TRUE(readPajotParts(file, pj, err)) << err;
    EXPECT_EQ(pj.pixels.size(), size_t(h.width) * size_t(h.height));
}

// A file written by a newer mcstat whose state parts belong to an operation this one does not
// know: the file reads, --info and --check name the owner and say it is unknown, the operations
// over the sub-buffers work, and the one that needs its own state says the file has none.
TEST_F(PajotFile, StatePartsOfAnUnknownOwnerAreKeptUnread) {
    ASSERT_EQ(render("--scene tiny --spp 8 -o " + path("plain.mcstat")).code, 0);
    StatsImage img;
    std::string err;
    ASSERT_TRUE(readStatsFile(path("plain.mcstat"), img, err)) << err;
    PixelStateParts state;
    state.owner = {"futureop", "level=3:weights=1,2", "future", "futurerecs"};
    state.floatChannels = {"x"};
    state.floats.assign(img.pixelCount(), 1.5f);
    state.recordChannels = {"A", "Z", "v"};
    state.recordCounts.assign(img.pixelCount(), 1);
    for (size_t p = 0; p < img.pixelCount(); ++p)
        state.records.insert(state.records.end(), {1.f, float(p), 2.f});
    img.header.state = state.owner;
    img.header.formatVersion =
        std::max(img.header.formatVersion, requiredFormatVersion(img.header));
    StatsExtras extras;
    extras.state = &state;
    const std::string f = path("future.mcstat");
    ASSERT_TRUE(writeStatsFile(f, img, extras, err)) << err;
    StatsHeader h;
    ASSERT_TRUE(readStatsHeader(f, h, err)) << err;
    EXPECT_EQ(h.state, state.owner);
    ToolRun r = mcstat(f + " --info");
    ASSERT_EQ(r.code, 0) << r.err;
    std::string text = r.out;
    EXPECT_NE(text.find("future, futurerecs (state parts of 'futureop', an operation this mcstat "
                        "does not know"),
              std::string::npos)
        << text;
    r = mcstat(f + " --check");
    ASSERT_EQ(r.code, 0) << r.err;
    text = r.out;
    EXPECT_NE(text.find("future, futurerecs: decoded (their owner unknown to this mcstat)"),
              std::string::npos)
        << text;
    EXPECT_EQ(mcstat(f + " --gmon -o " + path("g.exr")).code, 0);
    r = mcstat(f + " --pajot -o " + path("p.exr"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("neither per-sample records nor Pajot's online state"), std::string::npos)
        << r.err;
    // A renderer cannot continue a state it does not know.
    r = render("--scene tiny --spp 16 --resume " + f + " -o " + path("more.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("holds the state of 'futureop', which this renderer cannot continue"),
              std::string::npos)
        << r.err;
}

// --info and --check describe Pajot's state through its registry entry's hook.
TEST_F(PajotFile, InfoAndCheckDescribeTheStateThroughTheRegistry) {
    ASSERT_EQ(render("--scene tiny --spp 8 --pajot rot --pajot-n 4 -o " + path("s.mcstat")).code,
              0);
    const Operation* op = findOperation("pajot");
    ASSERT_NE(op, nullptr);
    EXPECT_EQ(op->state.flatPart, "pajot");
    EXPECT_EQ(op->state.deepPart, "modes");
    ToolRun r = mcstat(path("s.mcstat") + " --check");
    ASSERT_EQ(r.code, 0) << r.err;
    std::string text = r.out;
    EXPECT_NE(text.find("pajot, modes: decoded and checked"), std::string::npos) << text;
    EXPECT_NE(text.find("pajot (online, delayed=64:delta=0:luma="), std::string::npos) << text;
    EXPECT_NE(text.find("method=rot:n=4:t=2): modes per pixel"), std::string::npos) << text;
    r = mcstat(path("s.mcstat") + " --info");
    ASSERT_EQ(r.code, 0) << r.err;
    text = r.out;
    EXPECT_NE(text.find("pajot: samples delayed"), std::string::npos) << text;
}

}  // namespace
}  // namespace mcstat
