// Test support: a scratch directory per test and small file helpers.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace mcstat {
struct StatsImage;
}

namespace mcstat::test {

/// A fresh directory for one test, removed (with its content) on destruction.
class ScratchDir {
  public:
    ScratchDir();
    ~ScratchDir();
    ScratchDir(const ScratchDir&) = delete;
    ScratchDir& operator=(const ScratchDir&) = delete;
    const std::filesystem::path& path() const { return dir_; }
    std::string file(const std::string& name) const { return (dir_ / name).string(); }
    /// Names of every entry in the directory, sorted.
    std::vector<std::string> entries() const;

  private:
    std::filesystem::path dir_;
};

std::vector<unsigned char> readBytes(const std::string& path);
void writeBytes(const std::string& path, const std::vector<unsigned char>& bytes);

/// Writes `img` to `path` with StatsFileWriter in blocks of `blockRows` rows on `threads` threads
/// (gtest failures on error).
void writeByBlocks(const std::string& path, const StatsImage& img, int blockRows, int threads);

/// Whether `haystack` contains `needle`.
bool contains(const std::string& haystack, const std::string& needle);

}  // namespace mcstat::test
