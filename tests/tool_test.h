// A GoogleTest fixture for end-to-end tests that run the built tools (mcstat, mcstat-render) in a
// scratch folder of their own: MCSTAT_BINARY_DIR/tests/<area>/tmp-<suite>-<test>, removed when
// the test passes, kept for inspection when it fails.
#pragma once

#include <OpenImageIO/filesystem.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "tool_run.h"

namespace mcstat::testing {

struct ToolRun {
    int code = 0;     ///< exit status; -1 when the tool did not exit normally
    std::string err;  ///< everything it wrote to stderr
    std::string out;  ///< everything it wrote to stdout
};

inline std::string slurp(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    std::stringstream s;
    s << f.rdbuf();
    return s.str();
}

class ToolTest : public ::testing::Test {
  protected:
    explicit ToolTest(std::string area) : area_(std::move(area)) {}
    std::string dir;
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        std::string name = std::string(info->test_suite_name()) + "-" + info->name();
        std::replace(name.begin(), name.end(), '/', '_');  // parameterised names have slashes
        dir = std::string(MCSTAT_BINARY_DIR) + "/tests/" + area_ + "/tmp-" + name;
        OIIO::Filesystem::remove_all(dir);
        OIIO::Filesystem::create_directory(dir);
    }
    void TearDown() override {
        if (!HasFailure()) OIIO::Filesystem::remove_all(dir);
    }
    std::string path(const std::string& n) const { return dir + "/" + n; }
    ToolRun run(const std::string& exe, const std::string& args) const {
        const std::string e = path("stderr.txt"), o = path("stdout.txt");
        const int status = runTool(exe, args, o, e);  // as std::system would, without a start
        return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(e), slurp(o)};
    }
    ToolRun render(const std::string& args) const {
        return run(MCSTAT_RENDER_EXE, "--quiet " + args);
    }
    ToolRun mcstat(const std::string& args) const { return run(MCSTAT_EXE, args); }

  private:
    std::string area_;
};

}  // namespace mcstat::testing
