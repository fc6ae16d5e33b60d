// Compact statistics files (include/mcstat/compact/compact.h, FORMAT.md "Version 6").
//
// Why G-MoN decides: G-MoN trims c = floor(G floor(M'/2)) buffers per side (Buisine et al. 2021,
// eq. 6), and where c = 0 it returns the count-weighted mean of the valid buffers, which is what
// every buffer-free pixel of the compact file stores. The decision is made by running G-MoN
// itself (both modes) rather than a copy of its threshold, so the rule follows G-MoN exactly,
// including any change to its dispersion rule.
#include "mcstat/compact/compact.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>

#include "mcstat/core/color_space.h"
#include "mcstat/core/parallel.h"
#include "mcstat/filters/aov_weights.h"
#include "mcstat/filters/pixel/gmon.h"

namespace mcstat {

std::string compactRuleText(const CompactRule& rule) {
    // {} is the shortest text that reads back as the same double (0.2126, not 0.21260000000000001).
    return fmt::format("gmon luma={},{},{} margin={:g} z={:g}", rule.luma[0], rule.luma[1],
                       rule.luma[2], rule.margin, rule.z);
}

bool checkCompactRule(const CompactRule& rule, std::string& err) {
    for (double l : rule.luma)
        if (!std::isfinite(l) || l < 0.0) {
            err = "luminance weights must be finite and >= 0";
            return false;
        }
    if (!(rule.margin >= 0.0 && rule.margin <= 1.0)) {
        err = fmt::format("margin {} is not in 0..1", rule.margin);
        return false;
    }
    if (!(rule.z >= 0.0) || !std::isfinite(rule.z)) {
        err = fmt::format("z {} is not a finite value >= 0", rule.z);
        return false;
    }
    return true;
}

namespace {

bool sameBits(const std::array<float, 3>& a, const std::array<float, 3>& b) {
    return std::memcmp(a.data(), b.data(), sizeof(a)) == 0;
}

/// Whether some valid buffer's luminance lies more than z robust sigmas from the median.
bool outlyingBuffer(const PixelBuffers& px, const std::array<double, 3>& luma, double z,
                    CompactScratch& s) {
    const std::vector<int>& valid = s.valid;
    const size_t n = valid.size();
    if (n < 3) return false;
    s.lum.resize(n);
    for (size_t i = 0; i < n; ++i) {
        const float* m = px.mean + 3 * valid[i];
        s.lum[i] = luminance(luma, m);
    }
    std::vector<double>& dev = s.deviation;
    dev = s.lum;
    std::nth_element(dev.begin(), dev.begin() + long(n / 2), dev.end());
    const double median = dev[n / 2];
    double largest = 0.0;
    for (size_t i = 0; i < n; ++i) {
        dev[i] = std::fabs(s.lum[i] - median);
        largest = std::max(largest, dev[i]);
    }
    std::nth_element(dev.begin(), dev.begin() + long(n / 2), dev.end());
    const double sigma = 1.4826 * dev[n / 2];
    return largest > z * sigma;
}

/// Whether a valid buffer has a negative channel or luminance (where G-MoN's Gini inputs differ).
bool negativeKey(const PixelBuffers& px, const std::vector<int>& valid,
                 const std::array<double, 3>& luma) {
    for (int j : valid) {
        const float* m = px.mean + 3 * j;
        if (m[0] < 0.f || m[1] < 0.f || m[2] < 0.f || luminance(luma, m) < 0.0) return true;
    }
    return false;
}

}  // namespace

bool compactKeeps(const PixelBuffers& px, const CompactRule& rule, CompactScratch& scratch,
                  std::array<float, 3>& mean, std::vector<double>* weights) {
    int excluded = 0;
    const int Mv = collectValidBuffers(px, scratch.valid, excluded);
    if (excluded > 0) return true;  // NaN / Inf buffers: each estimator has its own answer
    PixelEstimate lum, channel;
    scratch.estimator.wantWeights = weights != nullptr;
    GmonParams gp;  // G-MoN's defaults (the registry's: GiniInput::Magnitudes)
    gp.luma = rule.luma;
    gp.mode = EstimatorMode::Luminance;
    estimateGMoN(px, gp, lum, scratch.estimator);
    if (weights != nullptr) *weights = scratch.estimator.bufferWeight;
    scratch.estimator.wantWeights = false;
    gp.mode = EstimatorMode::PerChannel;
    estimateGMoN(px, gp, channel, scratch.estimator);
    // G-MoN trimmed something in one of the modes: the buffers are needed.
    for (int c = 0; c < 3; ++c)
        if (lum.kept[size_t(c)] != Mv || channel.kept[size_t(c)] != Mv) return true;
    // Both modes average the same buffers, but in their own rank orders: in the rare pixel where
    // that changes the last bit, the buffers are kept so that both stay exact.
    if (!sameBits(lum.rgb, channel.rgb)) return true;
    if (rule.margin > 0.0 && Mv >= 2) {
        const double k = double(Mv / 2);
        const double G = std::max({double(lum.gini[0]), double(channel.gini[0]),
                                   double(channel.gini[1]), double(channel.gini[2])});
        if (G > 0.0 && G * k >= 1.0 - rule.margin) return true;
    }
    if (rule.z > 0.0 && outlyingBuffer(px, rule.luma, rule.z, scratch)) return true;
    // G-MoN's two Gini inputs (gini=abs, the default, and gini=shift) are the same G on a pixel
    // without a negative mean or luminance; elsewhere the buffers stay when either form trims, so
    // that G-MoN is exact on the compact file in both.
    if (negativeKey(px, scratch.valid, rule.luma)) {
        gp.gini = GiniInput::Shifted;
        for (EstimatorMode mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
            gp.mode = mode;
            PixelEstimate shifted;
            estimateGMoN(px, gp, shifted, scratch.estimator);
            for (int c = 0; c < 3; ++c)
                if (shifted.kept[size_t(c)] != Mv) return true;
            if (!sameBits(shifted.rgb, lum.rgb)) return true;
        }
    }
    mean = lum.rgb;
    return false;
}

void bufferSpread(const PixelBuffers& px, const std::vector<int>& valid, float* out) {
    const size_t Mv = valid.size();
    out[0] = float(Mv);
    if (Mv < 2) {
        std::fill(out + 1, out + kSpreadFloats, std::numeric_limits<float>::quiet_NaN());
        return;
    }
    double n = 0.0, mu[3] = {0.0, 0.0, 0.0};
    for (int j : valid) {
        n += double(px.count[j]);
        for (int c = 0; c < 3; ++c) mu[c] += double(px.count[j]) * double(px.mean[3 * j + c]);
    }
    for (double& m : mu) m /= n;
    double cov[3][3] = {};
    for (int j : valid) {
        const double w = double(px.count[j]);
        double d[3];
        for (int c = 0; c < 3; ++c) d[c] = double(px.mean[3 * j + c]) - mu[c];
        for (int c = 0; c < 3; ++c)
            for (int e = c; e < 3; ++e) cov[c][e] += w * d[c] * d[e];
    }
    for (int c = 0; c < 3; ++c)
        for (int e = c; e < 3; ++e) out[spreadIndex(c, e)] = float(cov[c][e] / double(Mv - 1));
}

bool compactHeader(const StatsHeader& full, const std::string& name, const CompactRule& rule,
                   StatsHeader& out, std::string& err) {
    if (full.compact) {
        err = name + " is already compact";
        return false;
    }
    if (full.adaptiveM) {
        err = fmt::format(
            "{} has adaptive M, whose buffers were chosen while rendering: --compact takes a "
            "fixed-M file (render or ingest with a fixed M, then --compact)",
            name);
        return false;
    }
    if (std::string why; !checkCompactRule(rule, why)) {
        err = "--compact: " + why;
        return false;
    }
    out = full;
    out.adaptiveM = true;
    out.compact = true;
    out.compactRule = compactRuleText(rule);
    out.state = StateOwner();  // per-sample state and records stay in the full file
    out.hasRecords = false;
    out.formatVersion = kStatsFormatVersionMeansInBeauty;
    return true;
}

bool CompactStatsSource::init(StatsBlockSource& src, const CompactRule& rule, std::string& err,
                              int nthreads) {
    src_ = nullptr;
    if (!src.ready()) {
        err = src.name() + ": no image to compact";
        return false;
    }
    if (!compactHeader(src.header(), src.name(), rule, header_, err)) return false;
    src_ = &src;
    rule_ = rule;
    nthreads_ = nthreads;
    return true;
}

bool CompactStatsSource::read(int firstRow, int rows, unsigned /*parts*/, StatsImage& block,
                              std::string& err) {
    if (src_ == nullptr) {
        err = "compact source: read before a successful init";
        return false;
    }
    const StatsHeader& fh = src_->header();
    const unsigned all = kStatsAllParts;
    if (!src_->read(firstRow, rows, all, full_, err)) return false;
    const size_t pixels = full_.pixelCount(), M = size_t(fh.M), A = fh.aovs.size();
    // Pass 1, per pixel in parallel: keep or not; the mean, AOV values and spread of those that
    // don't, the number of valid buffers of those that do (their buffers give the rest).
    std::vector<uint8_t> keep(pixels);
    std::vector<float> mean(pixels * 3), aovMean(pixels * A), spread(pixels * kSpreadFloats, 0.f);
    const std::vector<AovClass> classes = aovClasses(fh.aovs);
    parallelFor(0, int64_t(pixels), 1024, nthreads_, [&](int64_t b, int64_t e) {
        CompactScratch scratch;
        AovScratch aovScratch;
        std::vector<double> weights;
        for (size_t p = size_t(b); p < size_t(e); ++p) {
            std::array<float, 3> m{};
            const PixelBuffers px = full_.pixelBuffers(p);
            keep[p] = compactKeeps(px, rule_, scratch, m, A > 0 ? &weights : nullptr);
            float* sp = spread.data() + p * size_t(kSpreadFloats);
            if (keep[p]) {
                sp[0] = float(scratch.valid.size());
                continue;
            }
            bufferSpread(px, scratch.valid, sp);
            std::copy(m.begin(), m.end(), mean.begin() + long(p * 3));
            if (A > 0)
                applyAovWeights(weights.data(), M, full_.aov.data() + p * M * A, A, classes.data(),
                                aovMean.data() + p * A, aovScratch);
        }
    });
    std::vector<uint32_t> m(pixels);
    for (size_t p = 0; p < pixels; ++p) m[p] = keep[p] ? uint32_t(M) : 1u;
    StatsImage out;
    out.header = header_;
    out.header.height = rows;
    out.header.originY = fh.originY + firstRow;
    if (!out.allocateAdaptive(m, err)) return false;
    out.beauty = full_.beauty;
    out.count = full_.count;
    out.normal = full_.normal;
    out.position = full_.position;
    out.albedo = full_.albedo;
    out.depth = full_.depth;
    out.coverage = full_.coverage;
    out.spread = std::move(spread);
    // Pass 2: the buffers, all M or the one mean with the pixel's count.
    parallelFor(0, int64_t(pixels), 1024, nthreads_, [&](int64_t b, int64_t e) {
        for (size_t p = size_t(b); p < size_t(e); ++p) {
            const PixelBuffers px = full_.pixelBuffers(p);
            const size_t k = out.bufferBegin(p);
            if (keep[p]) {
                std::copy(px.mean, px.mean + 3 * M, out.bufferMean.begin() + long(k * 3));
                std::copy(px.count, px.count + M, out.bufferCount.begin() + long(k));
                std::copy(full_.aov.begin() + long(p * M * A),
                          full_.aov.begin() + long((p + 1) * M * A), out.aov.begin() + long(k * A));
                continue;
            }
            double n = 0.0;
            for (size_t j = 0; j < M; ++j) n += double(px.count[j]);
            std::copy(mean.begin() + long(p * 3), mean.begin() + long(p * 3 + 3),
                      out.bufferMean.begin() + long(k * 3));
            // Version 8 keeps this mean once, in part beauty (what stock tools show, so they show
            // G-MoN's value: the count-weighted mean, summed in G-MoN's rank order).
            std::copy(mean.begin() + long(p * 3), mean.begin() + long(p * 3 + 3),
                      out.beauty.begin() + long(p * 3));
            out.bufferCount[k] = float(n);
            std::copy(aovMean.begin() + long(p * A), aovMean.begin() + long((p + 1) * A),
                      out.aov.begin() + long(k * A));
        }
    });
    block = std::move(out);
    return validateStats(block, name(), err);
}

bool compactStats(const StatsImage& full, const CompactRule& rule, StatsImage& out,
                  std::string& err, int nthreads) {
    MemoryStatsSource src(std::shared_ptr<const StatsImage>(&full, [](const StatsImage*) {}),
                          "statistics image");
    CompactStatsSource compact;
    if (!compact.init(src, rule, err, nthreads)) return false;
    return readAll(compact, out, err);
}

}  // namespace mcstat
