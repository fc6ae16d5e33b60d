// Drives the integrator over the image: one task per row, each pixel accumulated by a single
// thread in sample order, so the result does not depend on scheduling or thread count.
#include "mcstat/render/render.h"

#include <OpenImageIO/parallel.h>
#include <OpenImageIO/thread.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "accel.h"
#include "camera.h"
#include "film.h"
#include "integrator.h"
#include "lights.h"
#include "progress.h"
#include "rng.h"

namespace mcstat::render {

namespace {

int resolveThreads(int requested) {
    if (requested > 0) return requested;
    const unsigned hw = std::thread::hardware_concurrency();
    return hw > 0 ? int(hw) : 1;
}

/// Everything a render needs besides its output, built once per render.
struct RenderContext {
    const Scene& scene;
    Accel accel;
    LightSet lights;
    Camera camera;
    PathIntegrator integrator;

    explicit RenderContext(const Scene& s)
        : scene(s), lights(s), camera(s.camera, s.width, s.height), integrator(s, accel, lights) {}

    /// The camera sample `index` of pixel (x, y): box filter, jittered uniformly in the pixel.
    PathSample samplePixel(uint64_t seed, int x, int y, int64_t index) const {
        const uint64_t pixel = uint64_t(y) * uint64_t(scene.width) + uint64_t(x);
        Pcg32 rng = sampleRng(seed, pixel, uint64_t(index));
        const double jx = rng.uniform(), jy = rng.uniform();
        return integrator.trace(camera.generateRay(x + jx, y + jy), rng);
    }
};

/// Runs rowTask(y) for every row on `threads` threads (caller included), with progress.
template <typename RowTask>
double forEachRow(int height, const RenderOptions& opt, RowTask&& rowTask) {
    const auto start = std::chrono::steady_clock::now();
    const int threads = resolveThreads(opt.threads);
    Progress progress(height, opt.progress);
    auto task = [&](int64_t y0, int64_t y1) {
        for (int64_t y = y0; y < y1; ++y) {
            rowTask(int(y));
            progress.advance();
        }
    };
    if (threads == 1) {
        task(0, height);
    } else {
        // A private pool sized exactly: the caller plus threads-1 workers. Rows are handed out one
        // at a time, which balances rows of very different cost (glass vs. background).
        OIIO::thread_pool pool(threads - 1);
        OIIO::parallel_for_chunked(0, height, 1, task,
                                   OIIO::paropt(threads, OIIO::paropt::SplitDir::Y, 1).pool(&pool));
    }
    progress.finish();
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

bool validateOptions(const RenderOptions& opt, std::string& err) {
    if (opt.spp < 1) {
        err = "spp must be at least 1 (got " + std::to_string(opt.spp) + ")";
        return false;
    }
    if (opt.M < 1 || opt.M > kMaxBuffers) {
        err = "M must be between 1 and " + std::to_string(kMaxBuffers) + " (got " +
              std::to_string(opt.M) + ")";
        return false;
    }
    if (opt.threads < 0) {
        err = "threads must be 0 (all cores) or positive (got " + std::to_string(opt.threads) + ")";
        return false;
    }
    return true;
}

bool render(const Scene& scene, const RenderOptions& opt, StatsImage& out, std::string& err,
            RenderStats* stats) {
    if (!validateOptions(opt, err)) return false;
    const uint64_t cells = uint64_t(scene.width) * uint64_t(scene.height) * uint64_t(opt.M);
    if (scene.width < 1 || scene.height < 1 || cells > (uint64_t(1) << 30)) {
        err = scene.source + ": image of " + std::to_string(scene.width) + "x" +
              std::to_string(scene.height) + " with M=" + std::to_string(opt.M) +
              " is out of range";
        return false;
    }
    RenderContext ctx(scene);
    if (!ctx.accel.build(scene, err)) return false;

    StatsImage img;
    StatsHeader& h = img.header;
    h.width = scene.width;
    h.height = scene.height;
    h.M = opt.M;
    h.spp = opt.spp;
    h.assignment = "roundrobin";
    h.renderer = kRendererName;
    h.colorSpace = "lin_rec709";
    h.seeds = std::to_string(opt.seed);
    if (!img.allocate(err)) return false;

    std::atomic<int64_t> dropped{0};
    const double seconds = forEachRow(scene.height, opt, [&](int y) {
        PixelAccumulator acc(opt.M);
        int64_t rowDropped = 0;
        for (int x = 0; x < scene.width; ++x) {
            acc.reset();
            for (int64_t i = 0; i < opt.spp; ++i)
                if (!acc.add(i, ctx.samplePixel(opt.seed, x, y, i))) ++rowDropped;
            acc.store(img, size_t(y) * size_t(scene.width) + size_t(x));
        }
        dropped.fetch_add(rowDropped, std::memory_order_relaxed);
    });
    out = std::move(img);
    if (stats) {
        stats->nonFiniteSamples = dropped.load();
        stats->seconds = seconds;
    }
    return true;
}

bool renderReference(const Scene& scene, const RenderOptions& opt, std::vector<float>& rgb,
                     std::string& err, RenderStats* stats) {
    if (!validateOptions(opt, err)) return false;
    if (scene.width < 1 || scene.height < 1 ||
        uint64_t(scene.width) * uint64_t(scene.height) > (uint64_t(1) << 30)) {
        err = scene.source + ": image size out of range";
        return false;
    }
    RenderContext ctx(scene);
    if (!ctx.accel.build(scene, err)) return false;

    rgb.assign(size_t(scene.width) * size_t(scene.height) * 3, 0.0f);
    std::atomic<int64_t> dropped{0};
    const double seconds = forEachRow(scene.height, opt, [&](int y) {
        int64_t rowDropped = 0;
        for (int x = 0; x < scene.width; ++x) {
            MeanAccumulator acc;
            for (int64_t i = 0; i < opt.spp; ++i)
                if (!acc.add(ctx.samplePixel(opt.seed, x, y, i).L)) ++rowDropped;
            acc.store(&rgb[(size_t(y) * size_t(scene.width) + size_t(x)) * 3]);
        }
        dropped.fetch_add(rowDropped, std::memory_order_relaxed);
    });
    if (stats) {
        stats->nonFiniteSamples = dropped.load();
        stats->seconds = seconds;
    }
    return true;
}

}  // namespace mcstat::render
