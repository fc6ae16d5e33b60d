// The window family's kernel and its two passes (window_kernel.h).
#include "mcstat/filters/window/window_kernel.h"

#include <algorithm>

#include "mcstat/core/parallel.h"
#include "mcstat/filters/window/filter3d.h"
#include "mcstat/filters/window/mif.h"

namespace mcstat {

namespace {

/// WMIF / MIF over an RGB image: nothing to prepare, each pixel's window read where it lies.
class ImageWindowPass final : public WindowPass {
  public:
    ImageWindowPass(const RGBImageView& image, const SpatialParams& params)
        : image_(image), params_(params) {}
    std::unique_ptr<WindowScratch> newScratch() const override {
        return std::make_unique<SpatialScratch>();
    }
    void filterPixel(int x, int y, PixelEstimate& out, WindowScratch& s) const override {
        wmifPixel(image_, x, y, params_, out, static_cast<SpatialScratch&>(s));
    }

  private:
    RGBImageView image_;
    SpatialParams params_;
};

/// The 3D filters over sub-buffers: every pixel the output rectangle's windows reach is sorted
/// once (eq. 5.24) before any output pixel merges its window's lists.
class BufferWindowPass final : public WindowPass {
  public:
    BufferWindowPass(const BufferView& view, const SpatialParams& params, int x0, int y0, int x1,
                     int y1, int nthreads) {
        const int rx = params.windowWidth / 2, ry = params.windowHeight / 2;
        const int gx0 = std::max(0, x0 - rx), gx1 = std::min(view.width, x1 + rx);
        const int gy0 = std::max(0, y0 - ry), gy1 = std::min(view.height, y1 + ry);
        grid_.reset(view, params, gx0, gy0, gx1, gy1);
        if (gx1 <= gx0 || gy1 <= gy0) return;
        // Rows in chunks as threads free up: each pixel's ranking depends on nothing else, so the
        // result does not depend on the thread count.
        parallelFor(gy0, gy1, 0, nthreads, [&](int64_t ya, int64_t yb) {
            SpatialScratch scratch;
            grid_.sortRect(gx0, int(ya), gx1, int(yb), scratch);
        });
    }
    std::unique_ptr<WindowScratch> newScratch() const override {
        return std::make_unique<SpatialScratch>();
    }
    void filterPixel(int x, int y, PixelEstimate& out, WindowScratch& s) const override {
        grid_.filterPixel(x, y, out, static_cast<SpatialScratch&>(s));
    }

  private:
    RankedBufferGrid grid_;
};

}  // namespace

WindowKernel windowKernel(Neighbourhood over, const SpatialParams& params) {
    WindowKernel k;
    k.over = over;
    k.name = over == Neighbourhood::SubBuffers ? "3D filter" : "median image filter";
    k.mode = params.mode;
    k.halo[0] = params.windowWidth / 2;
    k.halo[1] = params.windowHeight / 2;
    k.check = [params](std::string& err) { return validateSpatialParams(params, err); };
    k.begin = [over, params](const WindowInput& in, int x0, int y0, int x1, int y1, int nthreads,
                             std::string& err) -> std::unique_ptr<WindowPass> {
        if (!validateSpatialParams(params, err)) return nullptr;
        if (over == Neighbourhood::Image && in.image)
            return std::make_unique<ImageWindowPass>(*in.image, params);
        if (over == Neighbourhood::SubBuffers && in.buffers)
            return std::make_unique<BufferWindowPass>(*in.buffers, params, x0, y0, x1, y1,
                                                      nthreads);
        err = over == Neighbourhood::SubBuffers ? "needs the sub-buffers of a statistics file"
                                                : "needs an RGB image";
        return nullptr;
    };
    return k;
}

}  // namespace mcstat
