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

#include "mcstat/stats_file.h"

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

/// A rejection is one non-empty line naming the file: "<path>: <problem>".
inline void requireOneLineError(const std::string& path, const std::string& err) {
    require(err.rfind(path + ": ", 0) == 0, "error does not start with the path", err);
    require(err.size() > path.size() + 2, "empty error reason", err);
    require(err.find('\n') == std::string::npos, "error of more than one line", err);
}

}  // namespace mcstat::fuzz
