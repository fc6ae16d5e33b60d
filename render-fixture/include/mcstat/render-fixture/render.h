// The fixture renderer's entry points: render a Scene into an mcstat StatsImage (sub-buffer means,
// moments and first-hit features), or into a mean-only RGB image for high-spp references.
// Output is bit-identical for any thread count: every sample draws its random numbers from a
// generator seeded by (seed, pixel, sample) and each pixel is accumulated by one thread in order.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/operation.h"
#include "mcstat/render-fixture/scene.h"

namespace mcstat::render {

inline constexpr const char* kRendererName = "mcstat-render 0.1";
/// The working space of every image the renderer writes (its scenes' colours are Rec.709 linear).
inline constexpr const char* kRenderColorSpace = "lin_rec709";

/// Default seed of the adaptive-M pilot pass: independent of --seed, so that renders of the same
/// scene with different seeds choose the same buffer counts and can be merged (ASCII "pilot").
inline constexpr uint64_t kDefaultPilotSeed = 0x70696c6f74;
/// Default M_max of adaptive M (the thesis' default, about 1e-7 overestimated pixels at N*p = 1).
inline constexpr int kDefaultMaxBuffers = 17;

/// How adaptive M chooses each pixel's buffer count M_p (docs/adaptive-m.md).
enum class AdaptiveStrategy {
    /// During the render: every pixel starts with one buffer; at checkpoints (after n0, 2 n0,
    /// 4 n0, ... samples) sigma_image is recomputed and a pixel's buffer count grows to eq. 4.15's,
    /// as far as its final buffers can still hold equal sample counts. Samples go to the buffer
    /// with the fewest ("leastcount"), so new buffers catch up with the old ones. No extra samples.
    Grow,
    /// Before the render: a pilot pass with its own seed, discarded, chooses M_p; then sample i
    /// goes to buffer i mod M_p ("roundrobin"). Renders with different seeds get the same M_p and
    /// can be merged; costs the pilot's samples.
    Pilot,
};

struct RenderOptions {
    int64_t spp = 64;       ///< samples per pixel, >= 1
    int M = 8;              ///< sub-buffers, 1..kMaxBuffers (ignored by renderReference and with
                            ///< adaptiveM)
    uint64_t seed = 1;      ///< seeds every sample's generator, recorded in the header
    int threads = 0;        ///< worker threads; 0 = all hardware threads
    bool progress = false;  ///< draw a progress line on stderr (the caller checks isatty)
    // Adaptive buffer count (Jung 2016, section 4.2.4, eq. 4.15; docs/adaptive-m.md): pixel p gets
    // its own M_p in 1..mMax (odd) from its luminance standard deviation against sigma_image.
    bool adaptiveM = false;
    AdaptiveStrategy strategy = AdaptiveStrategy::Grow;  ///< how M_p is chosen
    int mMax = kDefaultMaxBuffers;  ///< M_max, odd, 1..kMaxBuffers (eq. 4.15 gives odd counts)
    int64_t checkpoint = 0;  ///< Grow: first checkpoint (samples); 0 = growCheckpoints() default
    int64_t pilotSpp = 0;    ///< Pilot: pilot samples per pixel; 0 = pilotSamples() default
    uint64_t pilotSeed = kDefaultPilotSeed;  ///< Pilot: seed of the pilot's sample generators
    /// Index of the first sample of every pixel: a resumed render takes samples firstSample ..
    /// firstSample + spp - 1 of the same sequence (sample i still goes to buffer i mod M), so
    /// that with the earlier render it took exactly the samples of one longer render. Fixed M only.
    int64_t firstSample = 0;
    /// Write AOVs (part aovs, format version 5; docs/aovs.md): alpha "A" (the camera ray hit
    /// geometry) and a light-path split of the beauty (fixtureAovChannels), per sub-buffer, and
    /// per sample in the records with --keep-samples. Fixed M only (the part aovs is).
    bool aovs = false;
    /// The renderer's clamp (clampSample, as Cycles' Clamp): every sample, the pilot's too, is
    /// scaled down so that |R| + |G| + |B| <= clamp. 0 = off. A clamped render is another
    /// estimate of the scene: its mcstat:scene says so, so it never merges with an unclamped one.
    double clamp = 0.0;
};

/// The AOV channels a render with RenderOptions::aovs writes, in their order: "A" (class
/// alpha), then NAME.R, NAME.G, NAME.B (class light) for NAME in emission, background,
/// diffuse_direct, diffuse_indirect, specular_direct, specular_indirect. Their per-sample sum
/// is the beauty: emitters and the background seen first, then light arriving at the first hit
/// directly or after more bounces, split by the first hit's lobe (diffuse, or specular for
/// mirror and glass).
std::vector<AovChannel> fixtureAovChannels();

/// What a render produces besides the StatsImage (format version 4).
struct RenderExtras {
    /// An operation's online run (its registry entry's OperationState::start, new or continuing
    /// a resumed file's state): when non-null, every sample also goes to it, as float32 RGB (the
    /// values the records keep), in the order taken, pixel by pixel.
    OnlineRun* online = nullptr;
    /// Per-sample records (--keep-samples): called with consecutive blocks of whole rows, in
    /// order, each pixel's samples in the order taken, with `recordChannels` (R, G, B, Z =
    /// first-hit distance or +inf, then the channels of recordFieldsFor's fields). Returning
    /// false stops the render with its message. Not with the Grow strategy (a pixel's samples
    /// are taken in rounds). With RenderOptions::aovs the channels may include
    /// kRecordAovPrefix + each of fixtureAovChannels()' names.
    std::function<bool(const SampleBlock&, std::string&)> records;
    std::vector<std::string> recordChannels{"R", "G", "B", "Z"};
};

/// The record fields (sample_records.h's recordFieldTable) a render of `scene` can fill: screen
/// position, the random parameters the scene draws (lens with an aperture, time with motion,
/// the first hit's light and bounce numbers) and the features of the first and second hit.
std::vector<std::string> recordFieldsFor(const Scene& scene);

/// One checkpoint of the Grow strategy: the state right after its decisions.
struct GrowCheckpoint {
    int64_t samples = 0;      ///< samples per pixel taken before the decision
    double sigmaImage = 0;    ///< sigma_image from those samples (mean luminance sigma)
    int64_t grownPixels = 0;  ///< pixels whose buffer count grew here
    double meanBuffers = 0;   ///< sum of M_p / pixels after the decision
};

struct RenderStats {
    int64_t nonFiniteSamples = 0;  ///< samples dropped because their radiance was NaN or Inf
    double seconds = 0;            ///< wall-clock render time (pilot included)
    // Adaptive M only:
    double sigmaImage = 0;     ///< sigma_image of the last decision (pilot or last checkpoint)
    int64_t pilotSamples = 0;  ///< Pilot: pilot samples per pixel taken
    double meanBuffers = 0;    ///< sum of M_p / pixels ("image buffers", Table 4.1)
    double pilotSeconds = 0;   ///< Pilot: wall-clock time of the pilot pass
    std::vector<GrowCheckpoint> checkpoints;  ///< Grow: every checkpoint, in order
};

/// Luminance weights of eq. 4.15's standard deviations: Rec.709 / sRGB primaries, which are the
/// renderer's fixed output colour space (lin_rec709). Deliberately not taken from $OCIO: the
/// buffer counts, and so the file, must not depend on the environment.
inline constexpr double kSigmaLuma[3] = {0.2126, 0.7152, 0.0722};

/// Eq. 4.15: M_p = 1 when sigmaPixel / sigmaImage < 1, else 2 (floor(log2 ratio) + 1) + 1, capped
/// at mMax. floor(log2) is computed exactly (ilogb). sigmaPixel = 0 gives 1; sigmaImage = 0 with
/// sigmaPixel > 0 (an infinite ratio) gives mMax.
int adaptiveBufferCount(double sigmaPixel, double sigmaImage, int mMax);

/// Grow: the largest odd buffer count, at most mMax, whose buffers can all still end with
/// floor(spp / M) or ceil(spp / M) samples when the fullest buffer already holds maxCount:
/// floor(spp / maxCount) (mMax when maxCount is 0), made odd. Least-count assignment fills the new
/// buffers up to maxCount first, so growing within this cap keeps the thesis' equal-size means.
int growCap(int64_t spp, int64_t maxCount, int mMax);

/// Grow: a pixel's buffer count after a checkpoint: max(current, min(eq. 4.15, growCap)). Buffer
/// counts never shrink (a buffer's samples cannot be taken back out of its sum).
int grownBufferCount(int current, double sigmaPixel, double sigmaImage, int mMax, int64_t spp,
                     int64_t maxCount);

/// Grow: the checkpoints, in samples per pixel: n0, 2 n0, 4 n0, ... below spp, where n0 is
/// opt.checkpoint or by default max(2, spp / mMax) (so that the first decision can still reach
/// mMax). Empty when n0 >= spp or mMax = 1 (nothing could grow).
std::vector<int64_t> growCheckpoints(const RenderOptions& opt);

/// The pilot's samples per pixel: opt.pilotSpp, or by default min(spp, max(64, spp / 8)).
int64_t pilotSamples(const RenderOptions& opt);

/// The adaptive-M plan of a render: per pixel (y*width + x) the pilot's luminance standard
/// deviation sigma_p (unbiased, 0 with fewer than 2 finite samples) and M_p, and sigma_image, the
/// mean of sigma_p over all pixels (docs/adaptive-m.md). Deterministic for any thread count: each
/// pixel's statistics come from one thread, sigma_image is reduced afterwards in pixel order.
struct AdaptivePlan {
    std::vector<double> sigmaPixel;
    std::vector<uint32_t> buffers;
    double sigmaImage = 0;
    int64_t pilotSamples = 0;
};
bool planAdaptive(const Scene& scene, const RenderOptions& opt, AdaptivePlan& plan,
                  std::string& err);

/// Checks the option ranges; `err` is one line naming the bad option.
bool validateOptions(const RenderOptions& opt, std::string& err);

/// Renders `scene` and fills every array and the header of `out`. With opt.adaptiveM the image
/// has adaptive M (format version 2, header.M = mMax), chosen by opt.strategy.
bool render(const Scene& scene, const RenderOptions& opt, StatsImage& out, std::string& err,
            RenderStats* stats = nullptr, RenderExtras* extras = nullptr);

/// Renders the plain mean only (no sub-buffers, no features): rgb[(y*width + x)*3 + c].
/// Memory is one RGB image, so it suits very high spp.
bool renderReference(const Scene& scene, const RenderOptions& opt, std::vector<float>& rgb,
                     std::string& err, RenderStats* stats = nullptr);

}  // namespace mcstat::render
