// Help as oiiotool users expect it: --help COMMAND and COMMAND --help (generated from the command
// table, so from the registry's parameters), -h, --version, and "did you mean" for a mistyped
// command, help topic or modifier.
#include <gtest/gtest.h>

#include "cli_support.h"

namespace {

using mcstat::testing::runMcstat;

TEST(Help, OneCommandsHelpWithEveryParameterRangeAndDefault) {
    for (const char* args :
         {"--help gmon", "--help --gmon", "--gmon --help", "--gmon:mode=lum -h"}) {
        const auto r = runMcstat(args);
        EXPECT_EQ(r.code, 0) << args << r.err;
        EXPECT_EQ(r.out.rfind("  --gmon ", 0), 0u) << args << "\n" << r.out;
        EXPECT_NE(r.out.find(":mode=lum ('lum' or 'channel'"), std::string::npos) << r.out;
        EXPECT_NE(r.out.find(":diag=0 (0 or 1"), std::string::npos) << r.out;
        EXPECT_EQ(r.out.find("--mean"), std::string::npos) << "only gmon's help: " << r.out;
    }
    const auto c = runMcstat("--help compare");
    EXPECT_EQ(c.code, 0);
    EXPECT_NE(c.out.find(":level=0.01 (a number in (0, 0.5]"), std::string::npos) << c.out;
    // The whole help: every command.
    const auto all = runMcstat("-h");
    EXPECT_EQ(all.code, 0);
    EXPECT_NE(all.out.find("Usage: mcstat"), std::string::npos);
    EXPECT_NE(all.out.find("  --gmon "), std::string::npos);
    EXPECT_NE(all.out.find("  --compare "), std::string::npos);
}

TEST(Help, VersionAndDidYouMean) {
    const auto v = runMcstat("--version");
    EXPECT_EQ(v.code, 0);
    EXPECT_EQ(v.out, std::string("mcstat ") + MCSTAT_VERSION_TEXT + "\n");

    auto r = runMcstat("--help gmno");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("no such command (did you mean --gmon?)"), std::string::npos) << r.err;
    r = runMcstat("--compre");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("unknown command '--compre' (did you mean --compare?)"), std::string::npos)
        << r.err;
    r = runMcstat("--gmon:mdoe=lum");
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("no modifier 'mdoe' (did you mean mode?)"), std::string::npos) << r.err;
    // Nothing near: no suggestion.
    r = runMcstat("--frobnicate");
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err.find("did you mean"), std::string::npos) << r.err;
}

}  // namespace
