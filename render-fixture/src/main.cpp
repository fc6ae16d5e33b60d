// mcstat-render: renders a built-in or JSON scene into an mcstat statistics file, or (with
// --reference) into a plain mean-only EXR for high-spp reference images.
#include <OpenImageIO/argparse.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/strutil.h>
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "mcstat/color/color.h"
#include "mcstat/compact/compact.h"
#include "mcstat/core/detail/fork_server.h"
#include "mcstat/core/parallel.h"
#include "mcstat/core/params.h"
#include "mcstat/core/progress.h"
#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/codec/detail/fd_stream.h"
#include "mcstat/exr-deep/codec/temp_file.h"
#include "mcstat/exr-deep/sample_records.h"
#include "mcstat/exr-deep/stats_file.h"
#include "mcstat/filters/registry.h"
#include "mcstat/render-fixture/render.h"
#include "mcstat/render-fixture/scene.h"
#include "mcstat/version.h"
#include "reference_exr.h"

namespace {

using namespace mcstat::render;
using mcstat::parseInt;  // the one integer option parser (core/params.h)

int fail(const std::string& msg) {
    // One line whatever a scene file or a path holds (core/untrusted_text.h).
    fmt::print(stderr, "mcstat-render: {}\n", mcstat::oneLine(msg));
    return 1;
}

bool parseSeed(const std::string& text, uint64_t& out, std::string& err,
               const char* what = "--seed") {
    if (!mcstat::parseUnsignedText(text, out)) {
        err = fmt::format("{}: expected a non-negative 64-bit integer, got '{}'", what, text);
        return false;
    }
    return true;
}

/// Wall-clock and process CPU seconds (every thread) since construction, for --timings.
class Stopwatch {
  public:
    double wall() const {
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0_).count();
    }
    double cpu() const { return cpuNow() - cpu0_; }

  private:
    static double cpuNow() {
        timespec ts{};
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
        return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
    }
    std::chrono::steady_clock::time_point wall0_ = std::chrono::steady_clock::now();
    double cpu0_ = cpuNow();
};

/// The command line as typed: every option's text, checked once parsing is over.
struct CommandLine {
    std::string sceneName = "default", outPath, sppText = "64", mText = "8", seedText = "1",
                threadsText = "0", resW, resH, mMaxText = std::to_string(kDefaultMaxBuffers),
                pilotText = "0", checkpointText = "0", strategyText = "grow",
                pilotSeedText = std::to_string(kDefaultPilotSeed);
    bool reference = false, quiet = false, version = false, adaptive = false, keepSamples = false,
         timings = false;
    bool aovs = false;
    bool compact = false;  ///< --compact: write a compact file (FORMAT.md "Version 6")
    std::string maxSampleBytesText = std::to_string(mcstat::kDefaultMaxRecordBytes), resumePath;
    std::string clampText;  ///< --clamp: the renderer's clamp (empty: off)
    /// --online NAME[:key=value...], as given (once per time given).
    std::vector<std::string> online;
    /// The deprecated spellings of --online (mapped onto it by onlineRequests): --pajot METHOD
    /// and its --pajot-n, --pajot-delayed, --pajot-t, --pajot-delta (unset: not given), and
    /// --reweight with its --reweight-params TEXT.
    std::string pajotText;
    std::optional<std::string> pajotNText, pajotDelayedText, pajotTText, pajotDeltaText;
    bool reweight = false;
    std::optional<std::string> reweightParams;
    bool help = false;
};

