// Drives the integrator over the image: one task per row, each pixel accumulated by a single
// thread in sample order, so the result does not depend on scheduling or thread count.
// Adaptive M (docs/adaptive-m.md): a pilot pass over all rows, a sequential reduction of
// sigma_image, then the main pass with each pixel's own buffer count.
#include "mcstat/render/render.h"

#include <OpenImageIO/parallel.h>
#include <OpenImageIO/thread.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
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

/// Per-pixel luminance statistics of the pilot (Welford), written by the one thread that renders
/// the pixel's row.
struct PilotPixel {
    int64_t n = 0;
    double mean = 0, m2 = 0;
};

bool planAdaptive(const RenderContext& ctx, const RenderOptions& opt, AdaptivePlan& plan,
                  std::string& err);

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
    if (opt.adaptiveM) {
        if (opt.mMax < 1 || opt.mMax > kMaxBuffers || opt.mMax % 2 == 0) {
            err = "m-max must be odd and between 1 and " + std::to_string(kMaxBuffers) +
                  " (eq. 4.15 gives odd buffer counts; got " + std::to_string(opt.mMax) + ")";
            return false;
        }
        if (opt.pilotSpp < 0) {
            err = "pilot must be at least 1 sample per pixel, or 0 for the default (got " +
                  std::to_string(opt.pilotSpp) + ")";
            return false;
        }
    }
    return true;
}

int adaptiveBufferCount(double sigmaPixel, double sigmaImage, int mMax) {
    if (!(sigmaPixel > 0.0)) return 1;     // no spread (0; NaN cannot reach here but stays safe)
    if (!(sigmaImage > 0.0)) return mMax;  // infinite ratio
    const double ratio = sigmaPixel / sigmaImage;
    if (ratio < 1.0) return 1;
    if (!std::isfinite(ratio)) return mMax;
    const int64_t n = 2 * (int64_t(std::ilogb(ratio)) + 1) + 1;  // ilogb = floor(log2), exact
    return int(std::min<int64_t>(n, mMax));
}

int64_t pilotSamples(const RenderOptions& opt) {
    if (opt.pilotSpp > 0) return opt.pilotSpp;
    return std::min<int64_t>(opt.spp, std::max<int64_t>(64, opt.spp / 8));
}

bool planAdaptive(const Scene& scene, const RenderOptions& opt, AdaptivePlan& plan,
                  std::string& err) {
    RenderOptions o = opt;
    o.adaptiveM = true;
    if (!validateOptions(o, err)) return false;
    RenderContext ctx(scene);
    if (!ctx.accel.build(scene, err)) return false;
    return planAdaptive(ctx, o, plan, err);
}

namespace {

bool planAdaptive(const RenderContext& ctx, const RenderOptions& opt, AdaptivePlan& plan,
                  std::string& err) {
    const Scene& scene = ctx.scene;
    const size_t pixels = size_t(scene.width) * size_t(scene.height);
    AdaptivePlan r;
    r.pilotSamples = pilotSamples(opt);
    std::vector<PilotPixel> pilot;
    try {
        pilot.resize(pixels);
        r.sigmaPixel.resize(pixels);
        r.buffers.resize(pixels);
    } catch (const std::exception& e) {
        err = std::string("cannot allocate the pilot: ") + e.what();
        return false;
    }
    // Pass 1: every pixel's statistics, each pixel by one thread, no shared accumulator.
    forEachRow(scene.height, opt, [&](int y) {
        for (int x = 0; x < scene.width; ++x) {
            PilotPixel& px = pilot[size_t(y) * size_t(scene.width) + size_t(x)];
            for (int64_t i = 0; i < r.pilotSamples; ++i) {
                const Vec3 L = ctx.samplePixel(opt.pilotSeed, x, y, i).L;
                if (!isFinite(L)) continue;
                const double v = kPilotLuma[0] * L[0] + kPilotLuma[1] * L[1] + kPilotLuma[2] * L[2];
                ++px.n;
                const double d = v - px.mean;
                px.mean += d / double(px.n);
                px.m2 += d * (v - px.mean);
            }
        }
    });
    // Pass 2, after every thread has finished: sigma_image, the mean of the pixels' standard
    // deviations, summed in pixel order on this thread, so it is the same for any thread count and
    // no thread ever updates it (docs/adaptive-m.md says why the mean and not the pooled one).
    double sum = 0;
    for (size_t p = 0; p < pixels; ++p) {
        const PilotPixel& px = pilot[p];
        r.sigmaPixel[p] = px.n > 1 ? std::sqrt(px.m2 / double(px.n - 1)) : 0.0;
        sum += r.sigmaPixel[p];
    }
    r.sigmaImage = sum / double(pixels);
    for (size_t p = 0; p < pixels; ++p)
        r.buffers[p] = uint32_t(adaptiveBufferCount(r.sigmaPixel[p], r.sigmaImage, opt.mMax));
    plan = std::move(r);
    return true;
}

}  // namespace

