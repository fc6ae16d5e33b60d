// `mcstat --OP:ci=LEVEL` end to end (docs/confidence.md): the interval layers, their values against
// the intervals computed here by hand, the extremes (a NaN buffer, one valid buffer) and the
// one-line errors of a bad level.
#include <OpenImageIO/imagebuf.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "cli_support.h"
#include "mcstat/core/location_stats.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"

using namespace mcstat;

namespace {

class ConfidenceCli : public mcstat::testing::CliFixture {};

constexpr int kM = 9;
// Pixel 0's buffers (grey): sorted 1 1 2 3 4 5 5 6 9 (filters/pixel/test_confidence.cpp).
const float kNine[kM] = {3, 1, 4, 1, 5, 9, 2, 6, 5};

/// 8x6, M = 9 buffers of 4 samples; pixel 0 holds kNine, pixel 1 a NaN buffer among kNine's
/// first eight, pixel 2 one valid buffer (the rest empty), the others colour-varying noise.
StatsImage makeStats() {
    StatsImage s;
    s.header.width = 8;
    s.header.height = 6;
    s.header.M = kM;
    s.header.spp = 4 * kM;
    s.header.renderer = "test_confidence_cli";
    s.header.seeds = "7";
    std::string err;
    EXPECT_TRUE(s.allocate(err)) << err;
    for (size_t p = 0; p < s.pixelCount(); ++p) {
        double sum[3] = {0, 0, 0}, n = 0;
        for (int j = 0; j < kM; ++j) {
            float count = 4.f;
            for (int c = 0; c < 3; ++c) {
                float v = 0.1f + 0.05f * float((j * 7 + int(p) * 3 + c * 5) % 11);
                if (p <= 1) v = kNine[j];
                if (p == 1 && j == 8) v = std::nanf("");
                s.bufferMean[(p * kM + j) * 3 + c] = v;
            }
            if (p == 2 && j > 0) count = 0.f;
            s.bufferCount[p * kM + j] = count;
            for (int c = 0; c < 3; ++c)
                if (std::isfinite(s.bufferMean[(p * kM + j) * 3 + c]))
                    sum[c] += count * s.bufferMean[(p * kM + j) * 3 + c];
            n += count;  // the moments count every sample, a NaN buffer's too
        }
        s.count[p] = float(n);
        for (int c = 0; c < 3; ++c) {
            s.mean[p * 3 + c] = s.beauty[p * 3 + c] = float(sum[c] / std::max(n, 1.0));
            s.variance[p * 3 + c] = 0.01f;
        }
        s.coverage[p] = 1.f;
    }
    return s;
}

/// Channel `name` of pixel (x, y) of `img`.
float at(const OIIO::ImageBuf& img, const std::string& name, int x, int y) {
    const int c = img.spec().channelindex(name);
    EXPECT_GE(c, 0) << name;
    return c < 0 ? NAN : img.getchannel(x, y, 0, c);
}

}  // namespace

