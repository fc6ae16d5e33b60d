#!/usr/bin/env bash
# test_downstream.sh SOURCE BUILD WORK: installs mcstat into WORK/prefix, renders a tiny scene as
# seeds (the same scene twice with other seeds, and with its light 2 % brighter), configures the
# downstream project (downstream/CMakeLists.txt: find_package(mcstat) and mcstat_add_render_test)
# against the installed package and runs its CTest suite: same_scene must pass, brighter_light
# must fail, each leaving its JUnit, JSON and report page. The project enables no language (a
# render-test-only project needs no compiler) and checks the installed Python module, OCIO config
# and mcstat-farm too. Exits 1 with a message otherwise.
set -euo pipefail
src=$1 build=$2 work=$3
# The sanitizer build's suite sets LD_PRELOAD (CMakeLists.txt): kept for the downstream suite,
# whose python3 loads the instrumented module, and taken from the install and the configure.
preload=${LD_PRELOAD:-}
unset LD_PRELOAD
rm -rf "$work"
mkdir -p "$work"
fail() { echo "test_downstream: $*" >&2; exit 1; }

cmake --install "$build" --prefix "$work/prefix" --component dev >/dev/null
cmake --install "$build" --prefix "$work/prefix" --component bin >/dev/null
cmake --install "$build" --prefix "$work/prefix" --component plugin >/dev/null  # mcstat_PLUGIN_DIR
with_python=OFF  # a build without the Python module (docs/python.md)
if [ -d "$build/python/mcstat" ]; then
  with_python=ON
  cmake --install "$build" --prefix "$work/prefix" --component python >/dev/null  # mcstat_PYTHONPATH
fi

# The installed mcstat-farm runs the installed mcstat-render and mcstat beside it (neither PATH's
# nor the build tree's) with the installed templates: one frame of two seeds, without Slurm.
env -u MCSTAT_BIN_DIR PATH=/usr/bin:/bin "$work/prefix/bin/mcstat-farm" run-local "$work/shot" \
  --name t --frames 1 --seeds 2 --spp 4 --res 16 12 --fanin 2 --estimate none \
  --template-file "$work/prefix/share/mcstat/farm/templates/fixture-stats.tmpl" \
  >"$work/farm.log" 2>&1 || { cat "$work/farm.log" >&2; fail "the installed mcstat-farm failed"; }
[ -s "$work/shot/out/t.0001.mcstat" ] || fail "the installed mcstat-farm wrote no frame"
grep -q "$work/prefix/bin/mcstat-render" "$work/shot/logs/f0001/render.f0001.s0001."*.log ||
  fail "the installed mcstat-farm did not run the installed mcstat-render"
[ -f "$work/prefix/share/mcstat/farm/templates/cycles_seed.py" ] ||
  fail "the farm's Cycles template ({farm}/templates/cycles_seed.py) is not installed"

render="$build/render-fixture/mcstat-render"
scene="$src/tests/render-test/scenes/box.json"  # 32 x 24, its light seen directly
light="$src/tests/render-test/scenes/box-light-1.02.json"
pids=()
for s in 1 2 3 4; do
  mkdir -p "$work/renders/good" "$work/renders/new" "$work/renders/light"
  "$render" --scene "$scene" --spp 64 --seed $s --reference --quiet -o "$work/renders/good/seed_$s.exr" &
  pids+=($!)
  "$render" --scene "$scene" --spp 64 --seed $((s + 10)) --reference --quiet -o "$work/renders/new/seed_$s.exr" &
  pids+=($!)
  "$render" --scene "$light" --spp 64 --seed $((s + 10)) --reference --quiet -o "$work/renders/light/seed_$s.exr" &
  pids+=($!)
  wait "${pids[@]}"
  pids=()
done

cmake -S "$src/tests/render-test/downstream" -B "$work/downstream" -DCMAKE_PREFIX_PATH="$work/prefix" \
  -DRENDERS="$work/renders" -DWITH_PYTHON=$with_python >"$work/configure.log" 2>&1 || { cat "$work/configure.log" >&2; fail "configure failed"; }
set +e
LD_PRELOAD=$preload ctest --test-dir "$work/downstream" --output-on-failure >"$work/ctest.log" 2>&1
status=$?
set -e
cat "$work/ctest.log"
[ $status -ne 0 ] || fail "the downstream suite passed, but brighter_light must fail"
grep -Eq 'same_scene \.+ +Passed' "$work/ctest.log" || fail "same_scene did not pass"
grep -Eq 'ocio_config \.+ +Passed' "$work/ctest.log" || fail "oiiotool did not take the installed OCIO config"
if [ $with_python = ON ]; then
  grep -Eq 'python_same_scene \.+ +Passed' "$work/ctest.log" || fail "the installed Python module's check did not pass"
  LD_PRELOAD=$preload ctest --test-dir "$work/downstream" -R python_same_scene -V \
    >"$work/python.log" 2>&1 || true
  grep -q "$work/prefix/.*mcstat/__init__.py SAME" "$work/python.log" ||
    { cat "$work/python.log" >&2; fail "Python did not import the installed module"; }
fi
grep -Eq 'brighter_light \.+\*+Failed' "$work/ctest.log" || fail "brighter_light did not fail"
grep -q 'DIFFERENT' "$work/ctest.log" || fail "brighter_light's verdict is not in its output"
reports="$work/downstream/mcstat-reports"
for f in same_scene.xml same_scene.json same_scene/index.html brighter_light.xml brighter_light.json \
  brighter_light/index.html brighter_light/heatmap.png; do
  [ -s "$reports/$f" ] || fail "no report $reports/$f"
done
grep -q '<failure' "$reports/brighter_light.xml" || fail "brighter_light.xml has no <failure>"
if grep -q '<failure' "$reports/same_scene.xml"; then fail "same_scene.xml has a <failure>"; fi
# The libraries need a compiler: asked for in a project without CXX, find_package says so.
mkdir -p "$work/nocxx"
printf 'cmake_minimum_required(VERSION 3.20)\nproject(x NONE)\nfind_package(mcstat CONFIG REQUIRED COMPONENTS libraries)\n' \
  >"$work/nocxx/CMakeLists.txt"
if cmake -S "$work/nocxx" -B "$work/nocxx/build" -DCMAKE_PREFIX_PATH="$work/prefix" >"$work/nocxx.log" 2>&1; then
  fail "find_package(mcstat COMPONENTS libraries) succeeded in a project without CXX"
fi
grep -q "enable the CXX language" "$work/nocxx.log" || { cat "$work/nocxx.log" >&2; fail "no reason given for the missing libraries"; }
echo "test_downstream: same_scene passed, brighter_light failed, reports written"
