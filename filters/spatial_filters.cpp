// Jung's spatial and 3D robust filters (thesis chapter 5, eq. 5.6-5.8, 5.14, 5.19-5.21, 5.28):
// the weighted trimmed mean over a window of elements. Rules: include/mcstat/spatial_filters.h.
#include "mcstat/spatial_filters.h"

#include <algorithm>
#include <cmath>

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

namespace {

/// Sorts s.ranked ascending by key, ties by element index (the pair order), so results never
/// depend on the sort algorithm.
void sortRanked(SpatialScratch& s) { std::sort(s.ranked.begin(), s.ranked.end()); }

/// Walks the sorted elements, keeps the copies with duplicated rank in [lo, hi) and averages
/// channels [c0, c1) with weights r_i n_i. Returns the number of elements with a kept copy.
int trimmedAverage(const WindowElement* e, const SpatialScratch& s, int64_t lo, int64_t hi, int c0,
                   int c1, PixelEstimate& out) {
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
        ++kept;
    }
    for (int c = c0; c < c1; ++c) out.rgb[size_t(c)] = float(sum[c] / wsum);
    return kept;
}

}  // namespace

void weightedTrimmedMean(const WindowElement* elems, int n, const SpatialParams& p,
                         PixelEstimate& out, SpatialScratch& s) {
    out.rgb = {0.f, 0.f, 0.f};
    out.gini = {0.f, 0.f, 0.f};
    out.kept = {0, 0, 0};
    if (n <= 0) return;  // no valid element: black
    int64_t total = 0;   // s of eq. 5.6 / 5.19
    for (int i = 0; i < n; ++i) total += elems[i].weight;
    const int64_t c = spatialTrim(p.alpha, total);
    s.ranked.resize(size_t(n));
    if (p.mode == EstimatorMode::Luminance) {
        for (int i = 0; i < n; ++i) {
            const float* v = elems[i].rgb;
            s.ranked[size_t(i)] = {p.luma[0] * v[0] + p.luma[1] * v[1] + p.luma[2] * v[2], i};
        }
        sortRanked(s);
        out.kept.fill(trimmedAverage(elems, s, c, total - c, 0, 3, out));
        return;
    }
    for (int ch = 0; ch < 3; ++ch) {
        for (int i = 0; i < n; ++i) s.ranked[size_t(i)] = {double(elems[i].rgb[ch]), i};
        sortRanked(s);
        out.kept[size_t(ch)] = trimmedAverage(elems, s, c, total - c, ch, ch + 1, out);
    }
}

// ---- MIF / WMIF ---------------------------------------------------------------------------------

void wmifPixel(const RGBImageView& img, int x, int y, const SpatialParams& p, PixelEstimate& out,
               SpatialScratch& s) {
    // Window clipped to the image (the thesis does not treat borders).
    const int rx = p.windowWidth / 2, ry = p.windowHeight / 2;
    const int x0 = std::max(0, x - rx), x1 = std::min(img.width - 1, x + rx);
    const int y0 = std::max(0, y - ry), y1 = std::min(img.height - 1, y + ry);
    s.elems.clear();
    out.excluded = 0;
    for (int yy = y0; yy <= y1; ++yy)
        for (int xx = x0; xx <= x1; ++xx) {
            const float* v = img.rgb + (size_t(yy) * size_t(img.width) + size_t(xx)) * 3;
            if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2])) {
                ++out.excluded;
                continue;
            }
            // eq. 5.28: w_c at the centre, 1 elsewhere
            s.elems.push_back({v, 1.0, (xx == x && yy == y) ? p.centreWeight : int64_t(1)});
        }
    weightedTrimmedMean(s.elems.data(), int(s.elems.size()), p, out, s);
}

void wmifImage(const RGBImageView& img, const SpatialParams& p, float* out) {
    SpatialScratch s;
    PixelEstimate e;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            wmifPixel(img, x, y, p, e, s);
            float* o = out + (size_t(y) * size_t(img.width) + size_t(x)) * 3;
            o[0] = e.rgb[0];
            o[1] = e.rgb[1];
            o[2] = e.rgb[2];
        }
}

// ---- 3D filters ---------------------------------------------------------------------------------

PixelBuffers FixedBufferGrid::at(int x, int y) const {
    const size_t p = size_t(y) * size_t(width) + size_t(x);
    return {bufferMean + p * size_t(M) * 3, bufferCount + p * size_t(M), M};
}

BufferView FixedBufferGrid::view() const {
    return {width, height, this, [](const void* ctx, int x, int y) {
                return static_cast<const FixedBufferGrid*>(ctx)->at(x, y);
            }};
}

void filter3DPixel(const BufferView& v, int x, int y, const SpatialParams& p, PixelEstimate& out,
                   SpatialScratch& s) {
    const int rx = p.windowWidth / 2, ry = p.windowHeight / 2;
    const int x0 = std::max(0, x - rx), x1 = std::min(v.width - 1, x + rx);
    const int y0 = std::max(0, y - ry), y1 = std::min(v.height - 1, y + ry);
    s.elems.clear();
    out.excluded = 0;
    for (int yy = y0; yy <= y1; ++yy)
        for (int xx = x0; xx <= x1; ++xx) {
            const PixelBuffers px = v.at(xx, yy);  // this pixel's own M
            int excluded = 0;
            collectValidBuffers(px, s.valid, excluded);
            out.excluded += excluded;
            // eq. 5.19 with eq. 5.28: every buffer of the centre pixel carries w_c
            const int64_t w = (xx == x && yy == y) ? p.centreWeight : int64_t(1);
            for (int j : s.valid)
                s.elems.push_back({px.mean + 3 * size_t(j), double(px.count[j]), w});
        }
    weightedTrimmedMean(s.elems.data(), int(s.elems.size()), p, out, s);
}

void filter3DImage(const BufferView& v, const SpatialParams& p, float* out) {
    SpatialScratch s;
    PixelEstimate e;
    for (int y = 0; y < v.height; ++y)
        for (int x = 0; x < v.width; ++x) {
            filter3DPixel(v, x, y, p, e, s);
            float* o = out + (size_t(y) * size_t(v.width) + size_t(x)) * 3;
            o[0] = e.rgb[0];
            o[1] = e.rgb[1];
            o[2] = e.rgb[2];
        }
}

}  // namespace mcstat