TEST_F(ConfidenceCli, AddsSixFiniteChannelsAroundTheEstimate) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    for (const char* op : {"mean", "mon", "median", "gmon", "gmonb", "tmpe"}) {
        const std::string out = path(std::string(op) + ".exr");
        const auto r = mcstat(path("f.mcstat") + " --" + op + ":ci=0.95 -o " + out);
        ASSERT_EQ(r.code, 0) << op << ": " << r.err;
        OIIO::ImageBuf img(out);
        ASSERT_TRUE(img.read()) << img.geterror();
        // Exactly R, G, B and the six interval channels.
        ASSERT_EQ(img.nchannels(), 9) << op;
        for (const char* c : {"R", "G", "B", "ci_low.R", "ci_low.G", "ci_low.B", "ci_high.R",
                              "ci_high.G", "ci_high.B"})
            EXPECT_GE(img.spec().channelindex(c), 0) << op << " " << c;
        // Finite and low <= high wherever two or more buffers are valid; low <= estimate <= high
        // on the grey pixels (0, 0), (1, 0) for every estimator, and everywhere for the mean (the
        // centre of its t interval). (On colour-varying pixels a luminance-ranked estimate takes
        // one buffer's colour, which need not lie in each channel's interval: docs/confidence.md.)
        for (int y = 0; y < 6; ++y)
            for (int x = 0; x < 8; ++x) {
                if (y == 0 && x == 2) continue;  // one valid buffer: [-inf, inf] (below)
                for (const char* c : {"R", "G", "B"}) {
                    const float lo = at(img, std::string("ci_low.") + c, x, y);
                    const float hi = at(img, std::string("ci_high.") + c, x, y);
                    const float e = at(img, c, x, y);
                    EXPECT_TRUE(std::isfinite(lo) && std::isfinite(hi)) << op << " " << x << y;
                    EXPECT_LE(lo, hi) << op << " " << x << y;
                    if ((y == 0 && x < 2) || std::string(op) == "mean") {
                        EXPECT_LE(lo, e) << op << " " << x << y;
                        EXPECT_LE(e, hi) << op << " " << x << y;
                    }
                }
            }
        // One valid buffer: no interval, [-inf, inf].
        EXPECT_EQ(at(img, "ci_low.G", 2, 0), -INFINITY) << op;
        EXPECT_EQ(at(img, "ci_high.G", 2, 0), INFINITY) << op;
    }
}

TEST_F(ConfidenceCli, ValuesByHand) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    ASSERT_EQ(mcstat(path("f.mcstat") + " --mon:ci=0.95 -o " + path("mon.exr")).code, 0);
    ASSERT_EQ(mcstat(path("f.mcstat") + " --mean:ci=0.95 -o " + path("mean.exr")).code, 0);
    OIIO::ImageBuf mon(path("mon.exr")), mean(path("mean.exr"));
    // M = 9 at 0.95: order statistics 2 and 8 of 1 1 2 3 4 5 5 6 9: [1, 6].
    EXPECT_EQ(at(mon, "ci_low.R", 0, 0), 1.f);
    EXPECT_EQ(at(mon, "ci_high.B", 0, 0), 6.f);
    // The NaN buffer is left out: 8 valid, sorted 1 1 2 3 4 5 6 9 (kNine without its last 5).
    // M = 8 at 0.95: k = 2 covers P(2 <= Bin(8, 1/2) <= 6) = 1 - 18/256 = 0.9297 < 0.95, k = 1
    // covers 1 - 2/256 = 0.9922: [x_(1), x_(8)] = [1, 9].
    EXPECT_EQ(at(mon, "ci_low.G", 1, 0), 1.f);
    EXPECT_EQ(at(mon, "ci_high.G", 1, 0), 9.f);
    // Student: 4 +- 2.3060041 sqrt(0.75) = [2.0029418, 5.9970582].
    EXPECT_NEAR(at(mean, "ci_low.R", 0, 0), 2.0029418f, 1e-5);
    EXPECT_NEAR(at(mean, "ci_high.R", 0, 0), 5.9970582f, 1e-5);
}