bool render(const Scene& scene, const RenderOptions& opt, StatsImage& out, std::string& err,
            RenderStats* stats) {
    if (!validateOptions(opt, err)) return false;
    const int M = opt.adaptiveM ? opt.mMax : opt.M;
    const uint64_t cells = uint64_t(scene.width) * uint64_t(scene.height) * uint64_t(M);
    if (scene.width < 1 || scene.height < 1 || cells > (uint64_t(1) << 30)) {
        err = scene.source + ": image of " + std::to_string(scene.width) + "x" +
              std::to_string(scene.height) + " with M=" + std::to_string(M) + " is out of range";
        return false;
    }
    RenderContext ctx(scene);
    if (!ctx.accel.build(scene, err)) return false;

    AdaptivePlan plan;
    double pilotSeconds = 0;
    if (opt.adaptiveM) {
        const auto start = std::chrono::steady_clock::now();
        if (!planAdaptive(ctx, opt, plan, err)) return false;
        pilotSeconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }

    StatsImage img;
    StatsHeader& h = img.header;
    h.width = scene.width;
    h.height = scene.height;
    h.M = M;
    h.spp = opt.spp;
    h.assignment = "roundrobin";
    h.renderer = kRendererName;
    h.colorSpace = "lin_rec709";
    h.seeds = std::to_string(opt.seed);
    if (opt.adaptiveM) {
        h.formatVersion = kStatsFormatVersionAdaptive;
        std::vector<uint32_t> buffers = std::move(plan.buffers);
        if (!img.allocateAdaptive(buffers, err)) return false;
    } else if (!img.allocate(err)) {
        return false;
    }

    std::atomic<int64_t> dropped{0};
    const double seconds = forEachRow(scene.height, opt, [&](int y) {
        PixelAccumulator acc(M);
        int64_t rowDropped = 0;
        for (int x = 0; x < scene.width; ++x) {
            // Sample i goes to buffer i mod M_p: exactly a fixed-M render with M = M_p here.
            acc.reset(img.buffersOf(size_t(y) * size_t(scene.width) + size_t(x)));
            for (int64_t i = 0; i < opt.spp; ++i)
                if (!acc.add(i, ctx.samplePixel(opt.seed, x, y, i))) ++rowDropped;
            acc.store(img, size_t(y) * size_t(scene.width) + size_t(x));
        }
        dropped.fetch_add(rowDropped, std::memory_order_relaxed);
    });
    if (stats) {
        stats->nonFiniteSamples = dropped.load();
        stats->seconds = seconds + pilotSeconds;
        stats->pilotSeconds = pilotSeconds;
        if (opt.adaptiveM) {
            stats->sigmaImage = plan.sigmaImage;
            stats->pilotSamples = plan.pilotSamples;
            stats->meanBuffers = double(img.bufferCount.size()) / double(img.pixelCount());
        }
    }
    out = std::move(img);
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
