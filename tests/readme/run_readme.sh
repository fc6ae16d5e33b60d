#!/usr/bin/env bash
# Runs every shell block of README.md verbatim, in order, in one shell (as a user pasting them into
# a terminal), except the block holding the two set-up commands (scripts/demo.sh, scripts/test.sh),
# which is what this build already did. The scratch folder stands in for the repository's root:
# build/ is this build tree, render-fixture/, python/, docs/ and farm/ the source's (example scenes, scripts, measured tables, mcstat-blender), out/demo/ holds the demo's
# reference and seed renders (rendered here with fewer samples: the commands need renders of the
# same scene and size, not converged ones).
# Usage: run_readme.sh SOURCE_DIR BUILD_DIR WORK_DIR
set -euo pipefail
src=$1 build=$2 work=$3
# The sanitizer build's suite sets LD_PRELOAD (CMakeLists.txt): it is kept for the README's own
# commands below, where Debian's oiiotool and python3 load our instrumented plugin and module, and
# taken from this script's helpers (awk, ln; mawk's own reads trip ASan).
preload=${LD_PRELOAD:-}
unset LD_PRELOAD
[ -n "${KEEP:-}" ] || rm -rf "$work"
mkdir -p "$work/out/demo"
ln -s "$build" "$work/build"
ln -s "$src/render-fixture" "$work/render-fixture"  # example scenes the README renders
ln -s "$src/python" "$work/python"                  # the Python module's example scripts
ln -s "$src/docs" "$work/docs"                      # the measured tables the README plots
ln -s "$src/farm" "$work/farm"                      # mcstat-blender (with Blender's caustic scene)
cd "$work"
build/render-fixture/mcstat-render --scene default --spp 256 --seed 4242 --reference --quiet \
  -o out/demo/reference-65536spp.exr
# The demo's seed renders (fewer samples).
mkdir -p out/demo/seeds
for s in $(seq 9); do
  build/render-fixture/mcstat-render --scene default --spp 16 --seed $((100 + s)) --reference \
    --quiet -o "out/demo/seeds/default_s${s}_64spp.exr"
done

# The ```sh blocks of the README, minus the set-up block.
awk '/^```sh$/ { inblock = 1; block = ""; next }
     /^```$/ && inblock { inblock = 0; if (block !~ /scripts\/demo\.sh/) printf "%s", block; next }
     inblock { block = block $0 "\n" }' "$src/README.md" >commands.sh
n=$(grep -cvE '^\s*(#|$)' commands.sh)
[ "$n" -ge 10 ] || { echo "run_readme: found only $n commands in README.md" >&2; exit 1; }
unset OIIO_LIBRARY_PATH
# The sanitizer build's suite preloads the sanitizer runtime into every README command: not into
# Blender, which loads none of our code and which the runtime's allocator only slows.
if [ -n "$preload" ]; then
  export LD_PRELOAD=$preload
  blender=$(command -v blender || echo blender)
  mkdir -p "$work/.tools"
  printf '#!/bin/sh\nexec env -u LD_PRELOAD "%s" "$@"\n' "$blender" >"$work/.tools/blender"
  chmod +x "$work/.tools/blender"
  export BLENDER="$work/.tools/blender"
fi
# Each command is echoed before it runs, so a failure shows which one.
if ! bash -euo pipefail -x commands.sh >log.txt 2>&1; then
  echo "run_readme: a README command failed; the end of its log:" >&2
  tail -n 25 log.txt >&2
  exit 1
fi
echo "run_readme: $n README commands ran"
[ -n "${KEEP:-}" ] || rm -rf "$work"
