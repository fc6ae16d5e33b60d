// The writer replaces the target atomically: on failure there is no new file, an old target keeps
// its content and no temporary file is left behind.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>

#include "mcstat/exr-deep/codec/temp_file.h"
#include "mcstat/exr-deep/stats_file.h"
#include "sample_accumulator.h"
#include "test_support.h"

namespace mcstat::test {
namespace {

StatsImage smallImage() {
    return renderImage(4, 4, 2, 3, [](int, int) { return 4; });
}

TEST(AtomicWrite, NonexistentDirectoryGivesErrorAndNoFile) {
    ScratchDir dir;
    const std::string path = dir.file("no/such/dir/x.mcstat");
    std::string err;
    EXPECT_FALSE(writeStatsFile(path, smallImage(), err));
    EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
    EXPECT_TRUE(contains(err, "No such file or directory")) << err;
    EXPECT_TRUE(dir.entries().empty());
}

TEST(AtomicWrite, InvalidImageKeepsOldContentAndLeavesNoTempFile) {
    ScratchDir dir;
    const std::string path = dir.file("keep.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, smallImage(), err)) << err;
    const auto before = readBytes(path);

    StatsImage bad = renderImage(6, 6, 3, 4, [](int, int) { return 5; });
    bad.count[7] += 1.f;  // counts no longer sum
    EXPECT_FALSE(writeStatsFile(path, bad, err));
    EXPECT_EQ(err.rfind(path + ": ", 0), 0u) << err;
    EXPECT_TRUE(contains(err, "buffer counts sum to")) << err;

    StatsImage wrongSize = smallImage();
    wrongSize.albedo.resize(3);
    EXPECT_FALSE(writeStatsFile(path, wrongSize, err));
    EXPECT_TRUE(contains(err, "Albedo")) << err;

    EXPECT_EQ(readBytes(path), before);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"keep.mcstat"});
}

TEST(AtomicWrite, TargetThatIsADirectoryIsRefusedBeforeWriting) {
    ScratchDir dir;
    const std::string path = dir.file("sub");
    std::filesystem::create_directory(path);
    writeBytes(path + "/inside", {1, 2, 3});
    std::string err;
    EXPECT_FALSE(writeStatsFile(path, smallImage(), err));
    EXPECT_EQ(err, path + ": is a directory");
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"sub"});
    EXPECT_EQ(readBytes(path + "/inside"), (std::vector<unsigned char>{1, 2, 3}));
}

TEST(AtomicWrite, FailedRenameRemovesTheCompleteTempFile) {
    // The target turns into a directory after the checks: the whole file gets written, then
    // rename() fails (EISDIR) and the temporary goes.
    ScratchDir dir;
    const std::string path = dir.file("late");
    std::string err;
    {
        TemporaryFile tmp(path);
        writeBytes(tmp.path(), {1, 2, 3});
        std::filesystem::create_directory(path);
        writeBytes(path + "/inside", {4});
        EXPECT_FALSE(tmp.commit(err));
    }
    EXPECT_EQ(err.rfind(path + ": cannot rename ", 0), 0u) << err;
    EXPECT_TRUE(contains(err, "Is a directory")) << err;
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"late"});
}

TEST(AtomicWrite, ParentIsAFile) {
    ScratchDir dir;
    writeBytes(dir.file("plain"), {7});
    const std::string path = dir.file("plain/x.mcstat");
    std::string err;
    EXPECT_FALSE(writeStatsFile(path, smallImage(), err));
    EXPECT_EQ(err.rfind(path + ": cannot write into ", 0), 0u) << err;
    EXPECT_TRUE(contains(err, "Not a directory")) << err;
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"plain"});
}

TEST(AtomicWrite, UnwritableDirectoryKeepsOldContent) {
    // In-process, so it cannot drop root's capabilities for the write alone; the tools' test
    // (Untrusted.AReadOnlyFolderIsOneReasonNamingTheTargetForEveryFormat) covers root.
    if (::geteuid() == 0) GTEST_SKIP() << "root writes into a 0555 folder (CAP_DAC_OVERRIDE)";
    ScratchDir dir;
    const std::string path = dir.file("ro.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, smallImage(), err)) << err;
    const auto before = readBytes(path);
    ASSERT_EQ(::chmod(dir.path().c_str(), 0555), 0);
    const bool ok = writeStatsFile(path, renderImage(2, 2, 1, 9, [](int, int) { return 1; }), err);
    ::chmod(dir.path().c_str(), 0755);
    EXPECT_FALSE(ok);
    EXPECT_TRUE(contains(err, "Permission denied")) << err;
    EXPECT_EQ(readBytes(path), before);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"ro.mcstat"});
}