/// Declares the options of the scene and of how its samples are taken (fixed or adaptive M).
void addSamplingOptions(OIIO::ArgParse& ap, CommandLine& cl) {
    std::string names;
    for (const auto& n : builtinSceneNames()) names += (names.empty() ? "" : ", ") + n;

    ap.arg("--scene NAME|FILE")
        .help("built-in scene (" + names +
              ") or a JSON scene file (render-fixture/SCENES.md); "
              "default: default")
        .action([&](OIIO::cspan<const char*> a) { cl.sceneName = a[1]; });
    ap.arg("--spp N")
        .help("samples per pixel, >= 1 (default 64)")
        .action([&](OIIO::cspan<const char*> a) { cl.sppText = a[1]; });
    ap.arg("--M M")
        .help(
            "sub-buffers, 1..999; sample i goes to buffer i mod M; spp < M leaves buffers "
            "empty (default 8; ignored with --reference)")
        .action([&](OIIO::cspan<const char*> a) { cl.mText = a[1]; });
    ap.arg("--clamp C")
        .help(
            "the renderer's clamp, as Cycles' Clamp settings: a sample whose |R| + |G| + |B| "
            "exceeds C is scaled down to C (hue and AOV sums kept; the light above C is lost). "
            "C > 0; the file's mcstat:scene records it, so clamped and unclamped renders never "
            "merge (default: off)")
        .action([&](OIIO::cspan<const char*> a) { cl.clampText = a[1]; });
    ap.arg("--adaptive-m")
        .help(
            "adaptive buffer count (Jung eq. 4.15): pixel p gets M_p in 1..M_max buffers (odd) "
            "from its luminance standard deviation against the image's; the file stores them in "
            "a deep part (format 2; docs/adaptive-m.md). --M is ignored")
        .action([&](OIIO::cspan<const char*>) { cl.adaptive = true; });
    ap.arg("--m-strategy grow|pilot")
        .help(
            "with --adaptive-m: 'grow' (default) starts every pixel with one buffer and adds "
            "buffers at checkpoints during the render, new buffers catching up with the old; "
            "'pilot' chooses M_p first by a separate pilot pass (extra samples, but renders with "
            "different --seed get the same M_p and can be merged)")
        .action([&](OIIO::cspan<const char*> a) { cl.strategyText = a[1]; });
    ap.arg("--m-max N")
        .help("with --adaptive-m: the largest M_p, odd, 1..999 (default 17)")
        .action([&](OIIO::cspan<const char*> a) { cl.mMaxText = a[1]; });
    ap.arg("--checkpoint N")
        .help(
            "with --m-strategy grow: the first checkpoint, in samples per pixel, >= 2; later "
            "ones at 2N, 4N, ... (default max(2, spp / M_max))")
        .action([&](OIIO::cspan<const char*> a) { cl.checkpointText = a[1]; });
    ap.arg("--pilot N")
        .help(
            "with --m-strategy pilot: pilot samples per pixel (default min(spp, max(64, "
            "spp/8))); they only choose M_p and are not part of the image")
        .action([&](OIIO::cspan<const char*> a) { cl.pilotText = a[1]; });
    ap.arg("--pilot-seed S")
        .help(
            "with --m-strategy pilot: seed of the pilot, independent of --seed so that renders "
            "with different seeds get the same M_p and can be merged (default " +
            std::to_string(kDefaultPilotSeed) + ")")
        .action([&](OIIO::cspan<const char*> a) { cl.pilotSeedText = a[1]; });
}

/// Declares the options of what the file keeps besides the buffers: Pajot, records, AOVs, resume.
void addPerSampleOptions(OIIO::ArgParse& ap, CommandLine& cl) {
    ap.arg("--online NAME")
        .help(
            "run operation NAME online, every sample in the order taken, and keep its per-pixel "
            "state in the file (format 4): pajot (Pajot et al. 2011, parts pajot and modes; "
            "docs/pajot.md), reweight (Zirr et al. 2018, parts cascades and cascades.deep; "
            "docs/reweighting.md). Its parameters as mcstat's modifiers: checked against the "
            "registry entry, e.g. --online pajot:method=hybrid:n=30, --online reweight:count=5")
        .action([&](OIIO::cspan<const char*> a) { cl.online.emplace_back(a[1]); });
    // The spellings before --online, kept working (a note on stderr says the new one).
    ap.arg("--pajot adr|rot|hybrid")
        .help("deprecated: --online pajot:method=METHOD")
        .action([&](OIIO::cspan<const char*> a) { cl.pajotText = a[1]; });
    ap.arg("--pajot-n N")
        .help("deprecated: --online pajot:n=N (learning samples, default 50)")
        .action([&](OIIO::cspan<const char*> a) { cl.pajotNText = a[1]; });
    ap.arg("--pajot-delayed N")
        .help("deprecated: --online pajot:delayed=N (dubious list bound, default 64)")
        .action([&](OIIO::cspan<const char*> a) { cl.pajotDelayedText = a[1]; });
    ap.arg("--pajot-t T")
        .help("deprecated: --online pajot:t=T (hybrid's close maxima, default 2)")
        .action([&](OIIO::cspan<const char*> a) { cl.pajotTText = a[1]; });
    ap.arg("--pajot-delta D")
        .help("deprecated: --online pajot:delta=D (hybrid's closeness, default 0)")
        .action([&](OIIO::cspan<const char*> a) { cl.pajotDeltaText = a[1]; });
    ap.arg("--reweight")
        .help("deprecated: --online reweight")
        .action([&](OIIO::cspan<const char*>) { cl.reweight = true; });
    ap.arg("--reweight-params TEXT")
        .help("deprecated: --online reweight:TEXT (keys count, base, start, luma)")
        .action([&](OIIO::cspan<const char*> a) { cl.reweightParams = a[1]; });
    ap.arg("--keep-samples")
        .help(
            "keep every sample in the deep part records (format 4), written by blocks of rows: "
            "R, G, B, first-hit distance, screen position, the random parameters drawn (lens "
            "with an aperture, time with motion, the first hit's light and bounce numbers) and "
            "the normal, position and texture value of the first hit and normal and position of "
            "the second (random parameter filtering's inputs; 108-116 bytes per sample before "
            "compression)")
        .action([&](OIIO::cspan<const char*>) { cl.keepSamples = true; });
    ap.arg("--aovs")
        .help(
            "write AOVs (format 5, docs/aovs.md) per sub-buffer: alpha A (the camera ray hit "
            "geometry) and the beauty split by light path, emission, background, "
            "diffuse_direct, diffuse_indirect, specular_direct, specular_indirect (R, G, B each; "
            "they sum to the beauty sample by sample); with --keep-samples per sample too. Fixed "
            "M only")
        .action([&](OIIO::cspan<const char*>) { cl.aovs = true; });
    ap.arg("--compact")
        .help(
            "write a compact file (format 8, docs/compact.md): a pixel keeps its sub-buffers only "
            "where G-MoN would trim one, else their mean, decided once every sample is in; G-MoN "
            "of the file equals the full file's bit for bit. Fixed M, without --keep-samples, "
            "--online or --resume")
        .action([&](OIIO::cspan<const char*>) { cl.compact = true; });
    ap.arg("--max-sample-bytes N")
        .help(
            "with --keep-samples: refuse renders whose records exceed N bytes before compression "
            "(default " +
            std::to_string(mcstat::kDefaultMaxRecordBytes) + ", 4 GiB)")
        .action([&](OIIO::cspan<const char*> a) { cl.maxSampleBytesText = a[1]; });
    ap.arg("--resume FILE")
        .help(
            "continue FILE (rendered with fixed M by this renderer) up to --spp samples per pixel: "
            "same scene, size, seed and M; Pajot's state continues bit for bit")
        .action([&](OIIO::cspan<const char*> a) { cl.resumePath = a[1]; });
}

