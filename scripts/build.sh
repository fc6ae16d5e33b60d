#!/usr/bin/env bash
# scripts/build.sh DIR [cmake options...]: configures DIR (quick when cached) and builds it
# incrementally, Release unless an option says otherwise. $MCSTAT_TARGETS (space-separated) limits
# the build to those targets.
set -euo pipefail
cd "$(dirname "$0")/.."
dir=$1; shift
mkdir -p "$dir"
# Ninja where it is installed (scripts/install-deps.sh installs it) for a new build folder; a folder
# keeps the generator it was configured with.
generator=()
if [ ! -f "$dir/CMakeCache.txt" ] && command -v ninja >/dev/null; then generator=(-G Ninja); fi
cmake -S . -B "$dir" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release "$@" >"$dir/configure.log" 2>&1 ||
  { cat "$dir/configure.log" >&2; exit 1; }
targets=()
for t in ${MCSTAT_TARGETS:-}; do targets+=(--target "$t"); done
cmake --build "$dir" -j"$(nproc)" "${targets[@]}"
