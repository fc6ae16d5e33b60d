// Drives the integrator over the image: one task per row, each pixel accumulated by a single
// thread in sample order, so the result does not depend on scheduling or thread count.
// Adaptive M (docs/adaptive-m.md), two strategies. Grow: the render runs in rounds separated by
// checkpoints; at each, sigma_image is reduced sequentially and buffer counts grow. Pilot: a pilot
// pass over all rows, a sequential reduction of sigma_image, then the main pass with each pixel's
// own buffer count.
#include "mcstat/render-fixture/render.h"

#include <OpenImageIO/parallel.h>
#include <OpenImageIO/thread.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <thread>

#include "accel.h"
#include "camera.h"
#include "film.h"
#include "integrator.h"
#include "lights.h"
#include "mcstat/core/parallel.h"
#include "mcstat/core/params.h"
#include "mcstat/core/progress.h"
#include "rng.h"

namespace mcstat::render {

using mcstat::Progress;

namespace {

/// Everything a render needs besides its output, built once per render.
struct RenderContext {
    const Scene& scene;
    Accel accel;
    LightSet lights;
    Camera camera;
    PathIntegrator integrator;
    double clamp = 0.0;  ///< RenderOptions::clamp

    RenderContext(const Scene& s, const RenderOptions& opt)
        : scene(s),
          lights(s),
          camera(s.camera, s.width, s.height, s.hasMotion()),
          integrator(s, accel, lights),
          clamp(opt.clamp) {}

