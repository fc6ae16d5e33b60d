// Running the project's tools from tests as `std::system("EXE ARGS >OUT 2>ERR")` would, without
// paying a process start for each run: one fork server per tool and test process
// (mcstat/core/detail/fork_server.h) runs each command in a fork of a started tool. A start costs
// about 0.2 s here (0.33 s under ASan), almost all of it the dynamic loader; the suites run the
// tools some 600 times each.
//
// The server's fork is the same program with the same arguments, folder, descriptors,
// environment, resource limits and umask, so it does what the shell's start would. Whatever the
// server cannot reproduce goes through the shell as before: a line that asks the shell for more
// than words, quotes, a leading `cd DIR &&` and `>FILE`, `2>FILE` (pipes, appends, variables,
// globs, `~`, `;`), a program other than the project's tools, a changed environment, limit or
// umask, a command line longer than 64 KiB, a server busy with another thread's command, or one
// that went away. MCSTAT_TESTS_WITHOUT_FORK_SERVER set (to anything) sends every command through
// the shell, as before.
#pragma once

#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

extern char** environ;

namespace mcstat::testing {

/// A command line as `sh -c` would run it, when it runs one program: the program's words, its
/// folder (a leading `cd DIR &&`) and its `>FILE` and `2>FILE` redirections.
struct ShellCommand {
    std::vector<std::string> words;
    std::string cwd;       ///< empty: the caller's
    std::string out, err;  ///< empty: the caller's stdout, stderr
};

/// `line` as a ShellCommand, or nothing when the shell would do more than split, unquote, change
/// folder and redirect a stream into a file (expansions, globs, pipes, lists, appends: those stay
/// with the shell).
inline std::optional<ShellCommand> parseShellCommand(const std::string& line) {
    std::vector<std::string> words;
    constexpr int kAnd = -1;
    std::vector<int> redirect;  ///< per word: 0, the stream (1, 2) it names the file of, or kAnd
    std::string word;
    bool inWord = false, quoted = false;
    int pending = 0;  ///< the stream the next word redirects
    const auto finish = [&] {
        if (!inWord) return;
        words.push_back(word), redirect.push_back(pending);
        word.clear(), inWord = quoted = false, pending = 0;
    };
    for (size_t i = 0; i < line.size(); ++i) {
        const char c = line[i];
        if (c == ' ' || c == '\t') {
            finish();
        } else if (c == '\'') {
            const size_t end = line.find('\'', i + 1);
            if (end == std::string::npos) return std::nullopt;
            word += line.substr(i + 1, end - i - 1), inWord = quoted = true, i = end;
        } else if (c == '"') {
            for (++i;; ++i) {
                if (i >= line.size()) return std::nullopt;
                const char d = line[i];
                if (d == '"') break;
                if (d == '$' || d == '`') return std::nullopt;
                if (d == '\\' && i + 1 < line.size() && std::strchr("\"\\$`\n", line[i + 1])) {
                    if (line[++i] != '\n') word += line[i];
                } else {
                    word += d;
                }
            }
            inWord = quoted = true;
        } else if (c == '\\') {
            if (i + 1 >= line.size() || line[i + 1] == '\n') return std::nullopt;
            word += line[++i], inWord = quoted = true;  // `\2>f` is stdout's, as '2'>f
        } else if (c == '>') {
            const int stream = inWord && !quoted && word == "2" ? 2 : 1;
            if (stream == 2) word.clear(), inWord = false;
            finish();
            if (pending || (i + 1 < line.size() && std::strchr(">&|", line[i + 1])))
                return std::nullopt;
            pending = stream;
        } else if (c == '&' && i + 1 < line.size() && line[i + 1] == '&' && !inWord &&
                   words.size() == 2 && words[0] == "cd" && !redirect[0] && !redirect[1] &&
                   !pending) {
            ++i;  // `cd DIR && ...`: the folder, then the command
            words.push_back("&&"), redirect.push_back(kAnd);
        } else if (std::strchr("|&;<()$`*?[]{}~!\n", c) || (c == '#' && !inWord)) {
            return std::nullopt;
        } else {
            word += c, inWord = true;
        }
    }
    finish();
    if (pending) return std::nullopt;
    ShellCommand cmd;
    size_t first = 0;
    if (words.size() >= 3 && words[0] == "cd" && redirect[2] == kAnd && !redirect[1])
        cmd.cwd = words[1], first = 3;
    for (size_t w = first; w < words.size(); ++w) {
        if (redirect[w] == 0) {
            cmd.words.push_back(words[w]);
            continue;
        }
        std::string& target = redirect[w] == 1 ? cmd.out : cmd.err;
        // Two files for one stream: the shell opens both; a '' file: the shell's error.
        if (!target.empty() || words[w].empty()) return std::nullopt;
        target = words[w];
    }
    if (cmd.words.empty() || cmd.words[0] == "cd") return std::nullopt;
    return cmd;
}

namespace detail {

/// The umask, read without setting it (umask(2) would change it for every thread meanwhile).
inline mode_t currentUmask() {
    std::ifstream status("/proc/self/status");
    std::string line;
    while (std::getline(status, line))
        if (line.rfind("Umask:", 0) == 0) return mode_t(std::strtoul(line.c_str() + 6, nullptr, 8));
    return mode_t(-1);  // unknown: never equal to a known one, so the shell runs the command
}

/// What a fork of the server inherits from it rather than from the client.
struct ProcessState {
    std::vector<std::string> environment;
    std::array<rlimit, RLIM_NLIMITS> limits{};
    mode_t umask = 0;