/// Declares the options of the run itself: seed, threads, size, output and what is printed.
void addRunOptions(OIIO::ArgParse& ap, CommandLine& cl) {
    ap.arg("--seed S")
        .help(
            "seed, a non-negative 64-bit integer; the same seed gives bit-identical output "
            "(default 1)")
        .action([&](OIIO::cspan<const char*> a) { cl.seedText = a[1]; });
    ap.arg("--threads N")
        .help("worker threads, 0 = all cores (default 0); the output does not depend on it")
        .action([&](OIIO::cspan<const char*> a) { cl.threadsText = a[1]; });
    ap.arg("--res W H")
        .help("override the scene's image size (pixels)")
        .action([&](OIIO::cspan<const char*> a) { cl.resW = a[1], cl.resH = a[2]; });
    ap.arg("--reference")
        .help(
            "write a plain RGB float EXR of the mean only (no sub-buffers: for high-spp "
            "reference images)")
        .action([&](OIIO::cspan<const char*>) { cl.reference = true; });
    ap.arg("--timings")
        .help(
            "print one line on stderr: wall and CPU seconds of the render and of writing the "
            "output (benchmarks: scripts/bench_render.sh)")
        .action([&](OIIO::cspan<const char*>) { cl.timings = true; });
    ap.arg("--quiet")
        .help("no progress line (it is shown only when stderr is a terminal anyway)")
        .action([&](OIIO::cspan<const char*>) { cl.quiet = true; });
    ap.arg("-o OUT")
        .help("output: a statistics file (.mcstat), or an .exr with --reference")
        .action([&](OIIO::cspan<const char*> a) { cl.outPath = a[1]; });
}

/// Parses the command line into `cl`; false when main must return `exitCode` now (an error, or
/// --help printed).
bool parseCommandLine(int argc, const char** argv, CommandLine& cl, int& exitCode) {
    OIIO::ArgParse ap;
    ap.intro(
          "mcstat-render -- the mcstat fixture path tracer (Embree; NEE + MIS, Russian roulette)")
        .usage("mcstat-render [options] -o OUT")
        .exit_on_error(false)
        .add_help(false)
        .print_defaults(false);
    ap.arg("--help").help("print this help and exit").action([&](OIIO::cspan<const char*>) {
        cl.help = true;
    });
    ap.arg("--version").help("print the version and exit").action([&](OIIO::cspan<const char*>) {
        cl.version = true;
    });
    addSamplingOptions(ap, cl);
    addPerSampleOptions(ap, cl);
    addRunOptions(ap, cl);

    if (ap.parse_args(argc, argv) < 0) {
        exitCode = fail(ap.geterror());
        return false;
    }
    if (cl.help) {
        ap.print_help();
        exitCode = 0;
        return false;
    }
    if (cl.version) {
        std::printf("mcstat-render %s\n", MCSTAT_VERSION);
        exitCode = 0;
        return false;
    }
    if (cl.outPath.empty()) {
        exitCode = fail("no output given (-o OUT); see --help");
        return false;
    }
    // The name says what the file is, for the tools that go by it (the OIIO plugin takes
    // .mcstat, and a plain EXR named so fails there; mcstat itself reads by content).
    const std::string ext = OIIO::Strutil::lower(OIIO::Filesystem::extension(cl.outPath, false));
    if (cl.reference && ext == "mcstat") {
        exitCode = fail(cl.outPath +
                        ": --reference writes a plain EXR image, not a statistics file: name it "
                        ".exr (the OIIO plugin would take a .mcstat for a statistics file)");
        return false;
    }
    if (cl.compact) {
        const char* clash =
            cl.reference            ? "--reference (a plain image)"
            : cl.adaptive           ? "--adaptive-m (its buffers are chosen while rendering)"
            : cl.keepSamples        ? "--keep-samples (a compact file keeps no samples)"
            : !cl.pajotText.empty() ? "--pajot (a compact file keeps no Pajot state)"
            : cl.reweight           ? "--reweight (a compact file keeps no cascades)"
            : !cl.online.empty()    ? "--online (a compact file keeps no operation's state)"
            : !cl.resumePath.empty()
                ? "--resume (resume the full file, then compact it with mcstat "
                  "--compact)"
                : nullptr;
        if (clash != nullptr) {
            exitCode = fail(fmt::format("--compact cannot be combined with {}", clash));
            return false;
        }
    }
    if (!cl.reference && ext != "mcstat" && !cl.quiet)
        fmt::print(stderr,
                   "mcstat-render: warning: {}: a statistics file named .{}: mcstat reads it by "
                   "its content, but the OIIO plugin and other tools go by the name (.mcstat)\n",
                   mcstat::oneLine(cl.outPath), ext.empty() ? "(no extension)" : ext);
    // Before hours of rendering: a target the write would refuse (a directory, /dev/null, a
    // read-only file, a missing directory) fails now.
    std::string err;
    if (!mcstat::checkOutputTarget(cl.outPath, err)) {
        exitCode = fail(err);
        return false;
    }
    return true;
}

