// Running the `mcstat` binary from tests (through its fork server, tool_run.h): stdout and stderr
// captured in files named after the running test, so tests run in parallel (ctest -j) never share
// them.
#pragma once

#include <OpenImageIO/filesystem.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "tool_run.h"

namespace mcstat::testing {

struct Result {
    int code = 0;
    std::string out, err;
};

inline std::string slurp(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    std::stringstream s;
    s << f.rdbuf();
    return s.str();
}

/// Runs `mcstat ARGS` with its output captured in DIR (default: the build's tests/cli folder).
inline Result runMcstat(const std::string& args,
                        const std::string& dir = std::string(MCSTAT_BINARY_DIR) + "/tests/cli") {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    const std::string stem = dir + "/" + info->test_suite_name() + "." + info->name();
    const std::string o = stem + ".stdout", e = stem + ".stderr";
    Result r;
    const int status = runTool(MCSTAT_EXE, args, o, e);
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(o);
    r.err = slurp(e);
    return r;
}

/// A fixture giving each test its own scratch directory (removed afterwards) and `mcstat(args)`
/// run with its output captured there.
class CliFixture : public ::testing::Test {
  protected:
    std::string dir;
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir = std::string(MCSTAT_BINARY_DIR) + "/tests/cli/tmp-" + info->test_suite_name() + "-" +
              info->name();
        OIIO::Filesystem::remove_all(dir);
        OIIO::Filesystem::create_directory(dir);
    }
    void TearDown() override { OIIO::Filesystem::remove_all(dir); }
    std::string path(const std::string& name) const { return dir + "/" + name; }
    Result mcstat(const std::string& args) const { return runMcstat(args, dir); }
};

}  // namespace mcstat::testing
