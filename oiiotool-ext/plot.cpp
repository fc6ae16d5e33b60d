// Plots drawn by gnuplot (docs/review.md, "How the plot is made"): a script and its data files go
// into a fresh temporary directory, gnuplot runs there as a child process (posix_spawnp: no shell,
// so no user text is ever parsed as a command line), and the PNG it writes is read back.
#include "plot.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

extern char** environ;

namespace mcstat::cli {

namespace {

using OIIO::Strutil::fmt::format;

/// A temporary directory removed (with everything in it) when it goes out of scope, so no path
/// through runGnuplot leaves files behind.
struct TempDir {
    std::string path;
    ~TempDir() {
        if (!path.empty()) OIIO::Filesystem::remove_all(path);
    }
};

bool writeText(const std::string& path, const std::string& text, std::string& err) {
    std::ofstream f(path, std::ios::binary);
    f << text;
    f.close();
    if (!f) {
        err = format("cannot write the temporary file {}", path);
        return false;
    }
    return true;
}

std::string firstLine(const std::string& path) {
    std::ifstream f(path);
    std::string line, last;
    // gnuplot echoes the offending script line before the message: report the message.
    while (std::getline(f, line)) {
        line = std::string(OIIO::Strutil::strip(line));
        if (line.empty() || line == "^") continue;
        if (OIIO::Strutil::contains(line, "error") || OIIO::Strutil::contains(line, "line "))
            return line;
        if (last.empty()) last = line;
    }
    return last;
}

}  // namespace

std::string plotSafe(const std::string& s) {
    std::string out;
    for (char c : s) {
        const bool ok = std::isalnum(static_cast<unsigned char>(c)) ||
                        std::string(" ._-/+,=()[]:").find(c) != std::string::npos;
        out += ok ? c : '_';
    }
    return out;
}

// $PATH is what posix_spawnp will search.
bool haveGnuplot(std::string& err) {
    const char* path = std::getenv("PATH");
    for (const std::string& d : OIIO::Strutil::splits(path ? path : "", ":")) {
        const std::string exe = (d.empty() ? std::string(".") : d) + "/gnuplot";
        if (access(exe.c_str(), X_OK) == 0) return true;
    }
    err = "needs gnuplot (scripts/install-deps.sh installs gnuplot-nox)";
    return false;
}

bool runGnuplot(const std::string& script,
                const std::vector<std::pair<std::string, std::string>>& dataFiles,
                const std::string& pngName, OIIO::ImageBuf& out, std::string& err) {
    const char* tmpEnv = std::getenv("TMPDIR");
    std::string templ = std::string(tmpEnv && *tmpEnv ? tmpEnv : "/tmp") + "/mcstat-plot-XXXXXX";
    std::vector<char> buf(templ.begin(), templ.end());
    buf.push_back('\0');
    if (!mkdtemp(buf.data())) {
        err = format("cannot create a temporary directory {}: {}", templ, std::strerror(errno));
        return false;
    }
    TempDir dir{buf.data()};
    for (const auto& [name, text] : dataFiles)
        if (!writeText(dir.path + "/" + name, text, err)) return false;
    if (!writeText(dir.path + "/plot.gp", script, err)) return false;

    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    // The script names its files relative to the directory, so no path is spelled in it.
    posix_spawn_file_actions_addchdir_np(&fa, dir.path.c_str());
    posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 2, "gnuplot.err", O_WRONLY | O_CREAT | O_TRUNC, 0600);
    char arg0[] = "gnuplot", arg1[] = "plot.gp";
    char* argv[] = {arg0, arg1, nullptr};
    pid_t pid = 0;
    const int rc = posix_spawnp(&pid, "gnuplot", &fa, nullptr, argv, environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc == ENOENT) {
        err = "needs gnuplot (scripts/install-deps.sh installs gnuplot-nox)";
        return false;
    }
    if (rc != 0) {
        err = format("cannot run gnuplot: {}", std::strerror(rc));
        return false;
    }
    int status = 0;
    while (waitpid(pid, &status, 0) < 0) {
        if (errno != EINTR) {
            err = format("waiting for gnuplot: {}", std::strerror(errno));
            return false;
        }
    }
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        const std::string why = firstLine(dir.path + "/gnuplot.err");
        err = WIFEXITED(status) ? format("gnuplot failed (exit {}){}{}", WEXITSTATUS(status),
                                         why.empty() ? "" : ": ", why)
                                : format("gnuplot was killed by signal {}", WTERMSIG(status));
        return false;
    }
    const std::string png = dir.path + "/" + pngName;
    if (!OIIO::Filesystem::exists(png)) {
        err = "gnuplot wrote no image";
        return false;
    }
    OIIO::ImageBuf img(png);
    if (!img.read(0, 0, true, OIIO::TypeDesc::FLOAT)) {
        err = format("reading gnuplot's image: {}", img.geterror());
        return false;
    }
    // pngcairo may write grey or RGBA: always hand back R, G, B.
    const int n = img.nchannels();
    const int order[3] = {0, n >= 3 ? 1 : 0, n >= 3 ? 2 : 0};
    const std::string names[3] = {"R", "G", "B"};
    OIIO::ImageBuf rgb;
    if (!OIIO::ImageBufAlgo::channels(rgb, img, 3, order, {}, names)) {
        err = format("reading gnuplot's image: {}", rgb.geterror());
        return false;
    }
    out = std::move(rgb);
    return true;
}

}  // namespace mcstat::cli
