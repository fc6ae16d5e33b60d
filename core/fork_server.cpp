// The fork server (include/mcstat/core/detail/fork_server.h): one request at a time, each in a
// fork.
#include "mcstat/core/detail/fork_server.h"

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define MCSTAT_FORK_SERVER_LSAN 1
#endif
#elif defined(__SANITIZE_ADDRESS__)
#define MCSTAT_FORK_SERVER_LSAN 1
#endif
#ifdef MCSTAT_FORK_SERVER_LSAN
#include <sanitizer/lsan_interface.h>
#endif
#include <dirent.h>
#include <dlfcn.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

namespace mcstat::detail {

namespace {

constexpr const char* kSocketVariable = "MCSTAT_FORK_SERVER_FD";
constexpr size_t kMaxRequest = 1 << 16;  ///< a command line; larger ones the client runs itself
constexpr int kStreams = 3;              ///< stdin, stdout, stderr

struct Request {
    std::vector<char> text;  ///< "CWD\0ARG0\0...": argv points into it
    int fds[kStreams] = {-1, -1, -1};
};

void closeAll(Request& r) {
    for (int& fd : r.fds)
        if (fd >= 0) ::close(fd), fd = -1;
}

/// Reads one request; false at the end of the stream or on a malformed message (which ends the
/// service: the client is the test suite's own helper, so a bad message is a bug to surface).
bool receive(int socket, Request& r) {
    r.text.assign(kMaxRequest, '\0');
    iovec iov{r.text.data(), r.text.size()};
    alignas(cmsghdr) char control[CMSG_SPACE(sizeof(int) * kStreams)];
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control;
    msg.msg_controllen = sizeof control;
    ssize_t n;
    do n = ::recvmsg(socket, &msg, MSG_CMSG_CLOEXEC);
    while (n < 0 && errno == EINTR);
    const cmsghdr* c = n > 0 ? CMSG_FIRSTHDR(&msg) : nullptr;
    if (c && c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_RIGHTS &&
        c->cmsg_len == CMSG_LEN(sizeof(int) * kStreams))
        std::memcpy(r.fds, CMSG_DATA(c), sizeof(int) * kStreams);
    const bool whole = n > 0 && !(msg.msg_flags & (MSG_TRUNC | MSG_CTRUNC)) && r.fds[2] >= 0 &&
                       r.text[size_t(n) - 1] == '\0';
    if (!whole) {
        closeAll(r);
        return false;
    }
    r.text.resize(size_t(n));
    return true;
}

/// The threads of this process (its entries in /proc/self/task).
int threadCount() {
    DIR* tasks = ::opendir("/proc/self/task");
    if (!tasks) return -1;
    int n = 0;
    while (const dirent* d = ::readdir(tasks)) n += d->d_name[0] != '.';
    ::closedir(tasks);
    return n;
}

/// Stops the threads libraries started while they loaded, and waits until this process has one
/// thread: a fork holds only the thread that forked, so any other would be missing from every
/// worker, with whatever lock it held (and the sanitizers' leak check would warn of it at each
/// worker's exit). log4cplus, which OpenVDB and so Debian's OpenImageIO load, starts a pool of
/// four at load; nothing here links it, so its own shutdownThreadPool() is looked up by name.
/// False when other threads remain after `limit`.
bool stopOtherThreads(std::chrono::milliseconds limit) {
    using Shutdown = void (*)();
    if (const auto stop = reinterpret_cast<Shutdown>(
            ::dlsym(RTLD_DEFAULT, "_ZN9log4cplus18shutdownThreadPoolEv")))
        stop();
    const auto end = std::chrono::steady_clock::now() + limit;
    while (threadCount() != 1) {
        if (std::chrono::steady_clock::now() > end) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return true;
}

/// How a worker exits, whether `run` returns or calls exit(): after the destructors of what the
/// run created, before those of the libraries' own start. Some of those wait for threads their
/// library started when the server started (log4cplus, which Debian's OpenImageIO pulls in, joins
/// its logging thread), and a fork holds only the thread that forked. The leak check the
/// sanitizers run at exit is run here instead.
void exitWorker(int status, void*) {
    std::fflush(nullptr);
#ifdef MCSTAT_FORK_SERVER_LSAN
    if (__lsan_do_recoverable_leak_check() != 0) status = 23;  // what LSan exits with
#endif
    std::_Exit(status);
}

/// In the fork: the request's streams and folder, then the program.
[[noreturn]] void work(int socket, Request& r, const std::function<int(int, char**)>& run) {
    ::close(socket);
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // a killed suite takes its running tool with it
    for (int i = 0; i < kStreams; ++i) ::dup2(r.fds[i], i);  // dup2 clears close-on-exec
    for (int fd : r.fds)
        if (fd >= kStreams) ::close(fd);
    std::vector<char*> argv;
    for (size_t i = 0; i < r.text.size(); i += std::strlen(&r.text[i]) + 1)
        argv.push_back(&r.text[i]);
    const char* cwd = argv.front();
    if (argv.size() < 2 || ::chdir(cwd) != 0) {
        std::fprintf(stderr, "fork server: cannot run in '%s'\n", cwd);
        std::_Exit(127);
    }
    argv.erase(argv.begin());
    argv.push_back(nullptr);
    ::on_exit(exitWorker, nullptr);
    std::exit(run(int(argv.size()) - 1, argv.data()));
}

}  // namespace

int forkServerSocket() {
    const char* text = std::getenv(kSocketVariable);
    if (!text) return -1;
    char* end = nullptr;
    const long fd = std::strtol(text, &end, 10);
    ::unsetenv(kSocketVariable);
    return end != text && *end == '\0' && fd > 2 && fd < 1024 ? int(fd) : -1;
}

int serveForks(int socket, const std::function<int(int, char**)>& run) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // the server never outlives the suite that started it
    if (!stopOtherThreads(std::chrono::seconds(10))) {
        ::close(socket);  // the client runs its commands through the shell instead
        return 1;
    }
    Request r;
    while (receive(socket, r)) {
        const pid_t pid = ::fork();
        if (pid == 0) work(socket, r, run);
        closeAll(r);
        int status = 127 << 8;  // what a shell reports for a command it could not start
        if (pid > 0)
            while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
            }
        if (::send(socket, &status, sizeof status, MSG_NOSIGNAL) != ssize_t(sizeof status)) break;
    }
    ::close(socket);
    return 0;
}

}  // namespace mcstat::detail
