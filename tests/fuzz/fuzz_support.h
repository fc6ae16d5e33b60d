// Shared by the libFuzzer targets (docs/fuzzing.md): the input as a file, the limits a fuzzed
// file gets, and the contract every rejection must keep. A broken contract aborts, which libFuzzer
// (or the replay driver, fuzz_replay.cpp) reports as a finding.
#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "mcstat/core/untrusted_text.h"
#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::fuzz {

/// The input bytes as a file with a path (/proc/self/fd/N of a memfd): the readers take paths.
/// In memory, so fuzzing does not wear a disk; closed (and gone) when destroyed.
class InputFile {
  public:
    InputFile(const uint8_t* data, size_t size) {
        fd_ = memfd_create("mcstat-fuzz.mcstat", MFD_CLOEXEC);
        if (fd_ < 0) std::abort();
        size_t done = 0;
        while (done < size) {
            const ssize_t n = ::write(fd_, data + done, size - done);
            if (n <= 0) std::abort();
            done += size_t(n);
        }
        path_ = "/proc/self/fd/" + std::to_string(fd_);
    }
    ~InputFile() { ::close(fd_); }
    InputFile(const InputFile&) = delete;
    InputFile& operator=(const InputFile&) = delete;
    const std::string& path() const { return path_; }

  private:
    int fd_ = -1;
    std::string path_;
};

/// Limits small enough that one input never costs more than a few hundred MB (libFuzzer's RSS
/// limit is 2 GB), large enough for every seed.
inline ReadLimits fuzzLimits() {
    ReadLimits limits;
    limits.maxPixels = int64_t(1) << 20;
    limits.maxBytes = int64_t(64) << 20;
    limits.maxDeepSamples = int64_t(1) << 22;
    return limits;
}

/// Stops with a message when `cond` is false: the finding libFuzzer saves.
inline void require(bool cond, const char* what, const std::string& detail) {
    if (cond) return;
    std::fprintf(stderr, "mcstat fuzz contract broken: %s: %s\n", what, detail.c_str());
    std::abort();
}

/// What a target would print holds no byte a terminal acts on: no control byte (newlines only
/// between lines when `lines`), no invalid UTF-8, no C1 or bidirectional control
/// (core/untrusted_text.h). The detail is shown escaped, so the finding's report stays readable.
inline void requirePrintable(const std::string& text, const char* what, bool lines = false) {
    require(isPrintable(text, lines), what, oneLine(text));
}

/// A rejection is one non-empty line of printable text naming the file: "<path>: <problem>".
inline void requireOneLineError(const std::string& path, const std::string& err) {
    require(err.rfind(path + ": ", 0) == 0, "error does not start with the path", err);
    require(err.size() > path.size() + 2, "empty error reason", err);
    require(err.find('\n') == std::string::npos, "error of more than one line", oneLine(err));
    requirePrintable(err, "error holds a control byte or invalid UTF-8");
}

/// --info's description of accepted headers (describeStatsHeader): printable lines.
inline void requirePrintableDescription(const StatsHeader& h) {
    for (const std::string& line : describeStatsHeader(h))
        requirePrintable(line, "--info line holds a control byte or invalid UTF-8");
}

}  // namespace mcstat::fuzz