/// Sizes OpenEXR's thread pool, which compresses the output, from the render's thread count.
void setWriteThreads(int renderThreads) {
    // Writing compresses every part with deflate, which at M = 21 costs about a tenth of a 64-spp
    // render's CPU time; OpenEXR compresses blocks of lines on its own pool, with the bytes
    // independent of the thread count (tests/exr-deep/test_roundtrip.cpp). 0 = no pool: the
    // calling thread compresses. At most kWriteThreads: each pool thread keeps two blocks of 16
    // lines of every part alive until the file is closed (measured: 26 MB more peak memory per
    // thread at 1920 pixels wide and M = 21), and a few threads already make the compression short.
    constexpr int kWriteThreads = 4;
    const int threads = std::min(mcstat::threadCount(renderThreads), kWriteThreads);
    mcstat::detail::setOpenExrThreads(threads);
}

/// Checks the sampling options into `opt` (and sizes the writer's thread pool).
bool parseRenderOptions(const CommandLine& cl, RenderOptions& opt, std::string& err) {
    int64_t v = 0;
    if (!parseInt(cl.sppText, "--spp", 1, (1LL << 40), v, err)) return false;
    opt.spp = v;
    if (!parseInt(cl.mText, "--M", 1, mcstat::kMaxBuffers, v, err)) return false;
    opt.M = int(v);
    if (!parseInt(cl.threadsText, "--threads", 0, 4096, v, err)) return false;
    opt.threads = int(v);
    setWriteThreads(opt.threads);
    if (!parseSeed(cl.seedText, opt.seed, err)) return false;
    opt.adaptiveM = cl.adaptive;
    opt.aovs = cl.aovs;
    if (!cl.clampText.empty()) {
        const mcstat::ParamSpec spec = mcstat::realParam(
            "clamp", 0.0, std::numeric_limits<double>::max(), true, "", "the renderer's clamp");
        mcstat::ParamValue clamp;
        if (!mcstat::parseParamValue("--clamp", spec, cl.clampText, clamp, err)) return false;
        opt.clamp = clamp.real;
    }
    if (!parseInt(cl.mMaxText, "--m-max", 1, mcstat::kMaxBuffers, v, err)) return false;
    opt.mMax = int(v);
    if (cl.adaptive && opt.mMax % 2 == 0) {
        err = fmt::format("--m-max: must be odd (eq. 4.15 gives odd counts; got {})", v);
        return false;
    }
    if (cl.strategyText == "grow") {
        opt.strategy = AdaptiveStrategy::Grow;
    } else if (cl.strategyText == "pilot") {
        opt.strategy = AdaptiveStrategy::Pilot;
    } else {
        err = fmt::format("--m-strategy: expected 'grow' or 'pilot', got '{}'", cl.strategyText);
        return false;
    }
    if (!parseInt(cl.checkpointText, "--checkpoint", 0, (1LL << 40), v, err)) return false;
    opt.checkpoint = v;
    if (!parseInt(cl.pilotText, "--pilot", 0, (1LL << 40), v, err)) return false;
    opt.pilotSpp = v;
    if (!parseSeed(cl.pilotSeedText, opt.pilotSeed, err, "--pilot-seed")) return false;
    opt.progress = !cl.quiet && mcstat::Progress::onTerminal();
    return true;
}

/// Loads the scene, at the size --res gives if it is given.
bool loadSizedScene(const CommandLine& cl, Scene& scene, std::string& err) {
    if (!loadScene(cl.sceneName, scene, err)) return false;
    if (!cl.resW.empty()) {
        int64_t w = 0, h = 0;
        if (!parseInt(cl.resW, "--res width", 1, 16384, w, err) ||
            !parseInt(cl.resH, "--res height", 1, 16384, h, err))
            return false;
        scene.width = int(w), scene.height = int(h);
    }
    return true;
}

/// The luminance weights of the renderer's working space (lin_rec709, the space it labels its
/// output with); a warning (a fallback config) is printed. False with `err` when the OCIO config
/// is unusable ($OCIO=ocio://... before OCIO 2.2).
bool luma(std::array<double, 3>& l, std::string& err) {
    std::string warning;
    if (!mcstat::lumaCoefficients(mcstat::kSceneLinear, l, err, &warning)) return false;
    if (!warning.empty()) fmt::print(stderr, "mcstat-render: warning: {}\n", warning);
    return true;
}