TEST_F(ConfidenceCli, WithDiagnosticsResidualAndStreamed) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    // With the diagnostics and the residual: the layers in between, the level in the metadata.
    const auto r =
        mcstat(path("f.mcstat") + " --gmon:ci=0.9:diag=1:residual=1 -o " + path("g.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    OIIO::ImageBuf g(path("g.exr"));
    ASSERT_TRUE(g.read());
    EXPECT_EQ(g.nchannels(), 3 + 3 + 6 + 3);  // R G B, gini kept excluded, ci x 6, residual x 3
    EXPECT_EQ(g.spec().get_float_attribute("mcstat:ciLevel"), 0.9f);
    // What it covers, in the file (issue 50): G-MoN's the median of the buffer means, the mean's
    // the pixel's expected value.
    EXPECT_NE(g.spec().get_string_attribute("mcstat:ciTarget").find("median of the buffer means"),
              std::string::npos);
    ASSERT_EQ(mcstat(path("f.mcstat") + " --mean:ci=0.9 -o " + path("m.exr")).code, 0);
    OIIO::ImageBuf m(path("m.exr"));
    ASSERT_TRUE(m.read());
    EXPECT_NE(m.spec().get_string_attribute("mcstat:ciTarget").find("expected value"),
              std::string::npos);
    // Every estimator with an interval names its target.
    for (const Operation& op : operationRegistry())
        if (hasIntervals(op)) {
            ParamValues v;
            ASSERT_TRUE(parseOperationParams(op, {}, v, err)) << err;
            EXPECT_FALSE(op.bindPixel(v, {0.3, 0.6, 0.1}).intervalTarget.empty()) << op.name;
        }
}

TEST_F(ConfidenceCli, CompactFilesKeepTheirIntervals) {
    // A compact file's pixels that kept only their mean get the mean's t interval from the stored
    // spread (the full file's --mean:ci there, up to float rounding of the spread); the others
    // the full file's G-MoN interval bit for bit. Before: [-inf, inf] in those pixels.
    const std::string render = std::string(MCSTAT_RENDER_EXE) +
                               " --quiet --scene default --res 40 30 --spp 180 --M 9 --seed 5 -o " +
                               path("full.mcstat");
    ASSERT_EQ(mcstat::testing::runCommand(render.c_str()), 0) << render;
    ASSERT_EQ(mcstat(path("full.mcstat") + " --compact -o " + path("small.mcstat")).code, 0);
    auto r = mcstat(path("small.mcstat") + " --gmon:ci=0.95 -o " + path("c.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.err.find("adaptive M"), std::string::npos) << r.err;
    ASSERT_EQ(mcstat(path("full.mcstat") + " --gmon:ci=0.95 -o " + path("g.exr")).code, 0);
    ASSERT_EQ(mcstat(path("full.mcstat") + " --mean:ci=0.95 -o " + path("m.exr")).code, 0);
    OIIO::ImageBuf c(path("c.exr")), g(path("g.exr")), m(path("m.exr"));
    ASSERT_TRUE(c.read(0, 0, true, OIIO::TypeFloat) && g.read(0, 0, true, OIIO::TypeFloat) &&
                m.read(0, 0, true, OIIO::TypeFloat));
    EXPECT_NE(c.spec().get_string_attribute("mcstat:ciTarget").find("compact file"),
              std::string::npos);
    StatsImage small;
    std::string err;
    ASSERT_TRUE(readStatsFile(path("small.mcstat"), small, err)) << err;
    int dropped = 0, kept = 0;
    for (int y = 0; y < 30; ++y)
        for (int x = 0; x < 40; ++x) {
            const bool one = small.buffersOf(size_t(y) * 40 + size_t(x)) == 1;
            (one ? dropped : kept) += 1;
            for (const char* ch : {"ci_low.R", "ci_high.G", "ci_low.B"}) {
                const float v = c.getchannel(x, y, 0, c.spec().channelindex(ch));
                ASSERT_TRUE(std::isfinite(v)) << ch << " at " << x << ", " << y;
                if (one) {
                    const float want = m.getchannel(x, y, 0, m.spec().channelindex(ch));
                    EXPECT_NEAR(v, want, 1e-5f * std::max(1.f, std::fabs(want)))
                        << ch << " at " << x << ", " << y;
                } else {
                    EXPECT_EQ(v, g.getchannel(x, y, 0, g.spec().channelindex(ch)))
                        << ch << " at " << x << ", " << y;
                }
            }
        }
    EXPECT_GT(dropped, 100);
    EXPECT_GT(kept, 10);
}

TEST_F(ConfidenceCli, ExpectedValueIntervalPoolsTheNeighboursVarianceByHand) {
    // citarget=expected: mean +- t_{m-1} sqrt(max(s2, pooled s2) / N), s2 the pixel's per-sample
    // variance, pooled the mean of the finite s2 in the 3 x 3 window (cipool=1) clipped to the
    // image; computed here from the buffers directly.
    const StatsImage s = makeStats();
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), s, err)) << err;
    auto r =
        mcstat(path("f.mcstat") + " --gmon:ci=0.95:citarget=expected:cipool=1 -o " + path("e.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    OIIO::ImageBuf e(path("e.exr"));
    ASSERT_TRUE(e.read(0, 0, true, OIIO::TypeFloat));
    EXPECT_NE(e.spec().get_string_attribute("mcstat:ciTarget").find("expected value"),
              std::string::npos);
    const int W = 8, H = 6;
    std::vector<double> mean(W * H * 3), s2(W * H * 3), N(W * H);
    std::vector<int> m(W * H);
    for (int p = 0; p < W * H; ++p)
        for (int c = 0; c < 3; ++c) {
            double sum = 0, n = 0, ss = 0;
            int k = 0;
            for (int j = 0; j < kM; ++j) {
                const double v = s.bufferMean[(size_t(p) * kM + size_t(j)) * 3 + size_t(c)];
                const double w = s.bufferCount[size_t(p) * kM + size_t(j)];
                if (!(w > 0) || !std::isfinite(v)) continue;
                sum += w * v, n += w, ++k;
            }
            const double mu = sum / n;
            for (int j = 0; j < kM; ++j) {
                const double v = s.bufferMean[(size_t(p) * kM + size_t(j)) * 3 + size_t(c)];
                const double w = s.bufferCount[size_t(p) * kM + size_t(j)];
                if (!(w > 0) || !std::isfinite(v)) continue;
                ss += w * (v - mu) * (v - mu);
            }
            mean[size_t(p) * 3 + size_t(c)] = mu;
            s2[size_t(p) * 3 + size_t(c)] = k >= 2 ? ss / (k - 1) : NAN;
            N[size_t(p)] = n;
            m[size_t(p)] = k;
        }
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const int p = y * W + x;
            for (int c = 0; c < 3; ++c) {
                double pooled = 0;
                int count = 0;
                for (int v = std::max(0, y - 1); v <= std::min(H - 1, y + 1); ++v)
                    for (int u = std::max(0, x - 1); u <= std::min(W - 1, x + 1); ++u)
                        if (std::isfinite(s2[size_t(v * W + u) * 3 + size_t(c)])) {
                            pooled += s2[size_t(v * W + u) * 3 + size_t(c)];
                            ++count;
                        }
                pooled /= count;
                const char* ch = c == 0 ? "R" : c == 1 ? "G" : "B";
                const float lo = at(e, std::string("ci_low.") + ch, x, y);
                const float hi = at(e, std::string("ci_high.") + ch, x, y);
                if (m[size_t(p)] < 2) {  // pixel 2: one valid buffer, no degrees of freedom
                    EXPECT_TRUE(std::isinf(lo) && std::isinf(hi)) << p;
                    continue;
                }
                const double own = s2[size_t(p) * 3 + size_t(c)];
                const double half = studentQuantile(0.975, m[size_t(p)] - 1) *
                                    std::sqrt(std::max(own, pooled) / N[size_t(p)]);
                const double mu = mean[size_t(p) * 3 + size_t(c)];
                EXPECT_NEAR(lo, mu - half, 1e-5 * std::max(1.0, std::fabs(mu))) << p << ch;
                EXPECT_NEAR(hi, mu + half, 1e-5 * std::max(1.0, std::fabs(mu))) << p << ch;
            }
        }
    // Refused: its modifiers without what they need, and the AOVs' expected intervals.
    for (const char* bad : {":cipool=2", ":ci=0.9:cipool=2", ":citarget=expected",
                            ":ci=0.9:citarget=expected:ciaovs=1", ":ci=0.9:citarget=mean"}) {
        r = mcstat(path("f.mcstat") + " --gmon" + bad + " -o " + path("x.exr"));
        EXPECT_EQ(r.code, 1) << bad;
        EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << bad << ": " << r.err;
    }
}

TEST_F(ConfidenceCli, BadLevelIsOneLine) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    for (const char* level : {"0", "1", "-1", "abc", "1.5", "nan"}) {
        const auto r = mcstat(path("f.mcstat") + " --gmon:ci=" + level + " -o " + path("g.exr"));
        EXPECT_NE(r.code, 0) << level;
        EXPECT_EQ(r.err, std::string("mcstat: --gmon: ci must be a number in (0, 1), not '") +
                             level + "'\n")
            << level;
    }
    const auto a = mcstat(path("f.mcstat") + " --gmon:ciaovs=1 -o " + path("g.exr"));
    EXPECT_NE(a.code, 0);
    EXPECT_EQ(a.err, "mcstat: --gmon: ciaovs=1 needs ci=LEVEL\n");
    // Estimators without an interval do not take it.
    const auto r = mcstat(path("f.mcstat") + " --myriad:ci=0.9 -o " + path("m.exr"));
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find("--myriad has no modifier 'ci'"), std::string::npos) << r.err;
}