    static ProcessState now() {
        ProcessState s;
        for (char** e = environ; *e; ++e) s.environment.emplace_back(*e);
        for (int r = 0; r < RLIM_NLIMITS; ++r)
            ::getrlimit(static_cast<__rlimit_resource_t>(r), &s.limits[r]);
        s.umask = currentUmask();
        return s;
    }
    bool operator==(const ProcessState& o) const {
        if (environment != o.environment || umask != o.umask) return false;
        for (int r = 0; r < RLIM_NLIMITS; ++r)
            if (limits[r].rlim_cur != o.limits[r].rlim_cur ||
                limits[r].rlim_max != o.limits[r].rlim_max)
                return false;
        return true;
    }
};

class ForkServer {
  public:
    explicit ForkServer(const std::string& exe) : started_(ProcessState::now()) {
        int sv[2];
        if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) != 0) return;
        const int child = ::fcntl(sv[1], F_DUPFD_CLOEXEC, 10);  // never 3, the fd it becomes
        ::close(sv[1]);
        std::vector<std::string> env = started_.environment;
        env.push_back("MCSTAT_FORK_SERVER_FD=3");
        std::vector<char*> envp;
        for (std::string& e : env) envp.push_back(e.data());
        envp.push_back(nullptr);
        std::string argv0 = exe;
        char* argv[] = {argv0.data(), nullptr};
        posix_spawn_file_actions_t fa;
        ::posix_spawn_file_actions_init(&fa);
        ::posix_spawn_file_actions_adddup2(&fa, child, 3);
        ::posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
        if (child >= 0 && ::posix_spawn(&pid_, exe.c_str(), &fa, nullptr, argv, envp.data()) == 0)
            socket_ = sv[0];
        else
            ::close(sv[0]), pid_ = -1;
        ::posix_spawn_file_actions_destroy(&fa);
        if (child >= 0) ::close(child);
    }
    ~ForkServer() { stop(); }
    ForkServer(const ForkServer&) = delete;
    ForkServer& operator=(const ForkServer&) = delete;

    /// Taken while a request runs: a second thread's command goes through the shell meanwhile.
    std::mutex busy;

