// Frame sequences with oiiotool's syntax and semantics: an argument holding a frame pattern (`#`,
// `@`, `%0Nd`) makes the whole command line run once per frame, the pattern replaced by that
// frame's number. `--frames 1-10x2,15` names the frames; without it they are the frames whose
// files exist for the first input pattern. `--framepadding N` sets the digits of `#` (4),
// `--skip-bad-frames` goes on past a frame that fails, and `--parallel-frames` runs frames as
// separate processes on the cores, their output printed in frame order (each frame's files are the
// same bytes as a serial run's: every command's result is independent of its thread count).
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/strutil.h>
#include <fcntl.h>
#include <fnmatch.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <csignal>
#include <cstdio>
#include <set>

#include "cli.h"
#include "mcstat/core/parallel.h"
#include "mcstat/core/params.h"
#include "mcstat/exr-deep/codec/temp_file.h"

extern char** environ;

namespace mcstat::cli {

using OIIO::Strutil::fmt::format;

namespace {

/// Most frames one command line may name (a typo such as 1-10000000 is refused, not run).
constexpr int64_t kMaxFrames = 1000000;

/// One frame token in an argument: [begin, end) and its digits (0: as many as the number has).
struct FrameToken {
    size_t begin = 0, end = 0;
    int digits = 0;
};

/// The frame tokens of `arg`: runs of '#' (`padding` digits each), runs of '@' (one digit each),
/// `%d` and `%0Nd`.
std::vector<FrameToken> frameTokens(const std::string& arg, int padding) {
    std::vector<FrameToken> out;
    for (size_t i = 0; i < arg.size();) {
        const char c = arg[i];
        if (c == '#' || c == '@') {
            size_t j = i;
            while (j < arg.size() && arg[j] == c) ++j;
            out.push_back({i, j, int(j - i) * (c == '#' ? padding : 1)});
            i = j;
        } else if (c == '%') {
            size_t j = i + 1;
            int digits = 0;
            if (j < arg.size() && arg[j] == '0') {
                ++j;
                while (j < arg.size() && std::isdigit(static_cast<unsigned char>(arg[j])) &&
                       digits < 100)
                    digits = digits * 10 + (arg[j++] - '0');
            }
            if (j < arg.size() && arg[j] == 'd') {
                out.push_back({i, j + 1, digits});
                i = j + 1;
            } else {
                ++i;
            }
        } else {
            ++i;
        }
    }
    return out;
}

std::string formatFrame(int64_t frame, int digits) {
    const std::string n = std::to_string(frame < 0 ? -frame : frame);
    const std::string pad(n.size() < size_t(digits) ? size_t(digits) - n.size() : 0, '0');
    return (frame < 0 ? "-" : "") + pad + n;
}

std::string expand(const std::string& arg, int64_t frame, int padding) {
    std::string out;
    size_t at = 0;
    for (const FrameToken& t : frameTokens(arg, padding)) {
        out += arg.substr(at, t.begin - at) + formatFrame(frame, t.digits);
        at = t.end;
    }
    return out + arg.substr(at);
}

/// oiiotool's frame ranges: comma-separated N, A-B and A-BxS (every S-th frame), in the order
/// given, each frame once.
bool parseFrameRange(const std::string& text, std::vector<int64_t>& frames, std::string& err) {
    frames.clear();
    std::set<int64_t> seen;
    for (const std::string& item : OIIO::Strutil::splits(text, ",")) {
        // A-B: the dash after the first character (the first may be a minus sign).
        const size_t dash = item.find('-', 1);
        int64_t a = 0, b = 0, step = 1;
        bool ok = true;
        if (dash == std::string::npos) {
            ok = parseIntegerText(item, a);
            b = a;
        } else {
            const std::string rest = item.substr(dash + 1);
            const size_t x = rest.find('x');
            ok = parseIntegerText(item.substr(0, dash), a) &&
                 parseIntegerText(rest.substr(0, x), b) &&
                 (x == std::string::npos || parseIntegerText(rest.substr(x + 1), step));
        }
        if (!ok || step < 1 || item.empty()) {
            err = format("--frames: '{}' is not a frame range (N, A-B, A-BxSTEP, comma-separated)",
                         item);
            return false;
        }
        const int64_t dir = b >= a ? 1 : -1;
        for (int64_t f = a; dir * (b - f) >= 0; f += dir * step) {
            if (seen.insert(f).second) frames.push_back(f);
            if (int64_t(frames.size()) > kMaxFrames) {
                err = format("--frames {}: more than {} frames", text, kMaxFrames);
                return false;
            }
        }
    }
    if (frames.empty()) {
        err = format("--frames '{}': no frame", text);
        return false;
    }
    return true;
}

/// The frames whose files exist for `pattern` (an input argument): its directory listed, the
/// file name matched with the frame tokens as numbers and globs as globs.
bool framesOnDisk(const std::string& pattern, int padding, std::vector<int64_t>& frames,
                  std::string& err) {
    const std::string dir = OIIO::Filesystem::parent_path(pattern);
    const std::string name = OIIO::Filesystem::filename(pattern);
    if (!frameTokens(dir, padding).empty() || dir.find_first_of("*?[") != std::string::npos) {
        err = format(
            "{}: the frames cannot be found on disk when the folder varies; give "
            "--frames",
            pattern);
        return false;
    }
    // A file is frame f when some run of digits in its name is f and the pattern with f in
    // place of its frame tokens matches the name as a glob (fnmatch, as --ingest's globs).
    std::vector<std::string> entries;
    OIIO::Filesystem::get_directory_entries(dir.empty() ? "." : dir, entries, false);
    std::set<int64_t> found;
    for (const std::string& e : entries) {
        const std::string file = OIIO::Filesystem::filename(e);
        for (size_t a = 0; a < file.size();) {
            if (!std::isdigit(static_cast<unsigned char>(file[a]))) {
                ++a;
                continue;
            }
            size_t b = a;
            while (b < file.size() && std::isdigit(static_cast<unsigned char>(file[b]))) ++b;
            const size_t from = a > 0 && file[a - 1] == '-' ? a - 1 : a;
            int64_t f = 0;
            if (b - a <= 18 && parseIntegerText(file.substr(from, b - from), f) &&
                fnmatch(expand(name, f, padding).c_str(), file.c_str(), 0) == 0)
                found.insert(f);
            a = b;
        }
    }
    if (found.empty()) {
        err = format("{}: no file of this frame sequence exists (give --frames to name them)",
                     pattern);
        return false;
    }
    frames.assign(found.begin(), found.end());
    return true;
}

struct FrameRun {
    std::vector<std::string> args;  ///< the command line without the frame options
    std::vector<int64_t> frames;
    std::string range;  ///< --frames' text, "" when not given
    int padding = 4;
    bool parallel = false, skipBad = false;
};

/// Takes the frame options out of `args`. False with `err` for a bad value.
bool takeFrameOptions(const std::vector<std::string>& args, FrameRun& run, std::string& err) {
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        if (a == "--frames" || a == "--framepadding") {
            if (i + 1 >= args.size()) {
                err = format("{} needs an argument", a);
                return false;
            }
            const std::string& v = args[++i];
            int64_t n = 0;
            if (a == "--frames") {
                run.range = v;
            } else if (!parseInt(v, a, 1, 20, n, err)) {
                err = format("--framepadding: expected 1..20 digits, not '{}'", v);
                return false;
            } else {
                run.padding = int(n);
            }
        } else if (a == "--parallel-frames") {
            run.parallel = true;
        } else if (a == "--skip-bad-frames") {
            run.skipBad = true;
        } else {
            run.args.push_back(a);
        }
    }
    return true;
}

/// Runs one frame as a child process (the same program), its stdout and stderr into files.
pid_t spawnFrame(const std::vector<std::string>& args, const std::string& out,
                 const std::string& errPath) {
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    posix_spawn_file_actions_addopen(&fa, 2, errPath.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    std::vector<char*> argv;
    std::string self = "/proc/self/exe";
    argv.push_back(self.data());
    std::vector<std::string> copy = args;
    for (std::string& a : copy) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_t pid = -1;
    if (posix_spawn(&pid, "/proc/self/exe", &fa, nullptr, argv.data(), environ) != 0) pid = -1;
    posix_spawn_file_actions_destroy(&fa);
    return pid;
}

void copyFile(const std::string& path, std::FILE* to) {
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) return;
    char buf[65536];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) std::fwrite(buf, 1, n, to);
    std::fclose(f);
    std::fflush(to);
}