/// An operation to run online as the command line asks for it: its registry name, its parameters
/// as given, the option that asked (for messages: "--online pajot", or a deprecated "--pajot" /
/// "--reweight") and what its parameter errors name.
struct OnlineRequest {
    std::string name;
    std::map<std::string, std::string> kv;
    std::string flag, context;
    bool deprecated = false;  ///< asked for by --pajot or --reweight
    std::string problem;      ///< the parameter text's, reported when the parameters are parsed
};

/// The registry's operations that run online (OperationState::start), comma-separated.
std::string onlineOperationNames(std::vector<std::string>* names = nullptr) {
    std::string text;
    for (const mcstat::Operation& op : mcstat::operationRegistry())
        if (op.state.start != nullptr) {
            text += (text.empty() ? "" : ", ") + op.name;
            if (names != nullptr) names->push_back(op.name);
        }
    return text;
}

/// The deprecated --pajot* and --reweight* options as the --online requests they mean, with the
/// one-line note that says so.
bool deprecatedOnlineRequests(const CommandLine& cl, std::vector<OnlineRequest>& out,
                              std::string& err) {
    std::vector<std::string> used;
    std::vector<std::string> instead;
    if (!cl.pajotText.empty()) {
        OnlineRequest r{"pajot", {{"method", cl.pajotText}}, "--pajot", "--pajot", true, {}};
        used.emplace_back("--pajot");
        const std::pair<const char*, const std::optional<std::string>*> keys[] = {
            {"n", &cl.pajotNText},
            {"delayed", &cl.pajotDelayedText},
            {"t", &cl.pajotTText},
            {"delta", &cl.pajotDeltaText}};
        for (const auto& [key, text] : keys)
            if (*text) {
                r.kv[key] = **text;
                used.push_back(std::string("--pajot-") + key);
            }
        instead.push_back("--online pajot:" + mcstat::paramText(r.kv));
        out.push_back(std::move(r));
    }
    if (cl.reweight) {
        OnlineRequest r{"reweight", {}, "--reweight", "--reweight-params", true, {}};
        used.emplace_back("--reweight");
        if (cl.reweightParams) {
            used.emplace_back("--reweight-params");
            if (!mcstat::parseParamText(*cl.reweightParams, r.kv, r.problem))
                r.problem = "--reweight-params: " + r.problem;
        }
        instead.push_back("--online reweight" +
                          (r.kv.empty() ? "" : ":" + mcstat::paramText(r.kv)));
        out.push_back(std::move(r));
    } else if (cl.reweightParams) {
        err = "--reweight-params needs --reweight";
        return false;
    }
    if (!used.empty())
        fmt::print(stderr, "mcstat-render: note: {} {} deprecated: use {}\n",
                   OIIO::Strutil::join(used, ", "), used.size() == 1 ? "is" : "are",
                   OIIO::Strutil::join(instead, " "));
    return true;
}

/// Every operation the command line asks to run online: --online NAME[:key=value...] (split as
/// mcstat splits a command from its modifiers, core/params.h parseNamedParams), and the
/// deprecated flags mapped onto it.
bool onlineRequests(const CommandLine& cl, std::vector<OnlineRequest>& out, std::string& err) {
    if (!deprecatedOnlineRequests(cl, out, err)) return false;
    for (const std::string& text : cl.online) {
        OnlineRequest r;
        if (!mcstat::parseNamedParams(text, r.name, r.kv, r.problem))
            r.problem = "--online " + r.name + ": " + r.problem;
        r.flag = r.context = "--online " + r.name;
        out.push_back(std::move(r));
    }
    return true;
}

/// The request's parameters as its registry entry's (parseOperationParams: each key one of the
/// entry's ParamSpecs, each value of its type and range), as `mcstat --NAME:key=value` checks them.
bool parseOnlineParams(const OnlineRequest& r, mcstat::ParamValues& values, std::string& err) {
    if (!r.problem.empty()) {
        err = r.problem;
        return false;
    }
    const mcstat::Operation* op = mcstat::findOperation(r.name);
    if (op == nullptr || op->state.start == nullptr) {
        std::vector<std::string> names;
        const std::string list = onlineOperationNames(&names);
        const std::string near = mcstat::nearestName(r.name, names);
        err = "--online: '" + mcstat::printable(r.name) +
              "' is no operation this renderer runs online" +
              (near.empty() ? std::string() : " (did you mean " + near + "?)") +
              " (it runs: " + (list.empty() ? std::string("none") : list) + ")";
        return false;
    }
    // The reweighting's kappa and spread apply when its cascades are reweighted, not online.
    if (r.name == "reweight")
        for (const char* later : {"kappa", "spread"})
            if (r.kv.count(later) != 0) {
                err = r.context + ": " + later +
                      " is chosen when reweighting (mcstat --reweight:" + later + "=...)";
                return false;
            }
    // As mcstat checks a command's modifiers: an unknown key is named with the nearest accepted
    // one (the deprecated options keep their messages).
    std::map<std::string, std::string> checked = r.kv;
    if (!r.deprecated && !mcstat::checkModifiers(r.context, op->params, checked, err)) return false;
    return mcstat::parseOperationParams(*op, r.kv, values, err, r.context);
}

