// Jung's spatial and 3D robust filters (thesis chapter 5, eq. 5.6-5.8, 5.14, 5.19-5.21, 5.28):
// the weighted trimmed mean over a window of elements. Rules:
// include/mcstat/filters/window/window_rank.h.
#include "mcstat/filters/window/window_rank.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>

#include "mcstat/core/color_space.h"
#include "mcstat/filters/operation.h"
#include "mcstat/filters/window/detail/window_sort.h"

namespace mcstat {

bool validateSpatialParams(const SpatialParams& p, std::string& err) {
    auto side = [&err](const char* what, int v) {
        if (v >= 1 && v <= kMaxSpatialWindow && v % 2 == 1) return true;
        err = std::string("window ") + what + " must be odd and in [1, " +
              std::to_string(kMaxSpatialWindow) + "], not " + std::to_string(v);
        return false;
    };
    if (!side("width", p.windowWidth) || !side("height", p.windowHeight)) return false;
    if (p.centreWeight < 1 || p.centreWeight > kMaxCentreWeight) {
        err = "centre weight must be an integer in [1, " + std::to_string(kMaxCentreWeight) +
              "], not " + std::to_string(p.centreWeight);
        return false;
    }
    if (!(p.alpha >= 0.0 && p.alpha <= 0.5)) {
        err = "alpha must be in [0, 0.5], not " + std::to_string(p.alpha);
        return false;
    }
    return true;
}

int64_t spatialTrim(double alpha, int64_t s) {
    if (s < 2 || !(alpha > 0.0)) return 0;
    // Eq. 5.19 sums ranks 1 + alpha*s .. s - alpha*s of the s duplicated values, alpha in {i/s}.
    // As in TMPE (eq. 5.1), floor(alpha*s + 1e-9) maps any alpha to a count and keeps alpha = i/s
    // (rounded in binary) from losing one; the cap keeps the median (odd s) or the two middle
    // values (even s), which is eq. 5.6's alpha = floor((s-1)/2).
    const double c = std::floor(std::min(alpha, 1.0) * double(s) + 1e-9);
    return std::clamp(int64_t(c), int64_t(0), (s - 1) / 2);
}

namespace detail {

/// Sorts s.ranked ascending by key, ties by element index (the pair order), so results never
/// depend on the sort algorithm.
void sortRanked(SpatialScratch& s) { std::sort(s.ranked.begin(), s.ranked.end()); }

/// Normalises recorded weights by their sum (the average's denominator).
void normaliseWeights(std::vector<SpatialScratch::WeightedElement>* rec, double wsum) {
    if (rec == nullptr) return;
    for (auto& w : *rec) w.weight /= wsum;
}

}  // namespace detail

namespace {

using detail::normaliseWeights;
using detail::sortRanked;

/// Walks the sorted elements, keeps the copies with duplicated rank in [lo, hi) and averages
/// channels [c0, c1) with weights r_i n_i. Returns the number of elements with a kept copy.
int trimmedAverage(const WindowElement* e, const SpatialScratch& s, int64_t lo, int64_t hi, int c0,
                   int c1, PixelEstimate& out,
                   std::vector<SpatialScratch::WeightedElement>* rec = nullptr) {
    double sum[3] = {0.0, 0.0, 0.0}, wsum = 0.0;
    int kept = 0;
    int64_t pos = 0;  // duplicated rank of the element's first copy
    for (const auto& ki : s.ranked) {
        const WindowElement& el = e[ki.second];
        const int64_t a = std::max(pos, lo), b = std::min(pos + el.weight, hi);
        pos += el.weight;
        if (b <= a) {
            if (pos >= hi) break;
            continue;
        }
        const double w = double(b - a) * el.count;  // r_i n_i
        wsum += w;
        for (int c = c0; c < c1; ++c) sum[c] += w * double(el.rgb[c]);
        if (rec) rec->push_back({ki.second, -1, w});
        ++kept;
    }
    for (int c = c0; c < c1; ++c) out.rgb[size_t(c)] = float(sum[c] / wsum);
    normaliseWeights(rec, wsum);
    return kept;
}

}  // namespace

void weightedTrimmedMean(const WindowElement* elems, int n, const SpatialParams& p,
                         PixelEstimate& out, SpatialScratch& s) {
    out.rgb = {0.f, 0.f, 0.f};
    out.gini = {0.f, 0.f, 0.f};
    out.kept = {0, 0, 0};
    s.weights.clear();
    if (n <= 0) return;  // no valid element: black
    int64_t total = 0;   // s of eq. 5.6 / 5.19
    for (int i = 0; i < n; ++i) total += elems[i].weight;
    const int64_t c = spatialTrim(p.alpha, total);
    s.ranked.resize(size_t(n));
    if (p.mode == EstimatorMode::Luminance) {
        for (int i = 0; i < n; ++i) {
            const float* v = elems[i].rgb;
            s.ranked[size_t(i)] = {luminance(p.luma, v), i};
        }
        sortRanked(s);
        out.kept.fill(trimmedAverage(elems, s, c, total - c, 0, 3, out,
                                     s.wantWeights ? &s.weights : nullptr));
        return;
    }
    for (int ch = 0; ch < 3; ++ch) {
        for (int i = 0; i < n; ++i) s.ranked[size_t(i)] = {double(elems[i].rgb[ch]), i};
        sortRanked(s);
        out.kept[size_t(ch)] = trimmedAverage(elems, s, c, total - c, ch, ch + 1, out);
    }
}

// ---- parameters ---------------------------------------------------------------------------------
// SpatialParams's defaults are MIF's / 3DMF's values below (tests/filters/window/ checks it).

ParamSpec windowSizeParam() {
    ParamSpec p;
    p.name = "size";
    p.type = ParamType::Size;
    p.min = 1;
    p.max = kMaxSpatialWindow;
    p.odd = true;
    p.defaultValue = "3x3";
    p.help = "window width x height in pixels, centred; clipped at image borders";
    return p;
}

ParamSpec centreWeightParam(const std::string& def, bool fixed) {
    ParamSpec p = intParam("w", 1, double(kMaxCentreWeight), def,
                           "integer weight of the centre pixel (eq. 5.28); 1 = unweighted");
    p.fixed = fixed;
    return p;
}

ParamSpec breakdownParam(const std::string& def, bool fixed) {
    return realParam("alpha", 0.0, 0.5, false, def,
                     "breakdown point: floor(alpha*s) weighted copies trimmed per side; 0 = mean, "
                     "0.5 = the weighted median",
                     fixed);
}

ParamSpec windowModeParam() {
    return modeParam(
        "lum: rank by luminance, return the chosen pixels'/buffers' RGB, their weights applied to "
        "every AOV; channel: R, G, B independently, refused with AOVs");
}

SpatialParams spatialParams(const ParamValues& values, const std::array<double, 3>& luma) {
    SpatialParams p;
    p.luma = luma;
    for (const auto& [key, v] : values) {
        if (key == "mode") {
            p.mode = v.text == "lum" ? EstimatorMode::Luminance : EstimatorMode::PerChannel;
        } else if (key == "size") {
            p.windowWidth = int(v.integer);
            p.windowHeight = int(v.integer2);
        } else if (key == "w") {
            p.centreWeight = v.integer;
        } else if (key == "alpha") {
            p.alpha = v.real;
        }
    }
    return p;
}

}  // namespace mcstat