/// Frame statuses that are not exit codes.
constexpr int kNotAttempted = -1;  ///< never started: an earlier frame failed
constexpr int kStopped = -2;       ///< started, then stopped (SIGTERM) when an earlier frame failed

/// --parallel-frames: up to one process per core, output printed in frame order. Returns each
/// frame's exit status, or kNotAttempted / kStopped. As the serial run (and oiiotool), it stops
/// at the first frame that fails unless --skip-bad-frames: no later frame is started, and later
/// frames still running are stopped (their handlers remove their temporary files, so their
/// targets stay as they were). Later frames that had already finished keep their outputs; the
/// summary says which.
std::vector<int> runParallel(const FrameRun& run) {
    const size_t n = run.frames.size();
    const int jobs = int(std::min<size_t>(n, size_t(threadCount(0))));
    // Each frame gets its share of the cores unless the command line says otherwise.
    const bool hasThreads =
        std::find(run.args.begin(), run.args.end(), "--threads") != run.args.end();
    const std::string stem =
        format("{}/mcstat-frames-{}-", OIIO::Filesystem::temp_directory_path(), getpid());
    auto outPath = [&](size_t i) { return stem + std::to_string(i) + ".out"; };
    auto errPath = [&](size_t i) { return stem + std::to_string(i) + ".err"; };
    std::vector<int> status(n, kNotAttempted);
    std::vector<pid_t> pids(n, -1);
    std::vector<bool> finished(n, false);
    size_t next = 0, firstFailed = n;
    int running = 0;
    const auto failedFrame = [&](int st) { return st != 0 && st != 2 && st != kStopped; };
    // Prints the output of the finished frames that follow the last frame printed, in order.
    size_t toPrint = 0;
    const auto printInOrder = [&] {
        for (; toPrint < n && finished[toPrint]; ++toPrint) {
            copyFile(outPath(toPrint), stdout);
            copyFile(errPath(toPrint), stderr);
            OIIO::Filesystem::remove(outPath(toPrint));
            OIIO::Filesystem::remove(errPath(toPrint));
        }
    };
    while (true) {
        while (firstFailed == n && running < jobs && next < n) {
            std::vector<std::string> args = {kFrameContextArg, std::to_string(run.frames[next])};
            if (!hasThreads) {
                args.push_back("--threads");
                args.push_back(std::to_string(std::max(1, threadCount(0) / jobs)));
            }
            for (const std::string& a : run.args)
                args.push_back(expand(a, run.frames[next], run.padding));
            pids[next] = spawnFrame(args, outPath(next), errPath(next));
            if (pids[next] >= 0) {
                ++running;
            } else {
                std::fprintf(stderr, "mcstat: frame %lld: could not start a process\n",
                             (long long)run.frames[next]);
                status[next] = 1;
                finished[next] = true;
                if (!run.skipBad) firstFailed = std::min(firstFailed, next);
            }
            ++next;
        }
        if (running == 0) break;
        int ws = 0;
        const pid_t pid = waitpid(-1, &ws, 0);
        if (pid < 0) break;
        size_t i = 0;
        while (i < next && pids[i] != pid) ++i;
        if (i == next) continue;  // not one of ours
        --running;
        finished[i] = true;
        const int code = WIFEXITED(ws) ? WEXITSTATUS(ws) : 128 + WTERMSIG(ws);
        // A frame asked to stop that had finished all the same (it exited before the signal
        // came) counts as done: its output exists, and the summary must not call it stopped.
        if (status[i] != kStopped || (WIFEXITED(ws) && (code == 0 || code == 2))) status[i] = code;
        if (!run.skipBad && failedFrame(status[i]) && i < firstFailed) {
            firstFailed = i;
            for (size_t j = i + 1; j < next; ++j)
                if (pids[j] >= 0 && !finished[j]) {
                    status[j] = kStopped;
                    kill(pids[j], SIGTERM);
                }
        }
        printInOrder();
    }
    finished.assign(n, true);  // what never started has nothing to print
    printInOrder();
    return status;
}

}  // namespace

