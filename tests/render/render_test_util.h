// Helpers the renderer's test files share: options, scene loading, rendering that fails the test
// with the renderer's message, and bit-for-bit comparison of statistics images.
#pragma once

#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "mcstat/render-fixture/render.h"
#include "mcstat/render-fixture/scene.h"

namespace mcstat::render::testutil {

inline RenderOptions options(int64_t spp, int M, uint64_t seed = 1, int threads = 0) {
    RenderOptions o;
    o.spp = spp;
    o.M = M;
    o.seed = seed;
    o.threads = threads;
    return o;
}

inline Scene mustLoad(const std::string& name) {
    Scene s;
    std::string err;
    EXPECT_TRUE(loadScene(name, s, err)) << err;
    return s;
}

inline StatsImage mustRender(const Scene& scene, const RenderOptions& opt,
                             RenderStats* stats = nullptr) {
    StatsImage img;
    std::string err;
    EXPECT_TRUE(render(scene, opt, img, err, stats)) << err;
    return img;
}

inline bool sameBits(const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() &&
           (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

/// Every array of two statistics images equal bit for bit.
inline void expectIdentical(const StatsImage& a, const StatsImage& b) {
    EXPECT_TRUE(sameBits(a.beauty, b.beauty));
    EXPECT_TRUE(sameBits(a.bufferMean, b.bufferMean));
    EXPECT_TRUE(sameBits(a.bufferCount, b.bufferCount));
    EXPECT_TRUE(sameBits(a.count, b.count));
    EXPECT_TRUE(sameBits(a.mean, b.mean));
    EXPECT_TRUE(sameBits(a.variance, b.variance));
    EXPECT_TRUE(sameBits(a.normal, b.normal));
    EXPECT_TRUE(sameBits(a.position, b.position));
    EXPECT_TRUE(sameBits(a.albedo, b.albedo));
    EXPECT_TRUE(sameBits(a.depth, b.depth));
    EXPECT_TRUE(sameBits(a.coverage, b.coverage));
}

}  // namespace mcstat::render::testutil
