// Untrusted input from the user's side: outputs the writers refuse with a reason, --info against
// --check on files whose values are bad, and interrupted writes that leave nothing behind.
#include <OpenImageIO/filesystem.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <thread>

#include "cli_support.h"
#include "mcstat/exr-deep/stats_file.h"
#include "raw_exr.h"

using namespace mcstat;

namespace {

using mcstat::testing::Result;
using mcstat::testing::slurp;

class Untrusted : public mcstat::testing::CliFixture {
  protected:
    /// A valid 5 x 4 statistics file, M = 3, 4 samples per buffer.
    std::string writeGood(const std::string& name) {
        StatsImage s;
        s.header.width = 5;
        s.header.height = 4;
        s.header.M = 3;
        s.header.spp = 12;
        std::string err;
        EXPECT_TRUE(s.allocate(err)) << err;
        for (size_t p = 0; p < s.pixelCount(); ++p) {
            for (int j = 0; j < 3; ++j) s.bufferCount[p * 3 + j] = 4.f;
            s.count[p] = 12.f;
            for (int c = 0; c < 3; ++c) {
                for (int j = 0; j < 3; ++j) s.bufferMean[(p * 3 + j) * 3 + c] = 0.25f;
                s.mean[p * 3 + c] = s.beauty[p * 3 + c] = 0.25f;
            }
        }
        good = s;
        EXPECT_TRUE(writeStatsFile(path(name), s, err)) << err;
        return path(name);
    }
    StatsImage good;
};

bool oneLine(const std::string& s) { return std::count(s.begin(), s.end(), '\n') == 1; }

// The cases: each refusal names the target and says why, in one line, exit status 1, and
// nothing is written (/dev/null and /dev/full stay devices).
TEST_F(Untrusted, OutputTargetsThatCannotBeWrittenAreOneLineReasons) {
    const std::string f = writeGood("f.mcstat");
    OIIO::Filesystem::create_directory(path("adir"));
    struct Case {
        std::string output, message;
    } cases[] = {
        {path("out.xyz"), path("out.xyz") + ": OpenImageIO has no writer for '.xyz' files"},
        {path("out"), path("out") + ": no file extension to choose the format by"},
        {"''", "-o: an empty file name"},
        {"/dev/full", "/dev/full: is a character device; mcstat writes a temporary file"},
        {"/dev/null", "/dev/null: is a character device; mcstat writes a temporary file"},
        {path("adir"), path("adir") + ": is a directory"},
        {path("no/such/dir/o.exr"), path("no/such/dir/o.exr") + ": cannot write into "},
    };
    for (const Case& c : cases) {
        const Result r = mcstat(f + " --mean -o " + c.output);
        EXPECT_EQ(r.code, 1) << c.output;
        EXPECT_EQ(r.err.rfind("mcstat: " + c.message, 0), 0u) << c.output << " -> " << r.err;
        EXPECT_TRUE(oneLine(r.err)) << r.err;
    }
    // The statistics writer checks its target the same way.
    OIIO::Filesystem::create_directory(path("d.mcstat"));
    const Result r = mcstat(f + " -o " + path("d.mcstat"));
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(r.err, "mcstat: " + path("d.mcstat") + ": is a directory\n");
    struct stat st {};
    ASSERT_EQ(::stat("/dev/null", &st), 0);
    EXPECT_TRUE(S_ISCHR(st.st_mode));
    ASSERT_EQ(::stat("/dev/full", &st), 0);
    EXPECT_TRUE(S_ISCHR(st.st_mode));
    for (const auto& e : std::filesystem::directory_iterator(dir))
        EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
    // The same reason for a user who may not write into /dev/ (issue 48: a plain user was told
    // "cannot write into /dev/"). As root, the tool runs as nobody, from copies of it and of the
    // file in a folder of its own that nobody can reach wherever the build lives (the tool links
    // mcstat's libraries statically).
    std::string prefix, exe = MCSTAT_EXE, input = f;
    char scratch[] = "/tmp/mcstat-untrusted-XXXXXX";
    const bool asNobody = ::geteuid() == 0;
    if (asNobody) {
        if (std::system("command -v setpriv >/dev/null") != 0) return;
        ASSERT_NE(::mkdtemp(scratch), nullptr);
        ASSERT_EQ(::chmod(scratch, 0755), 0);
        exe = std::string(scratch) + "/mcstat";
        input = std::string(scratch) + "/f.mcstat";
        std::filesystem::copy_file(MCSTAT_EXE, exe);
        std::filesystem::copy_file(f, input);
        ASSERT_EQ(::chmod(input.c_str(), 0644), 0);
        prefix = "setpriv --reuid=65534 --regid=65534 --clear-groups ";
    }
    for (const char* device : {"/dev/null", "/dev/full"}) {
        const std::string e = path("dev.stderr");
        std::system((prefix + exe + " " + input + " --mean -o " + device + " 2>" + e).c_str());
        EXPECT_EQ(slurp(e).rfind("mcstat: " + std::string(device) + ": is a character device", 0),
                  0u)
            << slurp(e);
    }
    if (asNobody) std::filesystem::remove_all(scratch);
}

// Policy: a read-only target is refused and kept (oiiotool 2.4 replaces it: docs/untrusted.md).
TEST_F(Untrusted, ReadOnlyTargetIsRefusedAndKept) {
    const std::string f = writeGood("f.mcstat");
    for (const std::string name : {"ro.exr", "ro.mcstat"}) {
        {
            std::ofstream o(path(name));
            o << "keep me";
        }
        ASSERT_EQ(::chmod(path(name).c_str(), 0444), 0);
        const Result r = mcstat(f + (name == "ro.exr" ? " --mean" : "") + " -o " + path(name));
        EXPECT_EQ(r.code, 1) << name;
        EXPECT_EQ(r.err, "mcstat: " + path(name) +
                             ": is read-only; mcstat does not replace read-only files (make it "
                             "writable, e.g. chmod u+w, to allow)\n");
        EXPECT_EQ(slurp(path(name)), "keep me");
        // Writable again, it is replaced.
        ASSERT_EQ(::chmod(path(name).c_str(), 0644), 0);
        EXPECT_EQ(mcstat(f + (name == "ro.exr" ? " --mean" : "") + " -o " + path(name)).code, 0);
        EXPECT_NE(slurp(path(name)), "keep me");
    }
}

// The values --info cannot see: it reads headers and says so; --check decodes everything
// and names the first bad pixel.
TEST_F(Untrusted, InfoReadsHeadersAndCheckValidatesEveryValue) {
    const std::string ok = writeGood("good.mcstat");
    Result r = mcstat(ok + " --check");
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find(ok + ": valid mcstat statistics file, format 1, 5 x 4, M 3"),
              std::string::npos)
        << r.out;
    EXPECT_NE(r.out.find("20 pixels and 60 sub-buffers decoded"), std::string::npos) << r.out;

