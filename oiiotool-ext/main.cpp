// mcstat: robust images from Monte Carlo statistics files. See `mcstat --help`.
#include "cli.h"
#include "mcstat/core/detail/fork_server.h"
#include "mcstat/exr-deep/codec/temp_file.h"

namespace {

int runMcstat(int argc, char** argv) {
    // Ctrl-C or a kill during a write removes the temporary file (the target is never touched).
    mcstat::removeTemporariesOnSignals();
    return mcstat::cli::run(argc, argv);
}

}  // namespace

int main(int argc, char** argv) {
    // The test suites' helpers start one mcstat as a fork server
    // (mcstat/core/detail/fork_server.h).
    if (const int socket = mcstat::detail::forkServerSocket(); socket >= 0)
        return mcstat::detail::serveForks(socket, runMcstat);
    return runMcstat(argc, argv);
}
