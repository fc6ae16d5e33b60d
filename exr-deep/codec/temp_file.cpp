#include "mcstat/exr-deep/codec/temp_file.h"

#include <dirent.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <ctime>
#include <fstream>
#include <random>

#include "mcstat/core/untrusted_text.h"

namespace mcstat {

namespace {

// ---- the registry the signal handler reads -----------------------------------------------------
// Fixed storage, no allocation and no locks: the handler may run in any thread at any moment.
// A slot is free (0), being filled (1) or holds a temporary's path (2).
constexpr int kSlots = 64;
constexpr size_t kMaxPath = 4096;
struct Slot {
    std::atomic<int> state{0};
    char path[kMaxPath];
};
std::array<Slot, kSlots> g_slots;

int registerPath(const std::string& path) {
    if (path.size() >= kMaxPath) return -1;
    for (int i = 0; i < kSlots; ++i) {
        int expected = 0;
        if (!g_slots[i].state.compare_exchange_strong(expected, 1)) continue;
        std::memcpy(g_slots[i].path, path.c_str(), path.size() + 1);
        g_slots[i].state.store(2);
        return i;
    }
    return -1;  // more than kSlots writes at once: this one is not removed on a signal
}

void unregisterPath(int slot) {
    if (slot >= 0) g_slots[slot].state.store(0);
}

extern "C" void removeTemporariesAndReraise(int sig) {
    for (Slot& s : g_slots)
        if (s.state.load() == 2) ::unlink(s.path);  // async-signal-safe
    // SA_RESETHAND restored the default action; the signal is blocked until this handler
    // returns, then it ends the process with the status the signal gives.
    ::raise(sig);
}

// ---- names -----------------------------------------------------------------------------------

/// This machine's name reduced to letters, digits and '_' (no '-' or '.', which the name's
/// fields and the suffix use), at most 32 characters.
const std::string& hostTag() {
    static const std::string tag = [] {
        char buf[256] = {};
        if (::gethostname(buf, sizeof buf - 1) != 0 || buf[0] == '\0') std::strcpy(buf, "host");
        std::string t;
        for (const char* c = buf; *c != '\0' && t.size() < 32; ++c)
            t += std::isalnum(static_cast<unsigned char>(*c)) ? *c : '_';
        return t;
    }();
    return tag;
}

void splitTarget(const std::string& target, std::string& dir, std::string& name) {
    const size_t slash = target.rfind('/');
    dir = slash == std::string::npos ? std::string() : target.substr(0, slash + 1);
    name = slash == std::string::npos ? target : target.substr(slash + 1);
}

/// Digits at `s[pos]...`; false when there are none or the number is absurd.
bool readNumber(const std::string& s, size_t& pos, long& value) {
    const size_t start = pos;
    value = 0;
    while (pos < s.size() && std::isdigit(static_cast<unsigned char>(s[pos])) && pos - start < 10)
        value = value * 10 + (s[pos++] - '0');
    return pos > start && value > 0;
}

bool readHex8(const std::string& s, size_t& pos) {
    if (s.size() < pos + 8) return false;
    for (size_t i = pos; i < pos + 8; ++i)
        if (!std::isxdigit(static_cast<unsigned char>(s[i]))) return false;
    pos += 8;
    return true;
}

bool processRuns(long pid) {
    if (pid == long(::getpid())) return true;
    return ::kill(pid_t(pid), 0) == 0 || errno == EPERM;
}

enum class Stale { No, Yes, IfOld };

/// Whether `entry` (a file name in the target's directory) is a temporary of `name` left by a
/// process that is gone.
Stale classify(const std::string& entry, const std::string& name) {
    const std::string prefix = "." + name + ".tmp";
    if (entry.size() <= prefix.size() || entry.compare(0, prefix.size(), prefix) != 0)
        return Stale::No;
    size_t pos = prefix.size();
    long pid = 0;
    if (entry[pos] != '-') {
        // The renderer's former ".<name>.tmp<pid>.exr".
        if (!readNumber(entry, pos, pid) || entry.compare(pos, std::string::npos, ".exr") != 0)
            return Stale::No;
        return processRuns(pid) ? Stale::No : Stale::IfOld;
    }
    ++pos;
    if (!readNumber(entry, pos, pid)) return Stale::No;
    if (pos == entry.size()) return processRuns(pid) ? Stale::No : Stale::IfOld;  // ".tmp-<pid>"
    if (entry[pos++] != '-' || !readHex8(entry, pos)) return Stale::No;
    const std::string rest = entry.substr(pos);
    if (rest.empty() || rest == ".records")  // ".tmp-<pid>-<hex>[.records]": no host
        return processRuns(pid) ? Stale::No : Stale::IfOld;
    const std::string host = "-" + hostTag();
    if (rest.compare(0, host.size(), host) != 0)
        return Stale::No;  // another machine's, or not ours
    const size_t after = host.size();
    if (after < rest.size() && rest[after] != '.') return Stale::No;  // a longer host name
    return processRuns(pid) ? Stale::No : Stale::Yes;
}

}  // namespace

namespace {

/// The temporary file goes into the target's folder: a folder this user cannot write is refused
/// here, naming the target, whatever the format (OIIO's writers and ours said it differently,
/// some naming the hidden temporary file). Root passes, as the kernel lets it write.
bool writableFolder(const std::string& target, const std::string& dirPath, std::string& err) {
    if (::access(dirPath.c_str(), W_OK | X_OK) != 0) {
        err = fmt::format("{}: cannot write into {} ({})", target, dirPath, std::strerror(errno));
        return false;
    }
    return true;
}

}  // namespace

bool checkOutputTarget(const std::string& target, std::string& err) {
    if (target.empty()) {
        err = "output: an empty file name";
        return false;
    }
    std::string dir, name;
    splitTarget(target, dir, name);
    if (name.empty() || name == "." || name == "..") {
        err = target + ": names a directory, not a file";
        return false;
    }
    struct stat st {};
    const std::string dirPath = dir.empty() ? std::string(".") : dir;
    const bool found = ::stat(dirPath.c_str(), &st) == 0;
    if (!found || !S_ISDIR(st.st_mode)) {
        err = fmt::format("{}: cannot write into {} ({})", target, dirPath,
                          std::strerror(found ? ENOTDIR : errno));
        return false;
    }
    // What the target is comes first, so that the reason is the same for every user (/dev/null
    // is a device to root and to anyone else; only root may write into /dev/).
    if (::stat(target.c_str(), &st) != 0) return writableFolder(target, dirPath, err);
    if (S_ISDIR(st.st_mode)) {
        err = target + ": is a directory";
        return false;
    }
    if (!S_ISREG(st.st_mode)) {
        const char* kind = S_ISCHR(st.st_mode)    ? "a character device"
                           : S_ISBLK(st.st_mode)  ? "a block device"
                           : S_ISFIFO(st.st_mode) ? "a FIFO"
                           : S_ISSOCK(st.st_mode) ? "a socket"
                                                  : "not a regular file";
        err = fmt::format(
            "{}: is {}; mcstat writes a temporary file and renames it onto the target, which "
            "would replace it: write to a file",
            target, kind);
        return false;
    }
    if ((st.st_mode & (S_IWUSR | S_IWGRP | S_IWOTH)) == 0) {
        err = target +
              ": is read-only; mcstat does not replace read-only files (make it "
              "writable, e.g. chmod u+w, to allow)";
        return false;
    }
    return writableFolder(target, dirPath, err);
}

int removeStaleTemporaries(const std::string& target) {
    std::string dir, name;
    splitTarget(target, dir, name);
    if (name.empty()) return 0;
    DIR* d = ::opendir(dir.empty() ? "." : dir.c_str());
    if (d == nullptr) return 0;
    int removed = 0;
    const time_t oldEnough = std::time(nullptr) - 15 * 60;
    while (const dirent* e = ::readdir(d)) {
        const std::string entry = e->d_name;
        const Stale stale = classify(entry, name);
        if (stale == Stale::No) continue;
        const std::string path = dir + entry;
        struct stat st {};
        if (::lstat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) continue;
        if (stale == Stale::IfOld && st.st_mtime > oldEnough) continue;
        if (::unlink(path.c_str()) == 0) ++removed;
    }
    ::closedir(d);
    return removed;
}

TemporaryFile::TemporaryFile(const std::string& target, const std::string& suffix)
    : target_(target) {
    removeStaleTemporaries(target);
    std::string dir, name;
    splitTarget(target, dir, name);
    std::random_device rd;
    path_ = fmt::format("{}.{}.tmp-{}-{:08x}-{}{}", dir, name, long(::getpid()), rd(), hostTag(),
                        suffix);
    slot_ = registerPath(path_);
}

TemporaryFile::~TemporaryFile() {
    if (!done_) remove();
}

void TemporaryFile::remove() {
    ::unlink(path_.c_str());
    unregisterPath(slot_);
    slot_ = -1;
    done_ = true;
}

bool TemporaryFile::commit(std::string& err) {
    if (done_) {
        err = target_ + ": the temporary file is gone";
        return false;
    }
    if (std::rename(path_.c_str(), target_.c_str()) != 0) {
        err =
            fmt::format("{}: cannot rename {} onto it ({})", target_, path_, std::strerror(errno));
        remove();
        return false;
    }
    unregisterPath(slot_);
    slot_ = -1;
    done_ = true;
    return true;
}

bool writeTextAtomically(const std::string& target, const std::string& text, std::string& err) {
    if (!checkOutputTarget(target, err)) return false;
    TemporaryFile tmp(target);
    {
        std::ofstream f(tmp.path(), std::ios::binary);
        f << text;
        f.flush();
        if (!f) {
            err = fmt::format("{}: cannot write ({})", oneLine(target), std::strerror(errno));
            return false;
        }
    }
    return tmp.commit(err);
}

void removeTemporariesOnSignals() {
    static std::atomic<bool> installed{false};
    if (installed.exchange(true)) return;
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
        struct sigaction old {};
        if (::sigaction(sig, nullptr, &old) != 0 || old.sa_handler != SIG_DFL) continue;
        struct sigaction sa {};
        sa.sa_handler = &removeTemporariesAndReraise;
        sigemptyset(&sa.sa_mask);
        sa.sa_flags = SA_RESETHAND;
        ::sigaction(sig, &sa, nullptr);
    }
}

}  // namespace mcstat
