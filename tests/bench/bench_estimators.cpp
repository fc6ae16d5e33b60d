// Per-estimator throughput over a synthetic statistics image with fireflies, single-threaded, for
// several M. Items are pixels, so Google Benchmark reports pixel/s; scripts/bench.sh turns the
// results into ratios against the plain mean measured in the same run.
#include <benchmark/benchmark.h>

#include <random>

#include "mcstat/color.h"
#include "mcstat/imageops.h"
#include "mcstat/registry.h"

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

const bool registered = [] {
    for (const EstimatorInfo& e : estimatorRegistry()) {
        for (auto mode : {EstimatorMode::Luminance, EstimatorMode::PerChannel}) {
            if (e.params.empty() && mode == EstimatorMode::PerChannel) continue;
            const std::string name =
                "estimate/" + e.name + (mode == EstimatorMode::Luminance ? "/lum" : "/channel");
            benchmark::RegisterBenchmark(name.c_str(), BM_Estimator, &e, mode)
                ->Arg(5)
                ->Arg(21)
                ->Arg(63)
                ->Unit(benchmark::kMillisecond);
        }
    }
    return true;
}();

}  // namespace

BENCHMARK_MAIN();
