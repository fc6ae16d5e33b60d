// Per-estimator throughput over a synthetic statistics image with fireflies, single-threaded, for
// several M. Items are pixels, so Google Benchmark reports pixel/s; scripts/bench.sh turns the
// results into ratios against the plain mean measured in the same run.
// Every operation of the registry is measured with its registry defaults: the per-pixel estimators,
// and the neighbourhood filters (Jung chapter 5; 3x3 windows by default): 3dmf, 3dwmf, 3dwtmf over
// the M buffers; mif and wmif over the mean image (computed outside the timing, so their cost does
// not depend on M). mpe+mif is the whole hybrid, MPE then MIF. Per-sample operations read a file
// and are not measured here. Names follow estimate/NAME/MODE/M as bench.sh expects.
#include <benchmark/benchmark.h>

#include <map>
#include <random>
#include <stdexcept>
#include <tuple>

#include "mcstat/color/color.h"
#include "mcstat/filters/registry.h"
#include "mcstat/image/imageops.h"
#include "mcstat/image/keep_light_image.h"
#include "mcstat/image/removed_light_layers.h"

using namespace mcstat;

namespace {

constexpr int kWidth = 256, kHeight = 256;

/// Buffer means of a noisy image where 1% of the buffers hold a firefly.
const StatsImage& syntheticImage(int M, int width = kWidth, int height = kHeight) {
    static std::map<std::tuple<int, int, int>, StatsImage> cache;
    const auto key = std::make_tuple(M, width, height);
    auto it = cache.find(key);
    if (it != cache.end()) return it->second;
    StatsImage s;
    s.header.width = width;
    s.header.height = height;
    s.header.M = M;
    std::string err;
    s.allocate(err);
    std::mt19937 rng(12345);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (size_t i = 0; i < s.bufferCount.size(); ++i) {
        const float firefly = u(rng) < 0.01f ? 1000.f : 1.f;
        for (int c = 0; c < 3; ++c) s.bufferMean[i * 3 + c] = (0.2f + 0.1f * u(rng)) * firefly;
        s.bufferCount[i] = 64.f;
    }
    return cache.emplace(key, std::move(s)).first->second;
}

/// `op`'s parameters: the registry's defaults with `mode`.
ParamValues defaults(const Operation& op, EstimatorMode mode) {
    ParamValues v;
    std::string err;
    std::map<std::string, std::string> kv;
    if (op.param("mode")) kv["mode"] = mode == EstimatorMode::Luminance ? "lum" : "channel";
    if (!parseOperationParams(op, kv, v, err)) throw std::runtime_error(err);
    return v;
}

void BM_Estimator(benchmark::State& state, const Operation* est, EstimatorMode mode) {
    const StatsImage& img = syntheticImage(int(state.range(0)));
    const PixelKernel kernel = est->bindPixel(defaults(*est, mode), lumaCoefficients());
    OIIO::ImageBuf out;
    for (auto _ : state) {
        estimate(out, img, *est, kernel, false, {}, 1);
        benchmark::DoNotOptimize(out.localpixels());
    }
    state.SetItemsProcessed(int64_t(state.iterations()) * kWidth * kHeight);
}

const std::vector<int64_t> kBufferCounts = {3, 7, 17, 21};

/// Thread scaling of the image loop: a 1920x1080 image, M = 21, luminance mode, with
/// state.range(0) threads; real time, so that 2 threads show as a speed-up. Names:
/// threads/NAME/1080p/THREADS.
void BM_EstimatorThreads(benchmark::State& state, const Operation* est) {
    constexpr int W = 1920, H = 1080;
    const StatsImage& img = syntheticImage(21, W, H);
    const PixelKernel kernel =
        est->bindPixel(defaults(*est, EstimatorMode::Luminance), lumaCoefficients());
    OIIO::ImageBuf out;
    for (auto _ : state) {
        estimate(out, img, *est, kernel, false, {}, int(state.range(0)));
        benchmark::DoNotOptimize(out.localpixels());
    }
    state.SetItemsProcessed(int64_t(state.iterations()) * W * H);
}

/// What the layers of issue 37 cost on top of an estimate (docs/confidence.md,
/// docs/removed-light.md): a 1920x1080 image, M = 21, luminance mode, all cores, real time. `what`:
/// "" the estimate alone, "ci" with its 0.95 confidence interval layers, "removed" with the
/// removed-light layers (radius 2, in the estimate's pass as applyOperation runs them), "keeplight"
/// with the removed light given back (keepLightEstimate, band by band, as applyOperation runs it;
/// docs/keep-light.md). Names:
/// layers/NAME[+ci|+removed|+keeplight]/1080p.
void BM_Layers(benchmark::State& state, const Operation* est, const std::string& what) {
    constexpr int W = 1920, H = 1080;
    const StatsImage& img = syntheticImage(21, W, H);
    ParamValues values = defaults(*est, EstimatorMode::Luminance);
    if (what == "ci") {
        ParamValue level;
        level.real = 0.95;
        level.text = "0.95";
        values["ci"] = level;
    }
    PixelKernel kernel = est->bindPixel(values, lumaCoefficients());
    bindConfidence(kernel, values);
    // The removed light as applyOperation computes it for a per-pixel estimator: in its pass;
    // with keeplight, the plain mean and the removed light's per-pixel step in that pass too.
    kernel.removedLight = what == "removed" || what == "keeplight";
    kernel.plainMeanLayers = what == "keeplight";
    kernel.removedLuma = lumaCoefficients();
    OIIO::ImageBuf out;
    for (auto _ : state) {
        // keeplight as applyOperation runs it: the estimate band by band with the return.
        if (what == "keeplight") {
            if (!keepLightEstimate(out, img, *est, kernel, false, lumaCoefficients(),
                                   KeepLightParams(), 0))
                throw std::runtime_error(out.geterror());
            benchmark::DoNotOptimize(out.localpixels());
            continue;
        }
        estimate(out, img, *est, kernel, false, {}, 0);
        if (what == "removed" &&
            !finishRemovedLight(out, out.nchannels() - 5, lumaCoefficients(), {}, 0))
            throw std::runtime_error(out.geterror());
        benchmark::DoNotOptimize(out.localpixels());
    }
    state.SetItemsProcessed(int64_t(state.iterations()) * W * H);
}

/// A Neighbourhood operation over the sub-buffers (3D filters) or over an image (MIF, WMIF; with
/// `withMPE` the MPE estimate is part of the timing: MPE+MIF).
void BM_Neighbourhood(benchmark::State& state, const Operation* op, EstimatorMode mode,
                      bool withMPE) {
    const StatsImage& img = syntheticImage(int(state.range(0)));
    const WindowKernel window = op->bindWindow(defaults(*op, mode), lumaCoefficients());
    OIIO::ImageBuf out;
    if (window.over == Neighbourhood::SubBuffers) {
        for (auto _ : state) {
            windowFilter(out, img, window, {}, 1);
            benchmark::DoNotOptimize(out.localpixels());
        }
    } else {
        const Operation& est = *findOperation(withMPE ? "median" : "mean");
        const PixelKernel kernel = est.bindPixel(defaults(est, mode), lumaCoefficients());
        OIIO::ImageBuf src = estimate(img, est, kernel, false, {}, 1);
        for (auto _ : state) {
            if (withMPE) estimate(src, img, est, kernel, false, {}, 1);
            windowFilter(out, src, window, {}, 1);
            benchmark::DoNotOptimize(out.localpixels());
        }
    }
    state.SetItemsProcessed(int64_t(state.iterations()) * kWidth * kHeight);
}

/// Every registry operation that runs over sub-buffers or an image, at 1920x1080, M = 21,
/// luminance mode where it has one, registry defaults, on state.range(0) threads, real time (so
/// that 2 threads show as a speed-up). Over an image (MIF, WMIF) the plain mean is part of the
/// timing, as in `mcstat F --mif`. scripts/bench.sh (SECTIONS=registry) runs each row in its own
/// process for its peak memory. Names: registry/NAME/1080p/THREADS.
void BM_Registry(benchmark::State& state, const Operation* op) {
    constexpr int W = 1920, H = 1080;
    const StatsImage& img = syntheticImage(21, W, H);
    const int threads = int(state.range(0));
    OIIO::ImageBuf out;
    if (op->input == InputKind::BufferMeans) {
        const PixelKernel kernel =
            op->bindPixel(defaults(*op, EstimatorMode::Luminance), lumaCoefficients());
        for (auto _ : state) {
            estimate(out, img, *op, kernel, false, {}, threads);
            benchmark::DoNotOptimize(out.localpixels());
        }
    } else {
        const WindowKernel window =
            op->bindWindow(defaults(*op, EstimatorMode::Luminance), lumaCoefficients());
        const Operation& mean = *findOperation("mean");
        const PixelKernel meanKernel =
            mean.bindPixel(defaults(mean, EstimatorMode::Luminance), lumaCoefficients());
        OIIO::ImageBuf plain;
        for (auto _ : state) {
            if (window.over == Neighbourhood::SubBuffers) {
                windowFilter(out, img, window, {}, threads);
            } else {
                estimate(plain, img, mean, meanKernel, false, {}, threads);
                windowFilter(out, plain, window, {}, threads);
            }
            benchmark::DoNotOptimize(out.localpixels());
        }
    }
    state.SetItemsProcessed(int64_t(state.iterations()) * W * H);
}

/// The synthetic 1080p image alone: the baseline of the registry rows' peak memory.
void BM_RegistryInput(benchmark::State& state) {
    const StatsImage& img = syntheticImage(21, 1920, 1080);
    for (auto _ : state) benchmark::DoNotOptimize(img.bufferMean.data());
}

const bool registered = [] {
    auto reg = [](const std::string& name, auto fn, auto... args) {
        benchmark::RegisterBenchmark(name.c_str(), fn, args...)
            ->ArgsProduct({kBufferCounts})
            ->Unit(benchmark::kMillisecond);
    };
    for (const Operation& op : operationRegistry()) {
        for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
            if (!op.param("mode") && mode == EstimatorMode::PerChannel) continue;
            const std::string name =
                "estimate/" + op.name + (mode == EstimatorMode::Luminance ? "/lum" : "/channel");
            if (op.input == InputKind::BufferMeans)
                reg(name, BM_Estimator, &op, mode);
            else if (op.input == InputKind::Neighbourhood)
                reg(name, BM_Neighbourhood, &op, mode, false);
            if (op.name == "mif")  // the hybrid MPE+MIF (Jung eq. 5.15)
                reg("estimate/mpe+mif" + name.substr(name.rfind('/')), BM_Neighbourhood, &op, mode,
                    true);
        }
    }
    for (const Operation& op : operationRegistry()) {
        if (op.input == InputKind::Samples) {
            // Per-sample records come from a file: scripts/bench.sh runs these through the CLI on
            // a render with --keep-samples; the row names them (--benchmark_list_tests).
            benchmark::RegisterBenchmark(("registry-samples/" + op.name).c_str(),
                                         [](benchmark::State& state) {
                                             for (auto _ : state)
                                                 state.SkipWithError("reads records from a file");
                                         })
                ->Iterations(1);
            continue;
        }
        if (op.input == InputKind::Neighbourhood && op.over == Neighbourhood::Image)
            // Over an image: in `mcstat` after an estimator (scripts/bench.sh puts --mean first).
            benchmark::RegisterBenchmark(("registry-image/" + op.name).c_str(),
                                         [](benchmark::State& state) {
                                             for (auto _ : state)
                                                 state.SkipWithError("named for bench.sh");
                                         })
                ->Iterations(1);
        benchmark::RegisterBenchmark(("registry/" + op.name + "/1080p").c_str(), BM_Registry, &op)
            ->Arg(1)
            ->Arg(2)
            ->Iterations(1)
            ->Repetitions(3)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
    }
    benchmark::RegisterBenchmark("registry/input/1080p", BM_RegistryInput)
        ->Iterations(1)
        ->Unit(benchmark::kMillisecond);
    for (const char* name : {"mean", "gmon", "mon"})
        benchmark::RegisterBenchmark((std::string("threads/") + name + "/1080p").c_str(),
                                     BM_EstimatorThreads, findEstimator(name))
            ->Arg(1)
            ->Arg(2)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
    for (const char* name : {"mean", "gmon", "tmpe"})
        for (const char* what : {"", "ci", "removed", "keeplight"}) {
            if (std::string(name) == "mean" && std::string(what) != "" && std::string(what) != "ci")
                continue;  // the mean removes nothing
            const std::string label = std::string("layers/") + name +
                                      (*what ? std::string("+") + what : std::string()) + "/1080p";
            benchmark::RegisterBenchmark(label.c_str(), BM_Layers, findEstimator(name),
                                         std::string(what))
                ->UseRealTime()
                ->Unit(benchmark::kMillisecond);
        }
    return true;
}();

}  // namespace

BENCHMARK_MAIN();