    /// The camera sample `index` of pixel (x, y): box filter, jittered uniformly in the pixel;
    /// then, only with a lens, the lens point; then, only with motion, the time (Camera::sample).
    PathSample samplePixel(uint64_t seed, int x, int y, int64_t index) const {
        PathSample s =
            mcstat::render::samplePixel(camera, integrator, scene.width, seed, x, y, index);
        clampSample(s, clamp);
        return s;
    }
};

/// Runs rowTask(y) for every row on `threads` threads (caller included), advancing `progress` by
/// `unitsPerRow` per row. Returns the wall-clock seconds.
template <typename RowTask>
double forEachRow(int height, const RenderOptions& opt, Progress& progress, int64_t unitsPerRow,
                  RowTask&& rowTask) {
    const auto start = std::chrono::steady_clock::now();
    // Rows are handed out one at a time, which balances rows of very different cost (glass vs.
    // background).
    mcstat::parallelFor(0, height, 1, opt.threads, [&](int64_t y0, int64_t y1) {
        for (int64_t y = y0; y < y1; ++y) {
            rowTask(int(y));
            progress.advance(unitsPerRow);
        }
    });
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// One pass over every row with its own progress line.
template <typename RowTask>
double forEachRow(int height, const RenderOptions& opt, RowTask&& rowTask) {
    Progress progress("rendering", height, opt.progress);
    const double seconds = forEachRow(height, opt, progress, 1, rowTask);
    progress.finish();
    return seconds;
}

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
    if (opt.aovs && opt.adaptiveM) {
        err = "AOVs need a fixed M: the statistics file's part aovs holds M buffers per pixel";
        return false;
    }
    if (opt.adaptiveM) {
        if (opt.mMax < 1 || opt.mMax > kMaxBuffers || opt.mMax % 2 == 0) {
            err = "m-max must be odd and between 1 and " + std::to_string(kMaxBuffers) +
                  " (eq. 4.15 gives odd buffer counts; got " + std::to_string(opt.mMax) + ")";
            return false;
        }
        if (opt.checkpoint < 0 || opt.checkpoint == 1) {
            err =
                "checkpoint must be at least 2 samples per pixel (a standard deviation needs "
                "two), or 0 for the default (got " +
                std::to_string(opt.checkpoint) + ")";
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

int growCap(int64_t spp, int64_t maxCount, int mMax) {
    if (maxCount <= 0) return mMax;
    const int64_t cap = std::min<int64_t>(spp / maxCount, mMax);
    if (cap < 1) return 1;  // already over-full (spp below what was taken): no growth
    return int(cap % 2 == 1 ? cap : cap - 1);
}

int grownBufferCount(int current, double sigmaPixel, double sigmaImage, int mMax, int64_t spp,
                     int64_t maxCount) {
    const int want =
        std::min(adaptiveBufferCount(sigmaPixel, sigmaImage, mMax), growCap(spp, maxCount, mMax));
    return std::max(current, want);
}

std::vector<int64_t> growCheckpoints(const RenderOptions& opt) {
    std::vector<int64_t> out;
    if (opt.mMax <= 1) return out;
    const int64_t n0 =
        std::max<int64_t>(2, opt.checkpoint > 0 ? opt.checkpoint : opt.spp / opt.mMax);
    int64_t n = n0;
    while (n < opt.spp) {
        out.push_back(n);
        n = n > opt.spp / 2 ? opt.spp : 2 * n;  // doubling without overflow
    }
    return out;
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
    RenderContext ctx(scene, opt);
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
    // Per-pixel luminance statistics, each written only by the one thread rendering its row.
    std::vector<RunningVariance> pilot;
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
            RunningVariance& px = pilot[size_t(y) * size_t(scene.width) + size_t(x)];
            for (int64_t i = 0; i < r.pilotSamples; ++i) {
                const Vec3 L = ctx.samplePixel(opt.pilotSeed, x, y, i).L;
                if (isFinite(L)) px.add(sigmaLuma(L));
            }
        }
    });
    // Pass 2, after every thread has finished: sigma_image, the mean of the pixels' standard
    // deviations, summed in pixel order on this thread, so it is the same for any thread count and
    // no thread ever updates it (docs/adaptive-m.md says why the mean and not the pooled one).
    double sum = 0;
    for (size_t p = 0; p < pixels; ++p) {
        r.sigmaPixel[p] = pilot[p].sigma();
        sum += r.sigmaPixel[p];
    }
    r.sigmaImage = sum / double(pixels);
    for (size_t p = 0; p < pixels; ++p)
        r.buffers[p] = uint32_t(adaptiveBufferCount(r.sigmaPixel[p], r.sigmaImage, opt.mMax));
    plan = std::move(r);
    return true;
}

}  // namespace

namespace {

/// The header every render writes; the caller allocates the arrays.
StatsImage newStatsImage(const Scene& scene, const RenderOptions& opt, int M) {
    StatsImage img;
    StatsHeader& h = img.header;
    h.width = scene.width;
    h.height = scene.height;
    h.M = M;
    h.spp = opt.spp;
    h.assignment =
        opt.adaptiveM && opt.strategy == AdaptiveStrategy::Grow ? "leastcount" : "roundrobin";
    h.renderer = kRendererName;
    h.scene = scene.identity;
    if (opt.clamp > 0.0) h.scene += " clamp " + mcstat::realText(opt.clamp);
    h.colorSpace = kRenderColorSpace;
    h.seeds = std::to_string(opt.seed);
    if (opt.adaptiveM) h.formatVersion = kStatsFormatVersionAdaptive;
    if (opt.aovs) {
        h.aovs = fixtureAovChannels();
        h.formatVersion = std::max(h.formatVersion, kStatsFormatVersionAovs);
    }
    return img;
}

/// The online run of a render (RenderExtras::online), or none.
struct OnlineFeed {
    OnlineRun* run = nullptr;
    bool on() const { return run != nullptr; }
    void add(size_t p, const Vec3& L) {
        const float rgb[3] = {float(L[0]), float(L[1]), float(L[2])};
        run->add(p, rgb);  // refuses non-finite values (the renderer counts those)
    }
};

}  // namespace

std::vector<AovChannel> fixtureAovChannels() {
    std::vector<AovChannel> out;
    AovChannel a;
    a.name = "A";
    a.cls = AovClass::Alpha;
    out.push_back(a);
    for (int i = 0; i < kLightPathAovs; ++i)
        for (const char* c : {".R", ".G", ".B"}) {
            a.name = std::string(lightPathAovName(i)) + c;
            a.cls = AovClass::Light;
            out.push_back(a);
        }
    return out;
}

std::vector<std::string> recordFieldsFor(const Scene& scene) {
    std::vector<std::string> f{"screen"};
    if (scene.hasLens()) f.emplace_back("lens");
    if (scene.hasMotion()) f.emplace_back("time");
    for (const char* name : {"light", "bounce", "N1", "P1", "T1", "N2", "P2"}) f.emplace_back(name);
    return f;
}

namespace {

/// Samples of one row for the records: counts per pixel, the record channels per sample.
struct RowRecords {
    std::vector<uint32_t> counts;
    std::vector<float> samples;
};

/// What a record channel holds, resolved once from its name.
enum class RecordValue {
    R,
    G,
    B,
    Z,
    ScreenX,
    ScreenY,
    LensU,
    LensV,
    Time,
    LightU,
    LightV,
    BounceU,
    BounceV,
    N1x,
    N1y,
    N1z,
    P1x,
    P1y,
    P1z,
    T1r,
    T1g,
    T1b,
    N2x,
    N2y,
    N2z,
    P2x,
    P2y,
    P2z,
    Aov0  ///< Aov0 + a: channel a of fixtureAovChannels()
};

bool recordValueOf(const std::string& channel, RecordValue& v) {
    static const std::pair<const char*, RecordValue> kNames[] = {
        {"R", RecordValue::R},
        {"G", RecordValue::G},
        {"B", RecordValue::B},
        {"Z", RecordValue::Z},
        {"screen.x", RecordValue::ScreenX},
        {"screen.y", RecordValue::ScreenY},
        {"rand.lens.u", RecordValue::LensU},
        {"rand.lens.v", RecordValue::LensV},
        {"rand.time", RecordValue::Time},
        {"rand.light.u", RecordValue::LightU},
        {"rand.light.v", RecordValue::LightV},
        {"rand.bounce.u", RecordValue::BounceU},
        {"rand.bounce.v", RecordValue::BounceV},
        {"N1.X", RecordValue::N1x},
        {"N1.Y", RecordValue::N1y},
        {"N1.Z", RecordValue::N1z},
        {"P1.X", RecordValue::P1x},
        {"P1.Y", RecordValue::P1y},
        {"P1.Z", RecordValue::P1z},
        {"T1.R", RecordValue::T1r},
        {"T1.G", RecordValue::T1g},
        {"T1.B", RecordValue::T1b},
        {"N2.X", RecordValue::N2x},
        {"N2.Y", RecordValue::N2y},
        {"N2.Z", RecordValue::N2z},
        {"P2.X", RecordValue::P2x},
        {"P2.Y", RecordValue::P2y},
        {"P2.Z", RecordValue::P2z},
    };
    for (const auto& [name, value] : kNames)
        if (channel == name) {
            v = value;
            return true;
        }
    const std::string prefix = kRecordAovPrefix;
    if (channel.compare(0, prefix.size(), prefix) == 0) {
        const std::vector<AovChannel> aovs = fixtureAovChannels();
        for (size_t a = 0; a < aovs.size(); ++a)
            if (channel.substr(prefix.size()) == aovs[a].name) {
                v = static_cast<RecordValue>(int(RecordValue::Aov0) + int(a));
                return true;
            }
    }
    return false;
}

/// One sample's value of channel `v`, as float32 (features are 0 where the path has no hit);
/// `aov` holds the sample's fixtureAovValues.
float recordValue(const PathSample& s, RecordValue v, const double* aov) {
    if (int(v) >= int(RecordValue::Aov0)) return float(aov[int(v) - int(RecordValue::Aov0)]);
    switch (v) {
        case RecordValue::R:
            return float(s.L[0]);
        case RecordValue::G:
            return float(s.L[1]);
        case RecordValue::B:
            return float(s.L[2]);
        case RecordValue::Z:
            return s.hit ? float(s.depth) : std::numeric_limits<float>::infinity();
        case RecordValue::ScreenX:
            return float(s.screenX);
        case RecordValue::ScreenY:
            return float(s.screenY);
        case RecordValue::LensU:
            return float(s.lensU);
        case RecordValue::LensV:
            return float(s.lensV);
        case RecordValue::Time:
            return float(s.time);
        case RecordValue::LightU:
            return float(s.lightU);
        case RecordValue::LightV:
            return float(s.lightV);
        case RecordValue::BounceU:
            return float(s.bounceU);
        case RecordValue::BounceV:
            return float(s.bounceV);
        case RecordValue::N1x:
            return s.hit ? float(s.normal.x) : 0.f;
        case RecordValue::N1y:
            return s.hit ? float(s.normal.y) : 0.f;
        case RecordValue::N1z:
            return s.hit ? float(s.normal.z) : 0.f;
        case RecordValue::P1x:
            return s.hit ? float(s.position.x) : 0.f;
        case RecordValue::P1y:
            return s.hit ? float(s.position.y) : 0.f;
        case RecordValue::P1z:
            return s.hit ? float(s.position.z) : 0.f;
        case RecordValue::T1r:
            return s.hit ? float(s.albedo.x) : 0.f;
        case RecordValue::T1g:
            return s.hit ? float(s.albedo.y) : 0.f;
        case RecordValue::T1b:
            return s.hit ? float(s.albedo.z) : 0.f;
        case RecordValue::N2x:
            return s.hit2 ? float(s.normal2.x) : 0.f;
        case RecordValue::N2y:
            return s.hit2 ? float(s.normal2.y) : 0.f;
        case RecordValue::N2z:
            return s.hit2 ? float(s.normal2.z) : 0.f;
        case RecordValue::P2x:
            return s.hit2 ? float(s.position2.x) : 0.f;
        case RecordValue::P2y:
            return s.hit2 ? float(s.position2.y) : 0.f;
        case RecordValue::P2z:
            return s.hit2 ? float(s.position2.z) : 0.f;
        default:
            break;
    }
    return 0.f;
}

/// Fixed M, or adaptive M with a pilot plan: every pixel rendered in one go, sample i into
/// buffer i mod M_p. With records, rows are rendered by blocks and each block handed to the sink
/// in order, so memory holds one block of samples, never the image's. Returns false only when
/// the sink fails.
bool renderRoundRobin(const RenderContext& ctx, const RenderOptions& opt, StatsImage& img,
                      std::atomic<int64_t>& dropped, OnlineFeed& online,
                      const std::function<bool(const SampleBlock&, std::string&)>& records,
                      const std::vector<std::string>* recordChannels, double& seconds,
                      std::string& err) {
    const Scene& scene = ctx.scene;
    const int64_t first = opt.firstSample, end = opt.firstSample + opt.spp;
    static const std::vector<std::string> kBase{"R", "G", "B", "Z"};
    const std::vector<std::string>& channels = recordChannels ? *recordChannels : kBase;
    std::vector<RecordValue> values(channels.size());
    for (size_t c = 0; c < channels.size(); ++c)
        if (!recordValueOf(channels[c], values[c])) {
            err = "per-sample records: the renderer cannot fill channel '" + channels[c] + "'";
            return false;
        }
    const bool recordAovs = std::any_of(values.begin(), values.end(), [](RecordValue v) {
        return int(v) >= int(RecordValue::Aov0);
    });
    auto renderRow = [&](int y, RowRecords* rec) {
        PixelAccumulator acc(img.header.M, !img.header.aovs.empty());
        double aov[kFixtureAovFloats] = {};
        int64_t rowDropped = 0;
        if (rec) {
            rec->counts.assign(size_t(scene.width), uint32_t(opt.spp));
            rec->samples.clear();
            rec->samples.reserve(size_t(scene.width) * size_t(opt.spp) * values.size());
        }
        for (int x = 0; x < scene.width; ++x) {
            const size_t p = size_t(y) * size_t(scene.width) + size_t(x);
            // Sample i goes to buffer i mod M_p: exactly a fixed-M render with M = M_p here.
            acc.reset(img.buffersOf(p));
            for (int64_t i = first; i < end; ++i) {
                const PathSample s = ctx.samplePixel(opt.seed, x, y, i);
                if (!acc.add(i, s)) ++rowDropped;
                if (online.on()) online.add(p, s.L);
                if (rec) {
                    if (recordAovs) fixtureAovValues(s, aov);
                    for (RecordValue v : values) rec->samples.push_back(recordValue(s, v, aov));
                }
            }
            acc.store(img, p);
        }
        dropped.fetch_add(rowDropped, std::memory_order_relaxed);
    };
    if (!records) {
        seconds = forEachRow(scene.height, opt, [&](int y) { renderRow(y, nullptr); });
        return true;
    }
    // Blocks of rows: at least one row per thread, at most 64 rows or 256 MiB of samples.
    const double rowBytes =
        double(scene.width) * double(opt.spp) * double(values.size()) * sizeof(float);
    const int rows = int(std::clamp(std::floor(double(256 << 20) / rowBytes),
                                    double(mcstat::threadCount(opt.threads)), 64.0));
    Progress progress("rendering", scene.height, opt.progress);
    std::vector<RowRecords> block(static_cast<size_t>(rows));
    SampleBlock out;
    const auto start = std::chrono::steady_clock::now();
    for (int y0 = 0; y0 < scene.height; y0 += rows) {
        const int n = std::min(rows, scene.height - y0);
        forEachRow(n, opt, progress, 1, [&](int r) { renderRow(y0 + r, &block[size_t(r)]); });
        out.clear(y0, n, scene.width);
        out.channels = channels;
        for (int r = 0; r < n; ++r) {
            std::copy(block[size_t(r)].counts.begin(), block[size_t(r)].counts.end(),
                      out.counts.begin() + std::ptrdiff_t(r) * scene.width);
            out.samples.insert(out.samples.end(), block[size_t(r)].samples.begin(),
                               block[size_t(r)].samples.end());
        }
        if (!records(out, err)) return false;
    }
    progress.finish();
    seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return true;
}

/// Adaptive M growing during the render (docs/adaptive-m.md, "Grow"). The samples are rendered
/// in rounds ending at the checkpoints; within a round each pixel belongs to the one thread
/// rendering its row, and between rounds the calling thread alone reduces sigma_image (in pixel
/// order) and grows buffer counts, so nothing is shared while threads run and the result is
/// bit-identical for any thread count.
bool renderGrowing(const RenderContext& ctx, const RenderOptions& opt, StatsImage& img,
                   std::atomic<int64_t>& dropped, RenderStats& stats, OnlineFeed& online,
                   std::string& err) {
    const Scene& scene = ctx.scene;
    const size_t width = size_t(scene.width), pixels = width * size_t(scene.height);
    // One vector per row, so that each row's state is freed as soon as it is stored.
    std::vector<std::vector<GrowingPixel>> rows;
    try {
        rows.resize(size_t(scene.height));
        for (auto& row : rows) row.resize(width);
    } catch (const std::exception& e) {
        err = std::string("cannot allocate the pixel accumulators: ") + e.what();
        return false;
    }
    std::vector<int64_t> ends = growCheckpoints(opt);
    ends.push_back(opt.spp);
    Progress progress("rendering", int64_t(scene.height) * opt.spp, opt.progress);
    int64_t begin = 0;
    for (const int64_t end : ends) {
        stats.seconds += forEachRow(scene.height, opt, progress, end - begin, [&](int y) {
            int64_t rowDropped = 0;
            for (int x = 0; x < scene.width; ++x) {
                GrowingPixel& px = rows[size_t(y)][size_t(x)];
                const size_t p = size_t(y) * width + size_t(x);
                for (int64_t i = begin; i < end; ++i) {
                    const PathSample s = ctx.samplePixel(opt.seed, x, y, i);
                    if (!px.add(s)) ++rowDropped;
                    if (online.on()) online.add(p, s.L);
                }
            }
            dropped.fetch_add(rowDropped, std::memory_order_relaxed);
        });
        begin = end;
        if (end == opt.spp) break;
        // Checkpoint: every thread has joined. sigma_image = mean luminance sigma of all pixels
        // over all their samples so far, summed in pixel order on this thread.
        const auto start = std::chrono::steady_clock::now();
        GrowCheckpoint cp;
        cp.samples = end;
        double sum = 0;
        for (const auto& row : rows)
            for (const GrowingPixel& px : row) sum += px.luminance().sigma();
        cp.sigmaImage = sum / double(pixels);
        int64_t buffers = 0;
        for (auto& row : rows)
            for (GrowingPixel& px : row) {
                const int m = grownBufferCount(px.buffers(), px.luminance().sigma(), cp.sigmaImage,
                                               opt.mMax, opt.spp, px.maxBufferCount());
                if (m > px.buffers()) {
                    px.grow(m);
                    ++cp.grownPixels;
                }
                buffers += px.buffers();
            }
        cp.meanBuffers = double(buffers) / double(pixels);
        stats.checkpoints.push_back(cp);
        stats.sigmaImage = cp.sigmaImage;
        stats.seconds +=
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }
    progress.finish();

    std::vector<uint32_t> counts(pixels);
    for (size_t p = 0; p < pixels; ++p) counts[p] = uint32_t(rows[p / width][p % width].buffers());
    if (!img.allocateAdaptive(counts, err)) return false;
    for (size_t y = 0; y < rows.size(); ++y) {
        for (size_t x = 0; x < width; ++x) rows[y][x].store(img, y * width + x);
        std::vector<GrowingPixel>().swap(rows[y]);  // peak memory: the state or the image, not both
    }
    return true;
}

}  // namespace

bool render(const Scene& scene, const RenderOptions& opt, StatsImage& out, std::string& err,
            RenderStats* stats, RenderExtras* extras) {
    if (!validateOptions(opt, err)) return false;
    const bool growing = opt.adaptiveM && opt.strategy == AdaptiveStrategy::Grow;
    if (extras && extras->records && growing) {
        err =
            "per-sample records need every pixel's samples in one pass: use fixed M or "
            "--m-strategy pilot with --keep-samples";
        return false;
    }
    if (opt.firstSample != 0 && opt.adaptiveM) {
        err = "a resumed render (first sample > 0) needs fixed M";
        return false;
    }
    OnlineFeed online;
    if (extras) online.run = extras->online;
    const int M = opt.adaptiveM ? opt.mMax : opt.M;
    const uint64_t cells = uint64_t(scene.width) * uint64_t(scene.height) * uint64_t(M);
    if (scene.width < 1 || scene.height < 1 || cells > (uint64_t(1) << 30)) {
        err = scene.source + ": image of " + std::to_string(scene.width) + "x" +
              std::to_string(scene.height) + " with M=" + std::to_string(M) + " is out of range";
        return false;
    }
    RenderContext ctx(scene, opt);
    if (!ctx.accel.build(scene, err)) return false;

    RenderStats st;
    StatsImage img = newStatsImage(scene, opt, M);
    std::atomic<int64_t> dropped{0};
    if (growing) {
        if (!renderGrowing(ctx, opt, img, dropped, st, online, err)) return false;
    } else {
        if (opt.adaptiveM) {
            AdaptivePlan plan;
            const auto start = std::chrono::steady_clock::now();
            if (!planAdaptive(ctx, opt, plan, err)) return false;
            st.pilotSeconds =
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
            st.sigmaImage = plan.sigmaImage;
            st.pilotSamples = plan.pilotSamples;
            if (!img.allocateAdaptive(plan.buffers, err)) return false;
        } else if (!img.allocate(err)) {
            return false;
        }
        double seconds = 0;
        static const std::function<bool(const SampleBlock&, std::string&)> kNoRecords;
        if (!renderRoundRobin(ctx, opt, img, dropped, online,
                              extras && extras->records ? extras->records : kNoRecords,
                              extras ? &extras->recordChannels : nullptr, seconds, err))
            return false;
        st.seconds = seconds + st.pilotSeconds;
    }
    st.nonFiniteSamples = dropped.load();
    if (opt.adaptiveM) st.meanBuffers = double(img.bufferCount.size()) / double(img.pixelCount());
    if (stats) *stats = std::move(st);
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
    RenderContext ctx(scene, opt);
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
