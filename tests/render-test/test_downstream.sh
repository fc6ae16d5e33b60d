#!/usr/bin/env bash
# test_downstream.sh SOURCE BUILD WORK: installs mcstat into WORK/prefix, renders a tiny scene as
# seeds (the same scene twice with other seeds, and with its light 2 % brighter), configures the
# downstream project (downstream/CMakeLists.txt: find_package(mcstat) and mcstat_add_render_test)
# against the installed package and runs its CTest suite: same_scene must pass, brighter_light
# must fail, each leaving its JUnit, JSON and report page. Exits 1 with a message otherwise.
set -euo pipefail
src=$1 build=$2 work=$3
rm -rf "$work"
mkdir -p "$work"
fail() { echo "test_downstream: $*" >&2; exit 1; }

cmake --install "$build" --prefix "$work/prefix" --component dev >/dev/null
cmake --install "$build" --prefix "$work/prefix" --component bin >/dev/null
cmake --install "$build" --prefix "$work/prefix" --component plugin >/dev/null  # mcstat_PLUGIN_DIR

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
  -DRENDERS="$work/renders" >"$work/configure.log" 2>&1 || { cat "$work/configure.log" >&2; fail "configure failed"; }
set +e
ctest --test-dir "$work/downstream" --output-on-failure >"$work/ctest.log" 2>&1
status=$?
set -e
cat "$work/ctest.log"
[ $status -ne 0 ] || fail "the downstream suite passed, but brighter_light must fail"
grep -Eq 'same_scene \.+ +Passed' "$work/ctest.log" || fail "same_scene did not pass"
grep -Eq 'brighter_light \.+\*+Failed' "$work/ctest.log" || fail "brighter_light did not fail"
grep -q 'DIFFERENT' "$work/ctest.log" || fail "brighter_light's verdict is not in its output"
reports="$work/downstream/mcstat-reports"
for f in same_scene.xml same_scene.json same_scene/index.html brighter_light.xml brighter_light.json \
  brighter_light/index.html brighter_light/heatmap.png; do
  [ -s "$reports/$f" ] || fail "no report $reports/$f"
done
grep -q '<failure' "$reports/brighter_light.xml" || fail "brighter_light.xml has no <failure>"
if grep -q '<failure' "$reports/same_scene.xml"; then fail "same_scene.xml has a <failure>"; fi
echo "test_downstream: same_scene passed, brighter_light failed, reports written"
