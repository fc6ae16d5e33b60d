#!/usr/bin/env bash
# Installs what is missing, builds with warnings as errors, runs the whole test suite, then builds
# an AddressSanitizer + UndefinedBehaviorSanitizer configuration and runs the suite under it, then
# builds the libFuzzer targets (clang, ASan+UBSan) and runs each for 60 s: any finding fails.
set -euo pipefail
cd "$(dirname "$0")/.."

scripts/install-deps.sh
scripts/build.sh build -DMCSTAT_WERROR=ON
ctest --test-dir build --output-on-failure -j2

scripts/build.sh build-asan -DMCSTAT_WERROR=ON -DMCSTAT_SANITIZE=ON -DMCSTAT_BUILD_BENCHMARKS=OFF \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
  ctest --test-dir build-asan --output-on-failure -j2 -LE slow

# Coverage-guided fuzzing, bounded: the six targets at once for 60 s of wall time (tests/fuzz/).
scripts/fuzz.sh "${MCSTAT_FUZZ_SECONDS:-60}"
