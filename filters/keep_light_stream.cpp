// The removed light given back by bands of rows (include/mcstat/filters/keep_light_stream.h).
#include "mcstat/filters/keep_light_stream.h"

#include <algorithm>
#include <vector>

#include "keep_light_rows.h"

namespace mcstat {

namespace {

/// The per-pixel arrays of rows [first, end): what the caller filled and what the steps computed
/// for them. Rows are appended at the end and dropped from the front.
struct HeldBands {
    size_t width = 0, nc = 0;
    bool guided = false;
    int biasRadius = 0;  ///< rule 7's largest radius, 0 where it does not apply
    int first = 0, end = 0;
    std::vector<double> residual, norm, clusterNorm, lightNorm, biasNorm;
    std::vector<float> d, se, robustY, guide, cluster, light, restShare, biasGuide;
    std::vector<uint8_t> active, scale, restScale;

    size_t offset(int y) const { return size_t(y - first) * width; }
    template <class F>
    void each(F f) {
        f(residual, nc);
        f(norm, guided ? 1 : 0);
        f(clusterNorm, 1);
        f(lightNorm, 1);
        f(biasNorm, biasRadius > 0 ? 1 : 0);
        f(d, 1);
        f(se, 1);
        f(robustY, 1);
        f(guide, guided ? 1 : 0);
        f(cluster, 1);
        f(light, 1);
        f(restShare, 1);
        f(biasGuide, biasRadius > 0 ? 1 : 0);
        f(active, 1);
        f(scale, 1);
        f(restScale, 1);
    }
    void growTo(int y) {
        const size_t rows = size_t(y - first);
        each([&](auto& v, size_t k) { v.resize(rows * width * k); });
        end = y;
    }
    void dropBefore(int y) {
        if (y <= first) return;
        const size_t rows = size_t(y - first);
        each([&](auto& v, size_t k) {
            v.erase(v.begin(), v.begin() + std::ptrdiff_t(rows * width * k));
        });
        first = y;
    }
    keeplight::HeldRows view(int height) const {
        keeplight::HeldRows h;
        h.width = int(width);
        h.height = height;
        h.first = first;
        h.count = end - first;
        h.nc = nc;
        h.residual = residual.data();
        h.d = d.data();
        h.se = se.data();
        h.robustY = robustY.data();
        h.active = active.data();
        h.guide = guided ? guide.data() : nullptr;
        h.cluster = cluster.data();
        h.scale = scale.data();
        h.norm = guided ? norm.data() : nullptr;
        h.clusterNorm = clusterNorm.data();
        h.restScale = restScale.data();
        h.restShare = restShare.data();
        h.light = light.data();
        h.lightNorm = lightNorm.data();
        h.biasRadius = biasRadius;
        h.biasGuide = biasRadius > 0 ? biasGuide.data() : nullptr;
        h.biasNorm = biasRadius > 0 ? biasNorm.data() : nullptr;
        return h;
    }
};

}  // namespace

int keepLightBandRows(const KeepLightParams& params) {
    return std::max(64, 2 * keeplight::haloRows(params));
}

bool keepLightStream(int width, int height, int nch, bool guided, const KeepLightParams& params,
                     const KeepLightFill& fill, const KeepLightTake& take, int nthreads,
                     int bandRows) {
    const std::vector<int> radii = keepLightRadii(params.maxRadius);
    const int R = keeplight::haloRows(params);
    // Rule 7's windows (radius 2 to biasRadius) read the bias guide that far beyond their rows.
    const bool byBias = guided && params.biasRadius >= 2 && params.maxRadius >= 2;
    const int biasHalo = byBias ? std::min(params.biasRadius, R) : 0;
    const int band = bandRows > 0 ? bandRows : keepLightBandRows(params);
    HeldBands held;
    held.width = size_t(width);
    held.nc = size_t(nch);
    held.guided = guided;
    held.biasRadius = byBias ? params.biasRadius : 0;
    // Rule 7's inputs, for the rows the scales step computes at once (its guide is what stays).
    std::vector<float> bias, level;
    std::vector<double> add;
    keeplight::GatherScratch scratch;
    // Each step has computed the rows before its mark: filled, cluster and light guides, scales,
    // norms, returned. A step's rows [mark, to) become computable once the rows its windows read
    // are: the guides' one row beyond, the scales' R (the choice's windows), the norms' R (the
    // guides' windows; the bias guide's, computed with the scales, biasHalo), the return's R
    // beyond the norms.
    int filled = 0, clustered = 0, scaled = 0, normed = 0, returned = 0;
    while (returned < height) {
        if (filled < height) {
            const int y1 = std::min(height, filled + band);
            held.growTo(y1);
            const size_t o = held.offset(filled);
            const KeepLightBandIn in{held.residual.data() + o * held.nc,
                                     held.d.data() + o,
                                     held.se.data() + o,
                                     held.robustY.data() + o,
                                     held.active.data() + o,
                                     guided ? held.guide.data() + o : nullptr};
            if (!fill(filled, y1, in)) return false;
            filled = y1;
        }
        const bool all = filled == height;
        const int clusterTo = all ? height : filled - 1;
        const int scaleTo = all ? height : filled - R;
        const int normTo = all ? height : std::min(scaleTo - biasHalo, clusterTo - R);
        const int returnTo = all ? height : normTo - R;
        keeplight::HeldRows view = held.view(height);
        if (clusterTo > clustered) {
            keeplight::guideRows(view, clustered, clusterTo,
                                 held.cluster.data() + held.offset(clustered),
                                 held.light.data() + held.offset(clustered), nthreads);
            clustered = clusterTo;
        }
        if (scaleTo > scaled) {
            const size_t o = held.offset(scaled), n = size_t(scaleTo - scaled) * held.width;
            bias.resize(byBias ? n : 0);
            level.resize(byBias ? n : 0);
            keeplight::scalesRows(view, params, scaled, scaleTo, held.scale.data() + o,
                                  held.restScale.data() + o, held.restShare.data() + o,
                                  byBias ? bias.data() : nullptr, byBias ? level.data() : nullptr,
                                  nthreads);
            if (byBias)
                keeplight::biasGuideRows(bias.data(), level.data(), held.guide.data() + o, n,
                                         params.biasFloor, held.biasGuide.data() + o, nthreads);
            scaled = scaleTo;
        }
        if (normTo > normed) {
            keeplight::normsRows(view, radii, normed, normTo,
                                 guided ? held.norm.data() + held.offset(normed) : nullptr,
                                 held.clusterNorm.data() + held.offset(normed),
                                 held.lightNorm.data() + held.offset(normed),
                                 byBias ? held.biasNorm.data() + held.offset(normed) : nullptr,
                                 nthreads);
            normed = normTo;
        }
        if (returnTo > returned) {
            add.resize(size_t(returnTo - returned) * held.width * held.nc);
            keeplight::gatherRows(view, radii, returned, returnTo, add.data(), scratch, nthreads);
            if (!take(returned, returnTo, add.data())) return false;
            returned = returnTo;
        }
        // What the steps still read: the senders within R of the first row not yet returned (the
        // other steps' windows start later).
        held.dropBefore(std::max(0, returned - R));
    }
    return true;
}

}  // namespace mcstat
