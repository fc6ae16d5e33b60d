// mcstat: robust images from Monte Carlo statistics files. See `mcstat --help`.
#include "cli.h"

int main(int argc, char** argv) { return mcstat::cli::run(argc, argv); }
