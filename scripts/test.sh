#!/usr/bin/env bash
# Installs what is missing, builds with warnings as errors, runs the whole test suite, then builds
# an AddressSanitizer + UndefinedBehaviorSanitizer configuration and runs the suite under it, then
# builds the libFuzzer targets (clang, ASan+UBSan) and runs each for 60 s: any finding fails.
set -euo pipefail
cd "$(dirname "$0")/.."
# Each phase prints its wall time when it ends: CI has 30 minutes for the whole run.
phase_start=$SECONDS
phase() { echo "test.sh: $1 took $((SECONDS - phase_start)) s (total $SECONDS s)"; phase_start=$SECONDS; }

scripts/install-deps.sh
scripts/build.sh build -DMCSTAT_WERROR=ON
phase "build"
ctest --test-dir build --output-on-failure -j2
phase "tests"

# -O1 -g1: what the sanitizers' documentation asks for (optimised, frames kept; line tables give
# every report its file and line), and compiled in less than half the time of -O2 -g (37 s against
# 16 s for compare/compare.cpp), which keeps CI within its 30 minutes.
scripts/build.sh build-asan -DMCSTAT_WERROR=ON -DMCSTAT_SANITIZE=ON -DMCSTAT_BUILD_BENCHMARKS=OFF \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG"
phase "sanitizer build"
# Left out under the sanitizers: the `slow` label, the `architecture` greps (no code of ours runs
# in them), the `fuzz` corpus replays (the fuzzing step below runs every corpus input first, under
# clang's ASan+UBSan, before it mutates any), the `packaging` tests (an install and a downstream
# project built against it: the sanitizers find nothing there that the suite's own runs of the
# tools miss), and six tests whose code other tests of their suite run too, on smaller inputs, and
# which repeat it over many files, seeds or operations (CPU seconds under ASan: 29, 29, 21, 17, 14,
# 13); the normal suite above runs them. CI took 35 min 5 s on 2026-11-27 with only the first three
# of them left out.
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
  ctest --test-dir build-asan --output-on-failure -j2 -LE 'slow|architecture|packaging|fuzz' \
  -E '^(MergeN\.SixtyFourFilesGiveTheSameBytesInAnyOrder|Golden\.EveryOperationMatchesItsGoldenKeepsTheBeautyAndItsAovsSum|CompareCli\.FalseAlarmsOverSeedPairsStayNearTheLevel|FramesCli\.AShotOfSeedRendersIntoStatisticsFilesThenHalfImagesPerFrame|CompareCli\.SameSceneOtherSeedsPassesAndChangesAUserMustNotMissFail|RpfFile\.BeatsTheInputOnDepthOfField)$'
phase "sanitizer tests"

# Coverage-guided fuzzing, bounded: the six targets at once for 60 s of wall time (tests/fuzz/).
scripts/fuzz.sh "${MCSTAT_FUZZ_SECONDS:-60}"
phase "fuzzing"