bool hasFramePattern(const std::vector<std::string>& args) {
    for (const std::string& a : args)
        if (a == "--frames" || a == "--parallel-frames" || !frameTokens(a, 4).empty()) return true;
    return false;
}

int runFrames(const std::vector<std::string>& all) {
    FrameRun run;
    std::string err;
    if (!takeFrameOptions(all, run, err)) {
        std::fprintf(stderr, "mcstat: %s\n", oneLine(err).c_str());
        return 1;
    }
    // The first argument with a frame pattern that is neither an output nor a command (whose
    // modifiers may hold one: --ingest:seed=shot_s{seed}.#.exr) names the frames on disk.
    std::string input;
    bool anyPattern = false;
    for (size_t i = 0; i < run.args.size(); ++i) {
        if (frameTokens(run.args[i], run.padding).empty()) continue;
        anyPattern = true;
        const bool output = i > 0 && OIIO::Strutil::starts_with(run.args[i - 1], "-o") &&
                            (run.args[i - 1].size() == 2 || run.args[i - 1][2] == ':');
        const bool command = run.args[i][0] == '-';
        if (!output && !command && input.empty()) input = run.args[i];
    }
    if (!anyPattern) {
        std::fprintf(stderr,
                     "mcstat: --frames and --parallel-frames need a frame pattern in a file name "
                     "(#, @, %%0Nd; e.g. shot.#.exr)\n");
        return 1;
    }
    if (!run.range.empty()) {
        if (!parseFrameRange(run.range, run.frames, err)) {
            std::fprintf(stderr, "mcstat: %s\n", oneLine(err).c_str());
            return 1;
        }
    } else if (input.empty() || !framesOnDisk(input, run.padding, run.frames, err)) {
        if (input.empty()) err = "only output names hold a frame pattern: give --frames";
        std::fprintf(stderr, "mcstat: %s\n", oneLine(err).c_str());
        return 1;
    }
    // Every frame writing one file: the last would win, and parallel frames race for it.
    if (run.frames.size() > 1)
        for (size_t i = 1; i < run.args.size(); ++i) {
            const std::string& o = run.args[i - 1];
            const bool output =
                OIIO::Strutil::starts_with(o, "-o") && (o.size() == 2 || o[2] == ':');
            if (!output || !frameTokens(run.args[i], run.padding).empty()) continue;
            const std::string& name = run.args[i];
            const size_t dot = name.rfind('.');
            const std::string suggestion =
                dot == std::string::npos || dot == 0 || name.find('/', dot) != std::string::npos
                    ? name + ".#"
                    : name.substr(0, dot) + ".#" + name.substr(dot);
            std::fprintf(stderr,
                         "mcstat: %s %s: every one of the %zu frames of %s would write this one "
                         "file (the last would win); put a frame pattern in the output name, "
                         "e.g. %s\n",
                         o.c_str(), oneLine(name).c_str(), run.frames.size(),
                         input.empty() ? "--frames" : oneLine(input).c_str(),
                         oneLine(suggestion).c_str());
            return 1;
        }
    std::vector<int> status(run.frames.size(), kNotAttempted);
    if (run.parallel && run.frames.size() > 1) {
        status = runParallel(run);
    } else {
        for (size_t i = 0; i < run.frames.size(); ++i) {
            const int64_t f = run.frames[i];
            std::vector<std::string> args;
            for (const std::string& a : run.args) args.push_back(expand(a, f, run.padding));
            status[i] = runOnce(args, format("frame {}: ", f));
            if (!run.skipBad && status[i] != 0 && status[i] != 2) break;
        }
    }
    int worst = 0;
    std::vector<std::string> failed, stopped, notAttempted;
    for (size_t i = 0; i < status.size(); ++i) {
        const std::string f = std::to_string(run.frames[i]);
        if (status[i] == 2) worst = std::max(worst, 2);
        if (status[i] > 0 && status[i] != 2) failed.push_back(f);
        if (status[i] == kStopped) stopped.push_back(f);
        if (status[i] == kNotAttempted) notAttempted.push_back(f);
    }
    if (!failed.empty()) {
        // What was not done is said as plainly as what failed: a farm reruns exactly those.
        const auto list = [](const std::vector<std::string>& v) {
            return v.size() <= 20 ? OIIO::Strutil::join(v, ", ")
                                  : OIIO::Strutil::join(
                                        std::vector<std::string>(v.begin(), v.begin() + 20), ", ") +
                                        format(", ... ({} in all)", v.size());
        };
        std::string rest;
        if (!stopped.empty()) rest += format("; stopped when it failed: {}", list(stopped));
        if (!notAttempted.empty()) rest += format("; not attempted: {}", list(notAttempted));
        std::fprintf(stderr, "mcstat: %zu of %zu frames failed: %s%s%s\n", failed.size(),
                     run.frames.size(), list(failed).c_str(), rest.c_str(),
                     run.skipBad || (stopped.empty() && notAttempted.empty())
                         ? ""
                         : " (--skip-bad-frames goes on past a failed frame)");
        return 1;
    }
    return worst;
}

}  // namespace mcstat::cli
