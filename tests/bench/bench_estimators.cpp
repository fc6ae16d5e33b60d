// Per-estimator throughput over a synthetic statistics image with fireflies, single-threaded, for
// several M. Items are pixels, so Google Benchmark reports pixel/s; scripts/bench.sh turns the
// results into ratios against the plain mean measured in the same run.
// Jung's spatial filters (chapter 5) run with a 3x3 window: the 3D filters 3dmf, 3dwmf (w = 3),
// 3dwtmf (alpha = 0.25, w = 3) over the M buffers; mif and wmif (w = 3) over the mean image
// (computed outside the timing, so their cost does not depend on M); mpe+mif is the whole hybrid,
// MPE then MIF. Names follow estimate/NAME/MODE/M as bench.sh expects.
#include <benchmark/benchmark.h>

#include <random>

#include "mcstat/color.h"
#include "mcstat/imageops.h"
#include "mcstat/registry.h"
#include "mcstat/spatial_filters.h"

using namespace mcstat;

namespace {

constexpr int kWidth = 256, kHeight = 256;

/// Buffer means of a noisy image where 1% of the buffers hold a firefly.
const StatsImage& syntheticImage(int M) {
    static std::map<int, StatsImage> cache;
    auto it = cache.find(M);
    if (it != cache.end()) return it->second;
    StatsImage s;
    s.header.width = kWidth;
    s.header.height = kHeight;
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
    return cache.emplace(M, std::move(s)).first->second;
}

void BM_Estimator(benchmark::State& state, const EstimatorInfo* est, EstimatorMode mode) {
    const StatsImage& img = syntheticImage(int(state.range(0)));
    EstimatorParams p;
    p.mode = mode;
    p.luma = lumaCoefficients();
    OIIO::ImageBuf out;
    for (auto _ : state) {
        estimate(out, img, *est, p, false, {}, 1);
        benchmark::DoNotOptimize(out.localpixels());
    }
    state.SetItemsProcessed(int64_t(state.iterations()) * kWidth * kHeight);
}

const std::vector<int64_t> kBufferCounts = {3, 7, 17, 21};

SpatialParams spatialParams(EstimatorMode mode, int64_t w, double alpha) {
    SpatialParams p;
    p.mode = mode;
    p.luma = lumaCoefficients();
    p.centreWeight = w;
    p.alpha = alpha;
    return p;
}

void BM_Filter3D(benchmark::State& state, EstimatorMode mode, int64_t w, double alpha) {
    const StatsImage& img = syntheticImage(int(state.range(0)));
    const SpatialParams p = spatialParams(mode, w, alpha);
    OIIO::ImageBuf out;
    for (auto _ : state) {
        filter3D(out, img, p, {}, 1);
        benchmark::DoNotOptimize(out.localpixels());
    }
    state.SetItemsProcessed(int64_t(state.iterations()) * kWidth * kHeight);
}

/// MIF / WMIF of the mean image; with `withMPE` the MPE estimate is part of the timing (MPE+MIF).
void BM_ImageFilter(benchmark::State& state, EstimatorMode mode, int64_t w, bool withMPE) {
    const StatsImage& img = syntheticImage(int(state.range(0)));
    const SpatialParams p = spatialParams(mode, w, 0.5);
    EstimatorParams ep;
    ep.mode = mode;
    ep.luma = p.luma;
    const EstimatorInfo& est = *findEstimator(withMPE ? "median" : "mean");
    OIIO::ImageBuf src = estimate(img, est, ep, false, {}, 1), out;
    for (auto _ : state) {
        if (withMPE) estimate(src, img, est, ep, false, {}, 1);
        medianImageFilter(out, src, p, {}, 1);
        benchmark::DoNotOptimize(out.localpixels());
    }
    state.SetItemsProcessed(int64_t(state.iterations()) * kWidth * kHeight);
}

const bool registered = [] {
    for (const EstimatorInfo& e : estimatorRegistry()) {
        for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
            if (e.params.empty() && mode == EstimatorMode::PerChannel) continue;
            const std::string name =
                "estimate/" + e.name + (mode == EstimatorMode::Luminance ? "/lum" : "/channel");
            benchmark::RegisterBenchmark(name.c_str(), BM_Estimator, &e, mode)
                ->ArgsProduct({kBufferCounts})
                ->Unit(benchmark::kMillisecond);
        }
    }
    for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
        const std::string m = mode == EstimatorMode::Luminance ? "/lum" : "/channel";
        auto reg = [](const std::string& name, auto fn, auto... args) {
            benchmark::RegisterBenchmark(name.c_str(), fn, args...)
                ->ArgsProduct({kBufferCounts})
                ->Unit(benchmark::kMillisecond);
        };
        reg("estimate/3dmf" + m, BM_Filter3D, mode, int64_t(1), 0.5);
        reg("estimate/3dwmf" + m, BM_Filter3D, mode, int64_t(3), 0.5);
        reg("estimate/3dwtmf" + m, BM_Filter3D, mode, int64_t(3), 0.25);
        reg("estimate/mif" + m, BM_ImageFilter, mode, int64_t(1), false);
        reg("estimate/wmif" + m, BM_ImageFilter, mode, int64_t(3), false);
        reg("estimate/mpe+mif" + m, BM_ImageFilter, mode, int64_t(1), true);
    }
    return true;
}();

}  // namespace

BENCHMARK_MAIN();