TEST_F(ConfidenceCli, WithoutCiNothingChanges) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    ASSERT_EQ(mcstat(path("f.mcstat") + " --gmon -o " + path("g.exr")).code, 0);
    OIIO::ImageBuf g(path("g.exr"));
    ASSERT_TRUE(g.read());
    EXPECT_EQ(g.nchannels(), 3);
    EXPECT_EQ(g.spec().get_string_attribute("mcstat.parameters"), "gini=abs,mode=lum");
    EXPECT_EQ(g.spec().find_attribute("mcstat:ciLevel"), nullptr);
}

TEST_F(ConfidenceCli, TooFewBuffersWarns) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    // 0.999 needs 11 buffers for the median's interval (1 - 2^-10 = 0.99902 >= 0.999).
    const auto r = mcstat(path("f.mcstat") + " --mon:ci=0.999 -o " + path("m.exr"));
    EXPECT_EQ(r.code, 0);
    EXPECT_NE(r.err.find("only from 11 valid sub-buffers"), std::string::npos) << r.err;
}

TEST_F(ConfidenceCli, HeatmapOfTheRelativeWidthAndContactSheetTile) {
    std::string err;
    ASSERT_TRUE(writeStatsFile(path("f.mcstat"), makeStats(), err)) << err;
    // --heatmap:channel=ciwidth draws sum (high - low) / sum |estimate| on a log scale. Pixel
    // (0, 0) of the mean: width 2 * 1.9970582 per channel over the value 4: 0.99853.
    auto r =
        mcstat(path("f.mcstat") + " --mean:ci=0.95 --heatmap:channel=ciwidth -o " + path("w.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    OIIO::ImageBuf w(path("w.exr"));
    ASSERT_TRUE(w.read());
    EXPECT_EQ(w.spec().get_string_attribute("mcstat:heatmap:channel"), "ciwidth");
    EXPECT_EQ(w.spec().get_int_attribute("mcstat:heatmap:log"), 1);
    // Pixel 2 (one buffer) is unbounded: +inf, counted as non-finite.
    EXPECT_GE(w.spec().get_int_attribute("mcstat:heatmap:nonFinite"), 1);
    EXPECT_LE(w.spec().get_float_attribute("mcstat:heatmap:min"), 0.99853f);
    EXPECT_GE(w.spec().get_float_attribute("mcstat:heatmap:max"), 0.99853f);
    // Without :ci there is nothing to draw: one line naming the missing channel.
    r = mcstat(path("f.mcstat") + " --mean --heatmap:channel=ciwidth -o " + path("w2.exr"));
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find("has no channel ci_low.R"), std::string::npos) << r.err;
    // The contact sheet's :ci=LEVEL adds one tile after the relative error.
    ASSERT_EQ(mcstat(path("f.mcstat") + " --mean -o " + path("ref.exr")).code, 0);
    r = mcstat(path("f.mcstat") + " --contactsheet:estimators=gmon:ci=0.9 " + path("ref.exr") +
               " -o " + path("sheet.exr"));
    ASSERT_EQ(r.code, 0) << r.err;
    OIIO::ImageBuf sheet(path("sheet.exr"));
    ASSERT_TRUE(sheet.read());
    EXPECT_EQ(sheet.spec().get_int_attribute("mcstat:sheet:tiles"), 5);  // mean gmon ref err ci
}