/// A render to do, its options checked.
struct Job {
    RenderOptions opt;
    Scene scene;
    mcstat::ParamValues onlineValues;  ///< the online operation's parameters (the entry's)
    /// The operation asked to run online (--online NAME), empty for none, and the option that
    /// asked for it (for messages).
    std::string onlineName, onlineFlag;
    bool deprecatedFlag = false;  ///< asked for by --pajot or --reweight
    bool wantPajot = false;       ///< Pajot asked for (its learning phase has a warning)
    /// The online run (--online, or a resumed file's state), started once the size is known.
    std::unique_ptr<mcstat::OnlineRun> online;
    int64_t maxSampleBytes = 0;
    std::array<double, 3> luma{};  ///< the working space's luma (for --online or --compact)
};

/// Checks every option but the output's into `job` and loads the scene.
bool prepareJob(const CommandLine& cl, Job& job, std::string& err) {
    if (!parseRenderOptions(cl, job.opt, err)) return false;
    if (!loadSizedScene(cl, job.scene, err)) return false;
    // The operation run online and the records (format version 4).
    std::vector<OnlineRequest> asked;
    if (!onlineRequests(cl, asked, err)) return false;
    if (asked.size() > 1) {
        err = asked[0].flag + " and " + asked[1].flag +
              " cannot be combined: a file keeps one operation's state";
        return false;
    }
    if (!asked.empty()) {
        job.onlineName = asked[0].name;
        job.onlineFlag = asked[0].flag;
        job.deprecatedFlag = asked[0].deprecated;
        job.wantPajot = job.onlineName == "pajot";
    }
    // Before any sample: a config that cannot give the luma fails now, not after the render.
    if ((!job.onlineName.empty() || cl.compact) && !luma(job.luma, err)) return false;
    if (!asked.empty() && !parseOnlineParams(asked[0], job.onlineValues, err)) return false;
    int64_t v = 0;
    if (!parseInt(cl.maxSampleBytesText, "--max-sample-bytes", 0, (1LL << 62), v, err))
        return false;
    job.maxSampleBytes = v;
    return true;
}

/// --timings: the render (scene setup included) and the writing of the output, measured apart
/// because the file's cost grows with M while the accumulation's must not.
struct Timings {
    Stopwatch renderClock, writeClock;
    double renderWall = 0, renderCpu = 0;

    /// Ends the render's measure and starts the write's.
    void renderDone() {
        renderWall = renderClock.wall(), renderCpu = renderClock.cpu();
        writeClock = Stopwatch();
    }
};

/// --reference: renders the mean alone and writes it as a plain RGB EXR.
bool renderReferenceOutput(const CommandLine& cl, const Job& job, RenderStats& stats,
                           Timings& timings, std::string& err) {
    if (!job.onlineName.empty() || cl.keepSamples || !cl.resumePath.empty() || cl.aovs) {
        err =
            "--reference writes a plain EXR: --online (--pajot, --reweight), --keep-samples, "
            "--aovs and --resume do not apply";
        return false;
    }
    std::vector<float> rgb;
    timings.renderClock = Stopwatch();
    if (!renderReference(job.scene, job.opt, rgb, err, &stats)) return false;
    timings.renderDone();
    return writeReferenceExr(cl.outPath, job.scene.width, job.scene.height, rgb, kRenderColorSpace,
                             job.opt.seed, job.opt.spp, err);
}

/// Starts the online run: --online's, continuing the state parts of the resumed file `ph` (when
/// it has some). The owner's registry entry decodes the state and checks that --online's
/// parameters are the resumed run's.
bool startOnline(const CommandLine& cl, const mcstat::StatsHeader* ph, Job& job, std::string& err) {
    const bool resumed = ph != nullptr && ph->hasState();
    const bool wanted = !job.onlineName.empty();
    const std::string& flag = job.onlineFlag;
    if (!resumed && !wanted) return true;
    if (!resumed && ph != nullptr) {
        const std::string what = job.wantPajot ? std::string("Pajot state")
                                 : job.onlineName == "reweight"
                                     ? std::string("reweighting cascades")
                                     : job.onlineName + "'s state";
        err = cl.resumePath + ": has no " + what + " to continue (rendered without " + flag + ")";
        return false;
    }
    const std::string name = resumed ? ph->state.operation : job.onlineName;
    const mcstat::Operation* op = mcstat::findOperation(name);
    if (op == nullptr || op->state.start == nullptr) {
        err = cl.resumePath + ": holds the state of '" + mcstat::printable(name) +
              "', which this renderer cannot continue";
        return false;
    }
    if (resumed && wanted && name != job.onlineName) {
        err = cl.resumePath + ": holds the state of '" + mcstat::printable(name) + "', not of " +
              flag;
        return false;
    }
    mcstat::ParamValues values = job.onlineValues;  // without the flag: the defaults, "stored"
    if (!wanted && !mcstat::parseOperationParams(*op, {}, values, err)) return false;
    mcstat::PixelStateParts parts;
    if (resumed && !mcstat::readPixelStateParts(cl.resumePath, parts, err)) return false;
    const size_t pixels = size_t(job.scene.width) * size_t(job.scene.height);
    job.online =
        op->state.start(values, job.luma, job.scene.width, pixels, resumed ? &parts : nullptr, err);
    if (!job.online) {
        err = (resumed ? cl.resumePath : flag) + ": " + err;
        return false;
    }
    return true;
}

