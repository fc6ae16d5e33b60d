// The file is a standard multi-part OpenEXR file: Debian's exrheader and oiiotool read it.
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cstdio>

#include "mcstat/exr-deep/stats_file.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

/// Runs `cmd` through the shell; returns its exit status and fills `out` with stdout+stderr.
int run(const std::string& cmd, std::string& out) {
    out.clear();
    FILE* p = ::popen((cmd + " 2>&1").c_str(), "r");
    if (p == nullptr) return -1;
    std::array<char, 4096> buf{};
    size_t n = 0;
    while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) out.append(buf.data(), n);
    const int status = ::pclose(p);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string writeSample(const ScratchDir& dir) {
    const std::string path = dir.file("tool.mcstat");
    std::string err;
    const StatsImage img = renderImage(8, 6, 2, 4, [](int x, int) { return 1 + x; });
    EXPECT_TRUE(writeStatsFile(path, img, err)) << err;
    return path;
}

TEST(ExrTools, ExrheaderListsAllParts) {
    if (::access("/usr/bin/exrheader", X_OK) != 0) GTEST_SKIP() << "no /usr/bin/exrheader";
    ScratchDir dir;
    const std::string path = writeSample(dir);
    std::string out;
    ASSERT_EQ(run("/usr/bin/exrheader '" + path + "'", out), 0) << out;
    for (const char* name : {"\"beauty\"", "\"buffers\"", "\"moments\"", "\"features\""})
        EXPECT_TRUE(contains(out, name)) << name << "\n" << out;
    EXPECT_TRUE(contains(out, "mcstat:M (type int): 2")) << out;
    EXPECT_TRUE(contains(out, "b001.count, 32-bit floating-point")) << out;
}

TEST(ExrTools, ExrinfoReadsItThroughTheCoreApi) {
    if (::access("/usr/bin/exrinfo", X_OK) != 0) GTEST_SKIP() << "no /usr/bin/exrinfo";
    ScratchDir dir;
    const std::string path = writeSample(dir);
    std::string out;
    ASSERT_EQ(run("/usr/bin/exrinfo -v '" + path + "'", out), 0) << out;
    EXPECT_TRUE(contains(out, "parts: 4")) << out;
    for (const char* name : {"beauty", "buffers", "moments", "features"})
        EXPECT_TRUE(contains(out, std::string(": ") + name)) << name << "\n" << out;
}

TEST(ExrTools, OiiotoolInfoListsAllParts) {
    if (::access("/usr/bin/oiiotool", X_OK) != 0) GTEST_SKIP() << "no /usr/bin/oiiotool";
    ScratchDir dir;
    const std::string path = writeSample(dir);
    std::string out;
    // Without an mcstat plugin on the search path OIIO reads the file with its OpenEXR reader.
    ASSERT_EQ(run("env -u OIIO_LIBRARY_PATH /usr/bin/oiiotool --info -v -a '" + path + "'", out), 0)
        << out;
    for (const char* name : {"beauty", "buffers", "moments", "features"})
        EXPECT_TRUE(contains(out, std::string("\"") + name + "\"")) << name << "\n" << out;
    EXPECT_TRUE(contains(out, "4 subimages")) << out;
}

}  // namespace
}  // namespace mcstat::test
