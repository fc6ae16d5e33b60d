// mcstat: robust images from Monte Carlo statistics files. See `mcstat --help`.
#include "cli.h"
#include "mcstat/exr-deep/codec/temp_file.h"

int main(int argc, char** argv) {
    // Ctrl-C or a kill during a write removes the temporary file (the target is never touched).
    mcstat::removeTemporariesOnSignals();
    return mcstat::cli::run(argc, argv);
}