/// --resume: reads the file to continue into `prev` and sets `job` to render the samples it
/// lacks (same seed and M, from its last sample on).
bool prepareResume(const CommandLine& cl, Job& job, mcstat::StatsImage& prev, std::string& err) {
    const std::string& resumePath = cl.resumePath;
    RenderOptions& opt = job.opt;
    const Scene& scene = job.scene;
    const int64_t totalSpp = opt.spp;
    if (cl.keepSamples) {
        err =
            "--resume with --keep-samples is not supported: the records of the "
            "earlier render would have to be interleaved row by row";
        return false;
    }
    if (!mcstat::readStatsFile(resumePath, prev, err)) return false;
    const mcstat::StatsHeader& ph = prev.header;
    if (ph.renderer != kRendererName || ph.adaptiveM || ph.assignment != "roundrobin") {
        err = resumePath + ": only a fixed-M file written by " + kRendererName + " can be resumed";
        return false;
    }
    if (ph.width != scene.width || ph.height != scene.height) {
        err = fmt::format("{}: the file is {}x{}, the scene {}x{}", resumePath, ph.width, ph.height,
                          scene.width, scene.height);
        return false;
    }
    if (!parseSeed(ph.seeds, opt.seed, err, "mcstat:seeds of the resumed file")) {
        err = resumePath + ": " + err;
        return false;
    }
    for (float c : prev.count)
        if (double(c) != double(ph.spp)) {
            err = resumePath + ": its pixels do not all hold mcstat:spp samples";
            return false;
        }
    if (totalSpp <= ph.spp) {
        err = fmt::format(
            "--spp {}: the resumed file already has {} samples per "
            "pixel; --spp is the total wanted",
            totalSpp, ph.spp);
        return false;
    }
    if (cl.aovs != !ph.aovs.empty()) {
        err = resumePath + (cl.aovs ? ": has no AOVs to continue (rendered without --aovs)"
                                    : ": has AOVs: resume it with --aovs");
        return false;
    }
    opt.M = ph.M;
    opt.firstSample = ph.spp;
    opt.spp = totalSpp - ph.spp;
    return startOnline(cl, &ph, job, err);
}

/// --keep-samples: opens the records next to the output and has the render write them.
bool openRecords(const CommandLine& cl, const Job& job, mcstat::SampleRecordsWriter& records,
                 RenderExtras& extras, std::string& err) {
    const Scene& scene = job.scene;
    mcstat::StatsHeader recHeader;
    recHeader.width = scene.width;
    recHeader.height = scene.height;
    recHeader.formatVersion = mcstat::kStatsFormatVersionSamples;
    if (cl.aovs) recHeader.aovs = fixtureAovChannels();
    std::vector<std::string> fields = recordFieldsFor(scene);
    if (cl.aovs) fields.emplace_back(mcstat::kRecordFieldAov);
    std::vector<std::string> channels;
    if (!mcstat::recordChannelsOf(fields, channels, err, recHeader.aovs)) return false;
    const int64_t perSample = mcstat::recordBytesOnDisk(channels.size());
    const double bytes =
        double(scene.width) * double(scene.height) * double(job.opt.spp) * double(perSample);
    if (bytes > double(job.maxSampleBytes)) {
        err = fmt::format(
            "--keep-samples: {}x{} pixels x {} spp x {} bytes = {:.4g} bytes of records "
            "exceed --max-sample-bytes {}; raise it or lower --spp or --res",
            scene.width, scene.height, job.opt.spp, perSample, bytes, job.maxSampleBytes);
        return false;
    }
    if (!records.open(cl.outPath, recHeader, err, fields)) return false;
    extras.recordChannels = records.channels();
    extras.records = [&records](const mcstat::SampleBlock& b, std::string& e) {
        return records.write(b, e);
    };
    return true;
}