    struct Case {
        const char* name;
        const char* part;
        const char* channel;
        size_t pixel;
        float value;
        std::string message;
    } cases[] = {
        {"negative", "buffers", "b002.count", 8, -4.f, "pixel (3, 1): buffer 2 count is negative"},
        {"nan", "moments", "count", 14, std::nanf(""), "pixel (4, 2): moments count is NaN"},
        {"fraction", "buffers", "b000.count", 0, 7.5f,
         "pixel (0, 0): buffer 0 count is not an "
         "integer"},
        {"huge", "moments", "count", 3, 33554432.f, "pixel (3, 0): moments count"},
        {"nosum", "moments", "count", 17, 13.f, "pixel (2, 3): buffer counts sum to"},
    };
    for (const Case& c : cases) {
        std::vector<test::RawPart> parts = test::rawPartsFrom(good);
        for (test::RawPart& p : parts)
            if (p.header.name() == c.part) p.values[c.channel][c.pixel] = c.value;
        const std::string file = path(std::string(c.name) + ".mcstat");
        test::writeRaw(file, parts);
        r = mcstat(file + " --info");
        EXPECT_EQ(r.code, 0) << c.name << ": " << r.err;
        EXPECT_NE(r.out.find("checked: the headers and chunk table only; --check"),
                  std::string::npos)
            << r.out;
        r = mcstat(file + " --check");
        EXPECT_EQ(r.code, 1) << c.name;
        EXPECT_EQ(r.err.rfind("mcstat: " + file + ": ", 0), 0u) << r.err;
        EXPECT_NE(r.err.find(c.message), std::string::npos) << c.name << ": " << r.err;
        EXPECT_TRUE(oneLine(r.err)) << r.err;
        EXPECT_TRUE(r.out.empty()) << r.out;
    }
}

/// Starts `argv` with stdout and stderr discarded and the default signal dispositions.
pid_t spawn(const std::vector<std::string>& args) {
    const pid_t pid = ::fork();
    if (pid == 0) {
        std::freopen("/dev/null", "w", stdout);
        std::freopen("/dev/null", "w", stderr);
        for (int s : {SIGINT, SIGTERM, SIGHUP}) ::signal(s, SIG_DFL);
        std::vector<char*> argv;
        for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
        argv.push_back(nullptr);
        ::execv(argv[0], argv.data());
        ::_exit(127);
    }
    return pid;
}

std::vector<std::string> temporaries(const std::string& dir) {
    std::vector<std::string> out;
    for (const auto& e : std::filesystem::directory_iterator(dir))
        if (e.path().filename().string().find(".tmp-") != std::string::npos)
            out.push_back(e.path().filename().string());
    return out;
}

