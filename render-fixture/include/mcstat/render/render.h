// The fixture renderer's entry points: render a Scene into an mcstat StatsImage (sub-buffer means,
// moments and first-hit features), or into a mean-only RGB image for high-spp references.
// Output is bit-identical for any thread count: every sample draws its random numbers from a
// generator seeded by (seed, pixel, sample) and each pixel is accumulated by one thread in order.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mcstat/render/scene.h"
#include "mcstat/stats_file.h"

namespace mcstat::render {

inline constexpr const char* kRendererName = "mcstat-render 0.1";

struct RenderOptions {
    int64_t spp = 64;       ///< samples per pixel, >= 1
    int M = 8;              ///< sub-buffers, 1..kMaxBuffers (ignored by renderReference)
    uint64_t seed = 1;      ///< seeds every sample's generator, recorded in the header
    int threads = 0;        ///< worker threads; 0 = all hardware threads
    bool progress = false;  ///< draw a progress line on stderr (the caller checks isatty)
};

struct RenderStats {
    int64_t nonFiniteSamples = 0;  ///< samples dropped because their radiance was NaN or Inf
    double seconds = 0;            ///< wall-clock render time
};

/// Checks the option ranges; `err` is one line naming the bad option.
bool validateOptions(const RenderOptions& opt, std::string& err);

/// Renders `scene` and fills every array and the header of `out`.
bool render(const Scene& scene, const RenderOptions& opt, StatsImage& out, std::string& err,
            RenderStats* stats = nullptr);

/// Renders the plain mean only (no sub-buffers, no features): rgb[(y*width + x)*3 + c].
/// Memory is one RGB image, so it suits very high spp.
bool renderReference(const Scene& scene, const RenderOptions& opt, std::vector<float>& rgb,
                     std::string& err, RenderStats* stats = nullptr);

}  // namespace mcstat::render
