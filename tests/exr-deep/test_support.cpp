#include "test_support.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <iterator>
#include <memory>
#include <stdexcept>

#include "mcstat/exr-deep/stats_file.h"

namespace mcstat::test {

ScratchDir::ScratchDir() {
    const testing::TestInfo* info = testing::UnitTest::GetInstance()->current_test_info();
    std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "x";
    std::replace(name.begin(), name.end(), '/', '_');
    dir_ = std::filesystem::temp_directory_path() /
           ("mcstat-exrdeep-" + std::to_string(::getpid()) + "-" + name);
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
}

ScratchDir::~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
}

std::vector<std::string> ScratchDir::entries() const {
    std::vector<std::string> out;
    for (const auto& e : std::filesystem::directory_iterator(dir_))
        out.push_back(e.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
}

std::vector<unsigned char> readBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error("cannot open " + path);
    return std::vector<unsigned char>(std::istreambuf_iterator<char>(in),
                                      std::istreambuf_iterator<char>());
}

void writeBytes(const std::string& path, const std::vector<unsigned char>& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    if (!out) throw std::runtime_error("cannot write " + path);
}

bool contains(const std::string& haystack, const std::string& needle) {
    return haystack.find(needle) != std::string::npos;
}

void writeByBlocks(const std::string& path, const StatsImage& img, int blockRows, int threads) {
    MemoryStatsSource src(std::make_shared<const StatsImage>(img), "memory");
    StatsFileWriter w;
    std::string err;
    ASSERT_TRUE(w.open(path, img.header, err, threads)) << err;
    StatsImage block;
    for (int y = 0; y < img.header.height; y += blockRows) {
        ASSERT_TRUE(
            src.read(y, std::min(blockRows, img.header.height - y), kStatsAllParts, block, err))
            << err;
        ASSERT_TRUE(w.write(block, err)) << err;
    }
    ASSERT_TRUE(w.commit(err)) << err;
}

}  // namespace mcstat::test