// Kills must not leave temporary files. A render keeping every sample writes its records to a
// temporary from the first row on; SIGINT, SIGTERM and SIGHUP there remove it, and the process
// still ends by the signal (its parent sees what it asked for).
TEST_F(Untrusted, SignalsDuringAWriteRemoveTheTemporaryFile) {
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
        const std::string target = path("r" + std::to_string(sig) + ".mcstat");
        const pid_t pid = spawn({MCSTAT_RENDER_EXE, "--scene", "tiny", "--res", "48", "48", "--spp",
                                 "2000", "--keep-samples", "--threads", "1", "-o", target});
        ASSERT_GT(pid, 0);
        bool seen = false;
        for (int i = 0; i < 400 && !seen; ++i) {  // up to 20 s for the records to start
            seen = !temporaries(dir).empty();
            if (!seen) std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
        ASSERT_TRUE(seen) << "no temporary file appeared";
        ASSERT_EQ(::kill(pid, sig), 0);
        int status = 0;
        ASSERT_EQ(::waitpid(pid, &status, 0), pid);
        EXPECT_TRUE(WIFSIGNALED(status)) << "signal " << sig;
        if (WIFSIGNALED(status)) {
            EXPECT_EQ(WTERMSIG(status), sig);
        }
        EXPECT_TRUE(temporaries(dir).empty()) << temporaries(dir)[0];
        EXPECT_FALSE(std::filesystem::exists(target));
    }
}

// SIGKILL cannot be caught: its temporary stays until the next write to the same target removes
// it (its process is gone).
TEST_F(Untrusted, TemporaryOfAKilledWriteIsRemovedByTheNextWrite) {
    const std::string target = path("k.mcstat");
    const pid_t pid = spawn({MCSTAT_RENDER_EXE, "--scene", "tiny", "--res", "48", "48", "--spp",
                             "2000", "--keep-samples", "--threads", "1", "-o", target});
    ASSERT_GT(pid, 0);
    for (int i = 0; i < 400 && temporaries(dir).empty(); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ASSERT_EQ(::kill(pid, SIGKILL), 0);
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    ASSERT_EQ(temporaries(dir).size(), 1u);
    const std::string f = writeGood("f.mcstat");
    const Result r = mcstat(f + " -o " + target);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(temporaries(dir).empty()) << temporaries(dir)[0];
    EXPECT_TRUE(std::filesystem::exists(target));
}

// A read-only folder: every output format, and the renderer, give the same one-line reason naming
// the target, never the hidden temporary file (issue 34, item 9). Root writes into any folder
// through its capabilities (CAP_DAC_OVERRIDE), so as root the tools run as root without any
// capability (setpriv: empty bounding and inheritable sets): the same user, so they reach
// every file the test made wherever the build lives (a clone under a 0700 home), and a 0555
// folder refuses them as it refuses a plain user (issue 48: they ran as nobody, who cannot
// reach a build under /root).
TEST_F(Untrusted, AReadOnlyFolderIsOneReasonNamingTheTargetForEveryFormat) {
    std::string prefix;
    if (::geteuid() == 0) {
        if (std::system("command -v setpriv >/dev/null") != 0)
            GTEST_SKIP() << "as root the test needs setpriv (util-linux) to drop capabilities";
        prefix = "setpriv --inh-caps=-all --bounding-set=-all ";
    }
    const std::string f = writeGood("f.mcstat");
    const std::string ro = path("ro");
    OIIO::Filesystem::create_directory(ro);
    ASSERT_EQ(::chmod(ro.c_str(), 0555), 0);
    if (!prefix.empty() && std::system((prefix + "test -w " + ro).c_str()) == 0)
        GTEST_SKIP() << ro << " stays writable to root without capabilities here";
    struct Case {
        std::string tool, args, target;
    };
    const std::vector<Case> cases = {
        {MCSTAT_EXE, f + " --mean -o " + ro + "/a.exr", ro + "/a.exr"},
        {MCSTAT_EXE, f + " --mean -o " + ro + "/a.png", ro + "/a.png"},
        {MCSTAT_EXE, f + " --mean -o " + ro + "/a.tif", ro + "/a.tif"},
        {MCSTAT_EXE, f + " -o " + ro + "/a.mcstat", ro + "/a.mcstat"},
        {MCSTAT_RENDER_EXE, "--scene tiny --spp 2 -o " + ro + "/r.mcstat", ro + "/r.mcstat"},
        {MCSTAT_RENDER_EXE, "--scene tiny --spp 2 --reference -o " + ro + "/r.exr", ro + "/r.exr"},
    };
    for (const Case& c : cases) {
        const std::string out = path("ro.stdout"), err = path("ro.stderr");
        const int status =
            std::system((prefix + c.tool + " " + c.args + " >" + out + " 2>" + err).c_str());
        const std::string e = slurp(err);
        EXPECT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 1) << c.args << ": " << e;
        EXPECT_NE(e.find(c.target + ": cannot write into " + ro + "/ (Permission denied)"),
                  std::string::npos)
            << c.args << ": " << e;
        EXPECT_EQ(e.find(".tmp-"), std::string::npos) << e;
        EXPECT_EQ(std::count(e.begin(), e.end(), '\n'), 1) << e;
    }
    ::chmod(ro.c_str(), 0755);
    EXPECT_TRUE(std::filesystem::is_empty(ro));
}

}  // namespace
