#!/usr/bin/env bash
# Installs what is missing, builds with warnings as errors, runs the whole test suite, then builds
# an AddressSanitizer + UndefinedBehaviorSanitizer configuration and runs the suite under it, then
# builds the libFuzzer targets (clang, ASan+UBSan) and runs each for 60 s: any finding fails.
set -euo pipefail
cd "$(dirname "$0")/.."
# Each phase prints its wall time when it ends: the whole run should take at most 25 minutes on a
# quiet 2-core machine (issue 51).
phase_start=$SECONDS
# ctest runs three tests at once on two cores: some tests mostly wait (Slurm's queue: the farm
# test used 36 s of CPU in its 94 s; Blender's and every process's start-up), and at -j2 those
# waits left a core idle. MCSTAT_TEST_JOBS overrides it.
jobs=${MCSTAT_TEST_JOBS:-3}
phase() { echo "test.sh: $1 took $((SECONDS - phase_start)) s (total $SECONDS s)"; phase_start=$SECONDS; }

scripts/install-deps.sh
scripts/build.sh build -DMCSTAT_WERROR=ON
phase "build"
ctest --test-dir build --output-on-failure -j"$jobs"
phase "tests"

# One clang build serves the sanitizer suite and the fuzzers (issue 51): every library, tool and
# test compiled once with ASan+UBSan, the readers of untrusted bytes also with libFuzzer's
# coverage instrumentation (tests/fuzz/CMakeLists.txt lists them; on everything it made the
# suite's compute-bound tests up to 4x slower), and the fuzz targets linked against the same
# libraries. clang compiles this in about 60 % of gcc's time (compare.cpp under ASan at -O1 -g1:
# 12.1 s against 21.7 s), and the separate fuzz build is gone.
# -O1 -g1: what the sanitizers' documentation asks for (optimised, frames kept; line tables give
# every report its file and line).
CC=clang CXX=clang++ scripts/build.sh build-sanitize -DMCSTAT_WERROR=ON -DMCSTAT_SANITIZE=ON \
  -DMCSTAT_FUZZ=ON -DMCSTAT_BUILD_BENCHMARKS=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG"
phase "sanitizer build"
# The whole suite again under the sanitizers: Blender, Slurm, the Python module, the packaging,
# the architecture tests and the README's commands (tests/readme/run_readme.sh preloads the
# runtime into Debian's oiiotool and python3, which load our instrumented plugin and module).
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
  ctest --test-dir build-sanitize --output-on-failure -j"$jobs"
phase "sanitizer tests"

# Coverage-guided fuzzing, bounded: the six targets at once for 60 s of wall time (tests/fuzz/),
# built above.
BUILD=build-sanitize SKIP_BUILD=1 scripts/fuzz.sh "${MCSTAT_FUZZ_SECONDS:-60}"
phase "fuzzing"