    /// The wait status of `words` run in `cwd` with `out` and `err` as stdout and stderr, or
    /// nothing when this server cannot run it as the shell would.
    std::optional<int> run(const std::string& cwd, const std::vector<std::string>& words, int out,
                           int err) {
        if (socket_ < 0 || !(ProcessState::now() == started_)) return std::nullopt;
        std::string text = cwd + '\0';
        for (const std::string& w : words) text += w + '\0';
        if (text.size() > (1u << 16)) return std::nullopt;
        const int fds[3] = {0, out, err};
        alignas(cmsghdr) char control[CMSG_SPACE(sizeof fds)] = {};
        iovec iov{text.data(), text.size()};
        msghdr msg{};
        msg.msg_iov = &iov;
        msg.msg_iovlen = 1;
        msg.msg_control = control;
        msg.msg_controllen = sizeof control;
        cmsghdr* c = CMSG_FIRSTHDR(&msg);
        c->cmsg_level = SOL_SOCKET;
        c->cmsg_type = SCM_RIGHTS;
        c->cmsg_len = CMSG_LEN(sizeof fds);
        std::memcpy(CMSG_DATA(c), fds, sizeof fds);
        int status = 0;
        ssize_t n;
        do n = ::sendmsg(socket_, &msg, MSG_NOSIGNAL);
        while (n < 0 && errno == EINTR);
        if (n == ssize_t(text.size())) {
            do n = ::recv(socket_, &status, sizeof status, 0);
            while (n < 0 && errno == EINTR);
        }
        if (n != ssize_t(sizeof status)) {
            stop();  // gone: later runs go through the shell
            return std::nullopt;
        }
        return status;
    }

  private:
    void stop() {
        if (socket_ >= 0)
            ::close(socket_), socket_ = -1;  // the server exits when its socket closes
        if (pid_ > 0)
            while (::waitpid(pid_, nullptr, 0) < 0 && errno == EINTR) {
            }
        pid_ = -1;
    }
    ProcessState started_;
    pid_t pid_ = -1;
    int socket_ = -1;
};

}  // namespace detail

/// Whether `exe` is one of the project's tools, which serve forks.
inline bool servesForks([[maybe_unused]] const std::string& exe) {
#ifdef MCSTAT_EXE
    if (exe == MCSTAT_EXE) return true;
#endif
#ifdef MCSTAT_RENDER_EXE
    if (exe == MCSTAT_RENDER_EXE) return true;
#endif
    return false;
}

/// `std::system(line)`: the same wait status, output and files; a fork of a started tool when the
/// line runs one of the project's tools as parseShellCommand reads it.
inline int runCommand(const std::string& line) {
    static std::mutex mutex;
    static std::map<std::string, std::unique_ptr<detail::ForkServer>> servers;
    static const bool wanted = !std::getenv("MCSTAT_TESTS_WITHOUT_FORK_SERVER");
    std::optional<ShellCommand> cmd;
    if (wanted) cmd = parseShellCommand(line);
    char here[PATH_MAX];
    if (cmd && servesForks(cmd->words[0]) && ::getcwd(here, sizeof here)) {
        std::string cwd = here;
        if (!cmd->cwd.empty()) cwd = cmd->cwd[0] == '/' ? cmd->cwd : cwd + "/" + cmd->cwd;
        struct stat folder {};
        detail::ForkServer* server = nullptr;
        if (::stat(cwd.c_str(), &folder) == 0 && S_ISDIR(folder.st_mode)) {
            std::lock_guard<std::mutex> lock(mutex);
            auto& s = servers[cmd->words[0]];
            if (!s) s = std::make_unique<detail::ForkServer>(cmd->words[0]);
            server = s.get();
        }
        std::unique_lock<std::mutex> lock;
        if (server) lock = std::unique_lock<std::mutex>(server->busy, std::try_to_lock);
        if (lock) {
            // As the shell opens them: after the cd, stdout's first.
            const auto open = [&](const std::string& f) {
                const std::string p = f[0] == '/' ? f : cwd + "/" + f;
                return ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
            };
            const int o = cmd->out.empty() ? 1 : open(cmd->out);
            const int e = o < 0 ? -1 : cmd->err.empty() ? 2 : open(cmd->err);
            std::optional<int> status;
            if (o >= 0 && e >= 0) status = server->run(cwd, cmd->words, o, e);
            if (o > 2) ::close(o);
            if (e > 2) ::close(e);
            if (status) return *status;
        }
    }
    return std::system(line.c_str());
}

/// `std::system(EXE + " " + ARGS + " >" + OUT + " 2>" + ERR)`.
inline int runTool(const std::string& exe, const std::string& args, const std::string& out,
                   const std::string& err) {
    return runCommand(exe + " " + args + " >" + out + " 2>" + err);
}

}  // namespace mcstat::testing