/// Renders the statistics file (continuing --resume's file, with Pajot and records when asked)
/// and writes it.
bool renderStatsOutput(const CommandLine& cl, Job& job, RenderStats& stats, Timings& timings,
                       std::string& err) {
    mcstat::StatsImage prev;
    const int64_t totalSpp = job.opt.spp;
    if (!cl.resumePath.empty() && !prepareResume(cl, job, prev, err)) return false;
    if (cl.resumePath.empty() && !startOnline(cl, nullptr, job, err)) return false;
    mcstat::SampleRecordsWriter records;
    RenderExtras extras;
    extras.online = job.online.get();
    if (cl.keepSamples && !openRecords(cl, job, records, extras, err)) return false;
    if (job.wantPajot && job.online->learningSamples() > totalSpp)
        fmt::print(stderr,
                   "mcstat-render: warning: {}{} exceeds --spp {}: no pixel ends its "
                   "learning phase, and the Pajot estimate is the plain mean\n",
                   job.deprecatedFlag ? std::string("--pajot-n ") : job.onlineFlag + ":n=",
                   job.online->learningSamples(), totalSpp);
    mcstat::StatsImage img;
    timings.renderClock = Stopwatch();
    if (!render(job.scene, job.opt, img, err, &stats, &extras)) return false;
    if (!cl.resumePath.empty()) {
        mcstat::StatsImage merged;
        img.header.seeds.clear();  // the same seed, later samples: no overlap
        if (!mcstat::mergeStats(prev, img, merged, err)) return false;
        merged.header.seeds = prev.header.seeds;
        merged.header.renderer = kRendererName;
        img = std::move(merged);
    }
    timings.renderDone();
    mcstat::StatsExtras ex;
    mcstat::PixelStateParts state;
    if (job.online) {
        if (!job.online->encode(state, err)) {
            err = cl.outPath + ": " + err;
            return false;
        }
        ex.state = &state;
        img.header.state = state.owner;
    }
    if (cl.keepSamples) {
        if (!records.close(err)) return false;
        ex.recordsFile = records.path();
    }
    img.header.hasRecords = cl.keepSamples;
    img.header.formatVersion =
        std::max(img.header.formatVersion, mcstat::requiredFormatVersion(img.header));
    if (cl.compact) {  // decided now that every sample is in (docs/compact.md)
        mcstat::CompactRule rule;
        rule.luma = job.luma;
        mcstat::StatsImage small;
        if (!mcstat::compactStats(img, rule, small, err, job.opt.threads)) return false;
        return mcstat::writeStatsFile(cl.outPath, small, err);
    }
    return mcstat::writeStatsFile(cl.outPath, img, ex, err);
}

/// Prints what --timings asks for, the dropped samples and, on a terminal, the summary lines.
void report(const CommandLine& cl, const Job& job, const RenderStats& stats,
            const Timings& timings) {
    const RenderOptions& opt = job.opt;
    const Scene& scene = job.scene;
    if (cl.timings)
        fmt::print(stderr,
                   "mcstat-render: timings: render wall {:.4f} s cpu {:.4f} s, write wall {:.4f} "
                   "s cpu {:.4f} s\n",
                   timings.renderWall, timings.renderCpu, timings.writeClock.wall(),
                   timings.writeClock.cpu());
    if (stats.nonFiniteSamples > 0)
        fmt::print(stderr,
                   "mcstat-render: warning: {} samples with NaN/Inf radiance were dropped\n",
                   stats.nonFiniteSamples);
    if (cl.quiet || !mcstat::Progress::onTerminal()) return;
    fmt::print(stderr, "mcstat-render: {} ({}x{}, {} spp) in {:.2f} s -> {}\n", scene.source,
               scene.width, scene.height, opt.spp, stats.seconds, cl.outPath);
    if (opt.adaptiveM && !cl.reference && opt.strategy == AdaptiveStrategy::Pilot)
        fmt::print(stderr,
                   "mcstat-render: adaptive M: pilot {} spp ({:.2f} s), sigma_image {:.6g}, "
                   "{:.4f} buffers per pixel (M_max {})\n",
                   stats.pilotSamples, stats.pilotSeconds, stats.sigmaImage, stats.meanBuffers,
                   opt.mMax);
    if (opt.adaptiveM && !cl.reference && opt.strategy == AdaptiveStrategy::Grow) {
        for (const GrowCheckpoint& cp : stats.checkpoints)
            fmt::print(stderr,
                       "mcstat-render: adaptive M: checkpoint at {} spp: sigma_image {:.6g}, "
                       "{} pixels grew, {:.4f} buffers per pixel\n",
                       cp.samples, cp.sigmaImage, cp.grownPixels, cp.meanBuffers);
        fmt::print(stderr, "mcstat-render: adaptive M: {:.4f} buffers per pixel (M_max {})\n",
                   stats.meanBuffers, opt.mMax);
    }
}

}  // namespace

namespace {

int runRender(int argc, const char** argv) {
    // Ctrl-C or a kill removes the temporary files of the output (the target is never touched).
    mcstat::removeTemporariesOnSignals();
    CommandLine cl;
    int exitCode = 0;
    if (!parseCommandLine(argc, argv, cl, exitCode)) return exitCode;
    Job job;
    std::string err;
    if (!prepareJob(cl, job, err)) return fail(err);
    RenderStats stats;
    Timings timings;
    const bool written = cl.reference ? renderReferenceOutput(cl, job, stats, timings, err)
                                      : renderStatsOutput(cl, job, stats, timings, err);
    if (!written) return fail(err);
    report(cl, job, stats, timings);
    return 0;
}

}  // namespace

int main(int argc, const char** argv) {
    // The test suites' helpers start one renderer as a fork server
    // (mcstat/core/detail/fork_server.h).
    if (const int socket = mcstat::detail::forkServerSocket(); socket >= 0)
        return mcstat::detail::serveForks(socket, [](int n, char** args) {
            return runRender(n, const_cast<const char**>(args));
        });
    return runRender(argc, argv);
}