TEST(AtomicWrite, DiskFullRemovesTempFileAndKeepsTarget) {
    // A full disk, simulated: with RLIMIT_FSIZE, writes past the limit fail (EFBIG) the way they
    // fail with ENOSPC on a full disk.
    ScratchDir dir;
    const std::string path = dir.file("full.mcstat");
    std::string err;
    ASSERT_TRUE(writeStatsFile(path, smallImage(), err)) << err;
    const auto before = readBytes(path);
    const StatsImage big = renderImage(64, 64, 8, 5, [](int, int) { return 8; });
    // Lower only the soft limit (raised back below); ignore SIGXFSZ so write() fails with EFBIG.
    struct rlimit saved {};
    ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &saved), 0);
    struct rlimit small = saved;
    small.rlim_cur = 4096;
    void (*oldHandler)(int) = ::signal(SIGXFSZ, SIG_IGN);
    ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
    const bool ok = writeStatsFile(path, big, err);
    ::setrlimit(RLIMIT_FSIZE, &saved);
    ::signal(SIGXFSZ, oldHandler);
    EXPECT_FALSE(ok);
    EXPECT_EQ(err.rfind(path + ": cannot write (", 0), 0u) << err;
    EXPECT_TRUE(contains(err, "too large")) << err;  // strerror(EFBIG): "File too large"
    EXPECT_EQ(readBytes(path), before);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"full.mcstat"});
}

/// The pid of a process that has ended (forked, exited and reaped).
long deadPid() {
    const pid_t pid = ::fork();
    if (pid == 0) ::_exit(0);
    int status = 0;
    ::waitpid(pid, &status, 0);
    return long(pid);
}

// Which leftovers a write removes: ours (this host) of processes that are gone; never another
// host's, a live process's, another target's, or a recent one of a former naming without a host.
TEST(AtomicWrite, StaleTemporariesOfThisHostsDeadProcessesAreRemoved) {
    ScratchDir dir;
    const std::string target = dir.file("t.exr");
    std::string host;
    {
        const TemporaryFile probe(target);
        const std::string name = std::filesystem::path(probe.path()).filename().string();
        // ".t.exr.tmp-<pid>-<hex>-<host>"
        host = name.substr(name.find('-', name.find('-', name.find(".tmp-") + 5) + 1) + 1);
    }
    ASSERT_FALSE(host.empty());
    const long dead = deadPid(), alive = long(::getpid());
    auto make = [&](const std::string& name, bool old) {
        writeBytes(dir.file(name), {1});
        if (old) {
            const auto t = std::filesystem::file_time_type::clock::now() - std::chrono::hours(2);
            std::filesystem::last_write_time(dir.file(name), t);
        }
    };
    const std::string d = std::to_string(dead), a = std::to_string(alive);
    make(".t.exr.tmp-" + d + "-0badcafe-" + host, false);               // removed
    make(".t.exr.tmp-" + d + "-0badcafe-" + host + ".records", false);  // removed
    make(".t.exr.tmp-" + d + "-0badcafe-" + host + "x", false);         // another host
    make(".t.exr.tmp-" + d + "-0badcafe-otherhost", false);             // another host
    make(".t.exr.tmp-" + a + "-0badcafe-" + host, false);               // alive
    make(".u.exr.tmp-" + d + "-0badcafe-" + host, false);               // another target
    make(".t.exr.tmp-" + d, true);                                      // former, old: removed
    make(".t.exr.tmp-" + d + "-0badcafe", true);                        // former, old: removed
    make(".t.exr.tmp" + d + ".exr", true);                              // former renderer's
    make(".t.exr.tmp-" + d + "-0badcafe.records", false);               // former, recent
    make("t.exr.tmp-" + d, true);                                       // not hidden: not ours
    EXPECT_EQ(removeStaleTemporaries(target), 5);
    const std::vector<std::string> left = {
        ".t.exr.tmp-" + a + "-0badcafe-" + host,   ".t.exr.tmp-" + d + "-0badcafe-" + host + "x",
        ".t.exr.tmp-" + d + "-0badcafe-otherhost", ".t.exr.tmp-" + d + "-0badcafe.records",
        ".u.exr.tmp-" + d + "-0badcafe-" + host,   "t.exr.tmp-" + d,
    };
    std::vector<std::string> expected = left;
    std::sort(expected.begin(), expected.end());
    EXPECT_EQ(dir.entries(), expected);
}

}  // namespace
}  // namespace mcstat::test
