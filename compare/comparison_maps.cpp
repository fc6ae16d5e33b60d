// The comparison's images (comparison.h): the maps of p, z, effect and rejections per pixel and
// tile, and on request both sides' R, G, B means.
#include "comparison.h"
#include "mcstat/image/spec/image_spec.h"

namespace mcstat::detail {

void Comparison::buildMaps() {
    const bool tiles = T_ > 0;
    const bool equivalence = opt_.test == TwoSampleTest::Equivalence;
    std::vector<std::string> names;
    for (const Quantity& q : q_) {
        for (const char* m : {"p", "z", "effect", "differs"}) names.push_back(m + q.suffix);
        if (tiles)
            for (const char* m : {"tile.p", "tile.z", "tile.differs"})
                names.push_back(m + q.suffix);
    }
    const OIIO::ROI data(out_.originX, out_.originX + out_.width, out_.originY,
                         out_.originY + out_.height, 0, 1, 0, int(names.size()));
    const OIIO::ImageSpec spec = floatSpec(data, names);
    out_.maps.reset(spec, OIIO::InitializePixels::No);
    const size_t C = names.size(), W = size_t(out_.width);
    auto flag = [&](float p, double thr) {
        if (std::isnan(p)) return kNaNf;
        const bool rejected = double(p) <= thr;
        return (equivalence ? !rejected : rejected) ? 1.f : 0.f;
    };
    std::vector<float> row(W * C);
    for (int y = 0; y < out_.height; ++y) {
        for (size_t x = 0; x < W; ++x) {
            const size_t p = size_t(y) * W + x;
            const size_t t =
                tiles ? size_t(y / out_.tile) * size_t(tilesX_) + x / size_t(out_.tile) : 0;
            float* o = &row[x * C];
            for (size_t qi = 0; qi < q_.size(); ++qi) {
                const size_t h = qi * P_ + p;
                *o++ = p_[h];
                *o++ = z_[h];
                *o++ = effect_[h];
                *o++ = flag(p_[h], out_.threshold);
                if (tiles) {
                    const size_t ht = qi * T_ + t;
                    *o++ = tileP_[ht];
                    *o++ = tileZ_[ht];
                    *o++ = flag(tileP_[ht], out_.tileThreshold);
                }
            }
        }
        const OIIO::ROI r(out_.originX, out_.originX + out_.width, out_.originY + y,
                          out_.originY + y + 1, 0, 1, 0, int(C));
        out_.maps.set_pixels(r, OIIO::TypeFloat, row.data());
    }
}

void Comparison::buildMeans() {
    if (!opt_.keepMeans) return;
    const OIIO::ROI data(out_.originX, out_.originX + out_.width, out_.originY,
                         out_.originY + out_.height, 0, 1, 0, 3);
    for (auto [img, v] : {std::pair{&out_.meanA, &meanA_}, std::pair{&out_.meanB, &meanB_}}) {
        img->reset(floatSpec(data, {"R", "G", "B"}), OIIO::InitializePixels::No);
        img->set_pixels(data, OIIO::TypeFloat, v->data());
    }
}

}  // namespace mcstat::detail
