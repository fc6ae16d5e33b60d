// The tests' fork server (tests/tool_run.h, mcstat/core/detail/fork_server.h): a command line runs
// as the shell would run it, split and unquoted as sh splits it, with the same status, output and
// files, and anything the server cannot reproduce goes to the shell.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <dirent.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <string>
#include <vector>

#include "cli_support.h"

namespace {

using mcstat::testing::parseShellCommand;
using mcstat::testing::runCommand;
using mcstat::testing::slurp;

std::vector<std::string> words(const std::string& line) {
    const auto cmd = parseShellCommand(line);
    return cmd ? cmd->words : std::vector<std::string>{"<none>"};
}

TEST(ShellCommand, SplitsAndUnquotesAsShDoes) {
    // sh itself is the reference: printf prints each word it was given in angle brackets.
    const std::vector<std::string> lines = {
        "a 'b c' \"d\\\"e\" f\\ g '' \"\" h",
        "--gmon:ci=0.95 -o 'out dir/x.exr' a#b",
        "\"back\\\\slash\" 'it''s' \"tab\there\" x=y \\'",
        "  spaced   out\t",
        "\"keeps \\n and \\q\" 'and $HOME in single quotes'",
    };
    for (const std::string& args : lines) {
        const auto cmd = parseShellCommand("printf '<%s>' " + args);
        ASSERT_TRUE(cmd) << args;
        std::string ours;
        for (size_t i = 2; i < cmd->words.size(); ++i) ours += "<" + cmd->words[i] + ">";
        FILE* sh = ::popen(("printf '<%s>' " + args).c_str(), "r");
        ASSERT_NE(sh, nullptr);
        std::string theirs;
        char buf[256];
        for (size_t n; (n = std::fread(buf, 1, sizeof buf, sh)) > 0;) theirs.append(buf, n);
        ::pclose(sh);
        EXPECT_EQ(ours, theirs) << args;
    }
}

TEST(ShellCommand, ReadsTheFolderAndTheRedirections) {
    auto cmd = parseShellCommand("cd '/tmp/a b' && /bin/x y >o.txt 2>'e f.txt'");
    ASSERT_TRUE(cmd);
    EXPECT_EQ(cmd->cwd, "/tmp/a b");
    EXPECT_EQ(cmd->words, (std::vector<std::string>{"/bin/x", "y"}));
    EXPECT_EQ(cmd->out, "o.txt");
    EXPECT_EQ(cmd->err, "e f.txt");
    // Only an unquoted 2 that touches `>` names stderr; any other word before it is an argument.
    cmd = parseShellCommand("x a2>f");
    ASSERT_TRUE(cmd);
    EXPECT_EQ(cmd->words, (std::vector<std::string>{"x", "a2"}));
    EXPECT_EQ(cmd->out, "f");
    cmd = parseShellCommand("x '2'>f 2 >g");  // two stdout files: the shell's to open
    EXPECT_FALSE(cmd);
    cmd = parseShellCommand("x '2'>f 2 ");
    ASSERT_TRUE(cmd);
    EXPECT_EQ(cmd->words, (std::vector<std::string>{"x", "2", "2"}));
    EXPECT_EQ(cmd->out, "f");
    cmd = parseShellCommand("x \\2>f");  // an escaped 2 is a word, as a quoted one
    ASSERT_TRUE(cmd);
    EXPECT_EQ(cmd->words, (std::vector<std::string>{"x", "2"}));
    EXPECT_EQ(cmd->out, "f");
    EXPECT_EQ(cmd->err, "");
    cmd = parseShellCommand("x 2>f");
    ASSERT_TRUE(cmd);
    EXPECT_EQ(cmd->err, "f");
    EXPECT_EQ(cmd->out, "");
}

TEST(ShellCommand, LeavesEverythingElseToTheShell) {
    for (const char* line : {"x | y",
                             "x $HOME",
                             "x \"$HOME\"",
                             "x `y`",
                             "x *.exr",
                             "x r?.exr",
                             "x [ab].exr",
                             "x ~/a",
                             "x; y",
                             "x && y",
                             "x & ",
                             "x >>f",
                             "x 2>&1",
                             "x >&2",
                             "x <f",
                             "x #c",
                             "x >a >b",
                             "cd a",
                             "cd a && cd b && x",
                             "x 'open",
                             "x \"open",
                             "x >",
                             "x > ''",
                             "x {a,b}",
                             "(x)",
                             "x !y",
                             "x\ny",
                             "x \\"})
        EXPECT_EQ(words(line), std::vector<std::string>{"<none>"}) << line;
}

class ForkServer : public mcstat::testing::CliFixture {
  protected:
    /// Runs `line` (which must not redirect) through runCommand and through the shell, each with
    /// its own output files, and expects the same status and output.
    void expectSameAsTheShell(const std::string& line) {
        const std::string a = path("fork"), b = path("shell");
        const int viaFork = runCommand(line + " >" + a + ".out 2>" + a + ".err");
        const int viaShell = std::system((line + " >" + b + ".out 2>" + b + ".err").c_str());
        EXPECT_EQ(viaFork, viaShell) << line;
        EXPECT_EQ(slurp(a + ".out"), slurp(b + ".out")) << line;
        EXPECT_EQ(slurp(a + ".err"), slurp(b + ".err")) << line;
    }
    /// The children of this process that run `exe`: the fork servers it started.
    static int serversOf(const std::string& exe) {
        int n = 0;
        DIR* proc = ::opendir("/proc");
        while (const dirent* d = proc ? ::readdir(proc) : nullptr) {
            const std::string pid = d->d_name;
            if (pid.find_first_not_of("0123456789") != std::string::npos) continue;
            const std::string stat = slurp("/proc/" + pid + "/stat");
            const size_t close = stat.rfind(')');
            if (close == std::string::npos) continue;
            int ppid = 0;
            char state = 0;
            if (std::sscanf(stat.c_str() + close + 1, " %c %d", &state, &ppid) != 2) continue;
            char target[4096];
            const ssize_t len =
                ::readlink(("/proc/" + pid + "/exe").c_str(), target, sizeof target);
            if (ppid == ::getpid() && len > 0 && std::string(target, size_t(len)) == exe) ++n;
        }
        if (proc) ::closedir(proc);
        return n;
    }
};

TEST_F(ForkServer, GivesTheShellsStatusOutputAndFiles) {
    const std::string mcstat = MCSTAT_EXE, render = MCSTAT_RENDER_EXE;
    expectSameAsTheShell(mcstat + " --version");
    expectSameAsTheShell(mcstat + " --help");
    expectSameAsTheShell(mcstat + " " + path("missing.mcstat") + " --gmon -o " + path("x.exr"));
    expectSameAsTheShell(mcstat + " --no-such-option");
    expectSameAsTheShell(render + " --version");
    EXPECT_EQ(serversOf(mcstat), 1);  // those ran in forks (a second run reused the server)
    EXPECT_EQ(serversOf(render), 1);
    // Relative names after `cd`: the render, the estimate and the redirection land in the folder.
    ASSERT_EQ(runCommand("cd " + dir + " && " + render +
                         " --quiet --scene default --res 12 8 --spp 8 --M 3 -o 'a b.mcstat'"),
              0);
    ASSERT_EQ(runCommand("cd " + dir + " && " + mcstat + " 'a b.mcstat' --gmon -o f.exr >f.txt"),
              0);
    ASSERT_EQ(
        std::system(("cd " + dir + " && " + mcstat + " 'a b.mcstat' --gmon -o s.exr").c_str()), 0);
    const auto diff = OIIO::ImageBufAlgo::compare(OIIO::ImageBuf(path("f.exr")),
                                                  OIIO::ImageBuf(path("s.exr")), 0.f, 0.f);
    EXPECT_FALSE(diff.error);
    EXPECT_EQ(diff.nfail, 0u);
    EXPECT_EQ(diff.maxerror, 0.0);
    EXPECT_TRUE(OIIO::Filesystem::exists(path("f.txt")));
}

TEST_F(ForkServer, AChangedEnvironmentGoesThroughTheShell) {
    // A variable set after the server started would not reach a fork (the fork's environment is
    // the server's): the state differs, so the command goes through the shell, and gives the same.
    const std::string mcstat = MCSTAT_EXE;
    ASSERT_EQ(runCommand(mcstat + " --version >/dev/null"), 0);
    ASSERT_EQ(serversOf(mcstat), 1);
    const auto before = mcstat::testing::detail::ProcessState::now();
    ::setenv("MCSTAT_FORK_SERVER_TEST", "1", 1);
    EXPECT_FALSE(mcstat::testing::detail::ProcessState::now() == before);
    expectSameAsTheShell(mcstat + " --version");
    ::unsetenv("MCSTAT_FORK_SERVER_TEST");
    EXPECT_TRUE(mcstat::testing::detail::ProcessState::now() == before);
}

}  // namespace
