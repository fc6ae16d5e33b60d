#!/usr/bin/env bash
# The render farm recipe (farm/, docs/farm.md) on a real one-node Slurm cluster, no mocks:
#   1. farm/demo.sh, the documented command (its own cluster): 3 frames x 6 seeds of the fixture
#      renderer merged in a tree of fan-in 2; each frame the same bytes as one
#      `mcstat <6 seeds> --merge:fanin=2`, its G-MoN the same pixels.
#   2. On a cluster started here (stopped by pid file at the end, also on failure): a shot with one
#      render task made to fail (frame 2, seed 3) and one killed with kill -9 during its write
#      (frame 1, seed 5). Frame 3 finishes; the report names the failed task, its array task id,
#      node and log, and the killed one; their frames' merges and estimate did not run; the killed
#      task's partial file never reached its final name. Resubmitted: only the 2 missing renders
#      and those frames' downstream jobs run (4 merges, 2 estimates), the rest is left untouched,
#      and every frame equals the single-machine merge (fan-in 3) bit for bit.
#      A rerun seed (as a requeue runs it) replaces its own file; the merge refuses a seed twice.
#   3. The EXR kind (fixture --reference): per frame one `mcstat --ingest`, the same bytes as one
#      `mcstat --ingest` of the same files on one machine.
#   4. The Blender/Cycles template (farm/templates/cycles.tmpl): 1 frame x 2 seeds through
#      ingest; the estimate carries the AOVs.
#   5. Other tree shapes, run without Slurm (mcstat-farm run-local): 9 seeds with fan-in 8 (a group
#      of one passes through a level), 10 seeds with fan-in 3, one seed; each the same bytes as
#      one `mcstat <seeds> --merge:fanin=K`.
# It fails (never skips) when Slurm cannot start: not root, slurm-wlm/munge missing, a daemon
# that does not come up; the reason is printed. Labelled slow (not run under the sanitizers).
#
#   test_farm.sh SOURCE_DIR BUILD_DIR WORK_DIR
set -euo pipefail
[[ $# -eq 3 ]] || { echo "usage: test_farm.sh SOURCE_DIR BUILD_DIR WORK_DIR" >&2; exit 2; }
src=$(cd "$1" && pwd)
build=$(cd "$2" && pwd)
work=$3
farm=$src/farm
export MCSTAT_BIN_DIR=$build          # mcstat-farm and demo.sh find build/oiiotool-ext/mcstat etc.
mcstat=$build/oiiotool-ext/mcstat
t_start=$SECONDS

fail() { echo "test_farm: FAIL: $*" >&2; exit 1; }
step() { echo "== [$((SECONDS - t_start)) s] $*"; }
check() { local what=$1; shift; "$@" || fail "$what"; }
json() { python3 -c "import json, sys; d = json.load(open(sys.argv[1])); print($2)" "$1"; }

# A local cluster needs root (slurmd runs each job as its user): as anyone else the test is
# skipped, one line saying why (CTest's SKIP_RETURN_CODE 77); as root it fails where Slurm fails.
if [[ $(id -u) -ne 0 ]]; then
  echo "test_farm: skipped: a local Slurm cluster (munged, slurmctld, slurmd) needs root; run as $(id -un)"
  exit 77
fi
for b in munged slurmctld slurmd sbatch squeue; do
  command -v "$b" >/dev/null || fail "$b not found: Slurm is needed (scripts/install-deps.sh installs slurm-wlm and munge)"
done
[[ -x $mcstat && -x $build/render-fixture/mcstat-render ]] || fail "mcstat or mcstat-render missing in $build"
command -v oiiotool >/dev/null || fail "oiiotool not found (openimageio-tools)"
command -v blender >/dev/null || fail "blender not found (scripts/install-deps.sh installs it; the Cycles template is tested)"

# A cluster left by a run that was killed (its pid files name it) is stopped first, by pid file.
[[ ! -d $work/slurm ]] || "$farm/local-slurm.sh" stop "$work/slurm" || true
rm -rf "$work"
mkdir -p "$work"
cd "$work"
host=$(hostname -s)

# Our own bound, below ctest's TIMEOUT (600 s): ctest's kill would leave the daemons running,
# a SIGTERM from here runs the traps that stop them.
# The sleep must not hold our stdout/stderr: killing the subshell leaves it running, and ctest
# waits for every holder of the test's output to close it.
( sleep "${MCSTAT_FARM_TEST_BOUND:-540}" </dev/null >/dev/null 2>&1
  echo "test_farm: FAIL: not done after ${MCSTAT_FARM_TEST_BOUND:-540} s; stopping" >&2
  kill -TERM $$ 2>/dev/null ) &
watchdog=$!
# The watchdog and its sleep (a child of the subshell, which a kill of the subshell leaves).
stop_watchdog() {
  local sleeper
  sleeper=$(ps -o pid= --ppid "$watchdog" 2>/dev/null || true)
  kill "$watchdog" $sleeper 2>/dev/null || true
}
child=""
on_term() {
  [[ -z $child ]] || kill -TERM "$child" 2>/dev/null || true
  [[ -z $child ]] || wait "$child" 2>/dev/null || true
  exit 124
}
trap on_term INT TERM
# Long steps run in the background and are waited for: a trap runs only after a foreground
# command ends, and a SIGTERM must stop a waiting submit at once.
run() { "$@" & child=$!; local rc=0; wait "$child" || rc=$?; child=""; return $rc; }
trap 'stop_watchdog' EXIT

# Same pixels (every channel) in two EXRs.
same_pixels() { oiiotool --fail 0 --failpercent 0 "$1" "$2" --diff >/dev/null 2>&1; }
# Each frame of SHOT against the single-machine merge of its seed files with fan-in K.
check_stats_shot() {
  local shot=$1 name=$2 k=$3 f f4
  mkdir -p "$shot.single"
  for f in $(json "$shot/shot.json" '" ".join(map(str, d["frames"]))'); do
    f4=$(printf %04d "$f")
    "$mcstat" -q "$shot"/render/f$f4/s*.mcstat --merge:fanin="$k" -o "$shot.single/$f4.mcstat"
    cmp "$shot.single/$f4.mcstat" "$shot/out/$name.$f4.mcstat" ||
      fail "$shot frame $f: the farm's statistics file differs from mcstat <seeds> --merge:fanin=$k"
    "$mcstat" -q "$shot.single/$f4.mcstat" --gmon -d half -o "$shot.single/$f4.gmon.exr"
    same_pixels "$shot.single/$f4.gmon.exr" "$shot/out/$name.$f4.gmon.exr" ||
      fail "$shot frame $f: the farm's G-MoN pixels differ from the single-machine estimate"
  done
}
check_exr_shot() {
  local shot=$1 name=$2 f f4
  mkdir -p "$shot.single"
  for f in $(json "$shot/shot.json" '" ".join(map(str, d["frames"]))'); do
    f4=$(printf %04d "$f")
    "$mcstat" -q --ingest "$shot/render/f$f4/s*.exr" -o "$shot.single/$f4.mcstat"
    cmp "$shot.single/$f4.mcstat" "$shot/out/$name.$f4.mcstat" ||
      fail "$shot frame $f: the farm's ingest differs from one mcstat --ingest of the same files"
    "$mcstat" -q "$shot.single/$f4.mcstat" --gmon -d half -o "$shot.single/$f4.gmon.exr"
    same_pixels "$shot.single/$f4.gmon.exr" "$shot/out/$name.$f4.gmon.exr" ||
      fail "$shot frame $f: the farm's G-MoN pixels differ from the single-machine estimate"
  done
}

# ---- 0. a user's folder is never the farm's (issue 47): refused, every file kept
step "a user's folder as --out or SHOTDIR"
mkdir -p user/src && echo mine >user/notes.txt && echo mine >user/src/main.py && mkdir -p user/shot
echo mine >user/shot/keep.txt
rc=0; "$farm/demo.sh" --out user >refused.log 2>&1 || rc=$?
[[ $rc -eq 1 ]] && grep -q "user holds files and is not a farm demo's folder" refused.log ||
  { cat refused.log >&2; fail "farm/demo.sh --out into a user's folder was not refused"; }
rc=0; "$farm/mcstat-farm" submit user --dry-run --frames 1 --seeds 2 --spp 4 --res 32 24 \
  --template-file "$farm/templates/fixture-stats.tmpl" >refused.log 2>&1 || rc=$?
[[ $rc -ne 0 ]] && grep -q "holds files but no shot.json" refused.log ||
  { cat refused.log >&2; fail "mcstat-farm submit into a user's folder was not refused"; }
[[ $(cat user/notes.txt user/src/main.py user/shot/keep.txt) == $'mine\nmine\nmine' &&
   $(find user | wc -l) -eq 6 ]] || fail "a user's folder changed: $(find user)"

# ---- 1. the documented command
step "farm/demo.sh (its own cluster)"
rc=0
run "$farm/demo.sh" --out "$work/demo" --wait 300 >demo.log 2>&1 || rc=$?
if [[ $rc -ne 0 ]]; then
  tail -n 40 demo.log >&2
  fail "farm/demo.sh failed (log above)"
fi
[[ $(grep -c "the same bytes as mcstat <6 seeds> --merge:fanin=2; G-MoN EXR: the same pixels" demo.log) -eq 3 ]] ||
  { cat demo.log >&2; fail "farm/demo.sh did not report 3 matching frames"; }
slurm_demo=$(sed -n 's/^== a one-node Slurm cluster in //p' demo.log)
[[ -n $slurm_demo && ! -e $slurm_demo ]] || fail "farm/demo.sh left its Slurm folder $slurm_demo"
grep -E "^(munged|slurmctld|slurmd): running \(pid [0-9]+\)" demo.log | sed 's/.*pid \([0-9]*\).*/\1/' >demo.pids
while read -r pid; do
  ! kill -0 "$pid" 2>/dev/null || [[ $(tr '\0' ' ' </proc/"$pid"/cmdline 2>/dev/null) != *"$slurm_demo"* ]] ||
    fail "farm/demo.sh left a daemon running (pid $pid)"
done <demo.pids
# The tree of fan-in 2 over 6 seeds: levels 6 -> 3 -> 2 -> 1, 5 merge jobs per frame.
[[ $(json demo/shot/submissions.json 'd[0]["counts"]["merge"]') -eq 15 ]] || fail "demo: 15 merge jobs expected"

# ---- 2. a cluster of our own, stopped by pid file whatever happens
slurm=$work/slurm
stop_cluster() {
  local rc=$?
  stop_watchdog
  "$farm/local-slurm.sh" stop "$slurm" || { echo "test_farm: could not stop the cluster in $slurm" >&2; rc=1; }
  exit $rc
}
trap stop_cluster EXIT
step "farm/local-slurm.sh start"
run "$farm/local-slurm.sh" start "$slurm" >start.out || fail "Slurm did not start (reason above)"
start_out=$(cat start.out)
eval "$start_out"
export SLURM_CONF
[[ $SLURM_CONF == "$slurm/slurm.conf" ]] || fail "local-slurm.sh start printed '$start_out'"
"$farm/local-slurm.sh" status "$slurm" >/dev/null || fail "local-slurm.sh status: not all daemons run"

step "a shot with a failing task (frame 2, seed 3) and a task killed during its write (frame 1, seed 5)"
trig=$work/triggers
mkdir -p "$trig"
touch "$trig/fail" "$trig/kill"
# The fault template: the fixture renderer, except that while a trigger file exists, frame 2
# seed 3 fails with exit 3, and frame 1 seed 5 writes half a file and then kill -9s its task
# (the run-task wrapper, its parent) and itself, as a lost node or the OOM killer would.
# Its message carries a colour escape and a window-title sequence, as a renderer's output may:
# the report shows them escaped (farm/mcstat-farm printable()).
fault_tmpl='if [ -e {trig}/fail ] && [ {frame} = 2 ] && [ {seed} = 3 ]; then echo "injected failure: frame {frame} seed {seed}" >&2; printf "\033[31mred\033]0;title\007 done\n" >&2; exit 3; fi; '
fault_tmpl+='if [ -e {trig}/kill ] && [ {frame} = 1 ] && [ {seed} = 5 ]; then head -c 50000 /dev/urandom >{output}; kill -9 $PPID $$; fi; '
fault_tmpl+='{mcstat_render} --scene default --res 64 48 --spp 16 --M 8 --seed $(( {frame} * 1000 + {seed} )) --quiet -o {output}'
B=$work/fault
rc=0
run "$farm/mcstat-farm" submit "$B" --name fault --kind stats --frames 1-3 --seeds 6 --spp 16 \
  --template "$fault_tmpl" --var trig="$trig" --fanin 3 --wait 300 >fault1.log 2>&1 || rc=$?
cat fault1.log
[[ $rc -eq 1 ]] || fail "submit --wait of the faulty shot: exit status 1 expected (frames incomplete), got $rc"
R=$B/report.json
[[ $(json "$R" 'd["frames"]["3"]["state"]') == done ]] || fail "frame 3 should be done"
[[ $(json "$R" 'd["frames"]["2"]["state"]') == failed ]] || fail "frame 2 should have failed"
[[ $(json "$R" 'd["frames"]["1"]["state"]') == failed ]] || fail "frame 1 should have failed (killed task)"
# The failed task: frame 2, seed 3 = array task 1*6+2 = 8, on this node, with its log.
[[ $(json "$R" '" ".join(i["item"] for i in d["frames"]["2"]["failed"])') == render.f0002.s0003 ]] ||
  fail "the report should name render.f0002.s0003 as the failed task"
[[ $(json "$R" 'd["frames"]["2"]["failed"][0]["array_task"]') == 8 ]] || fail "failed task: array task 8"
[[ $(json "$R" 'd["frames"]["2"]["failed"][0]["node"]') == "$host" ]] || fail "failed task: node $host"
[[ $(json "$R" 'd["frames"]["2"]["failed"][0]["exit_code"]') == 3 ]] || fail "failed task: exit code 3"
flog=$(json "$R" 'd["frames"]["2"]["failed"][0]["log"]')
grep -q "injected failure: frame 2 seed 3" "$B/$flog" || fail "the failed task's log $flog lacks its error"
[[ $(json "$R" '" ".join(sorted(i["item"] for i in d["frames"]["2"]["cancelled"]))') == \
   "estimate.f0002 merge.f0002.l1.g1 merge.f0002.l2.g1" ]] ||
  fail "frame 2: the merges reading seed 3 and the estimate should be reported as not run"
grep -q "FAILED render f2 s3 (array task 8 of job [0-9]*) on node $host: exit code 3; log $flog" "$B/report.txt" ||
  { cat "$B/report.txt"; fail "report.txt does not name the failed task, its node and log"; }
grep -qF '| \x1b[31mred\x1b]0;title\x07 done' "$B/report.txt" ||
  { cat "$B/report.txt"; fail "report.txt does not show the log's escape sequences escaped"; }
! LC_ALL=C grep -q "$(printf '[\001-\011\013-\037\177]')" "$B/report.txt" ||
  fail "report.txt holds a control byte"
# The killed task: started, never ended, gone from the queue; its partial file only under tmp/.
[[ $(json "$R" '" ".join(i["item"] for i in d["frames"]["1"]["killed"])') == render.f0001.s0005 ]] ||
  fail "the report should name render.f0001.s0005 as killed"
grep -q "KILLED render f1 s5 (array task 4 of job [0-9]*) on node $host" "$B/report.txt" ||
  fail "report.txt does not name the killed task"
[[ ! -e $B/render/f0001/s0005.mcstat ]] || fail "the killed task left a file under its final name"
ls "$B"/tmp/render.f0001.s0005.*/s0005.mcstat >/dev/null 2>&1 ||
  fail "the killed task's partial file should be left under tmp/ (the proof that it was written there)"
[[ $(json "$R" '" ".join(sorted(i["item"] for i in d["frames"]["1"]["cancelled"]))') == \
   "estimate.f0001 merge.f0001.l1.g2 merge.f0001.l2.g1" ]] || fail "frame 1: downstream steps not reported as not run"
for f in "$B"/out/fault.0001.mcstat "$B"/out/fault.0002.mcstat "$B"/out/fault.0001.gmon.exr \
    "$B"/out/fault.0002.gmon.exr "$B"/merge/f0002/l1_g1.mcstat "$B"/merge/f0001/l1_g2.mcstat \
    "$B"/status/merge.f0002.l1.g1.json "$B"/status/estimate.f0002.json; do
  [[ ! -e $f ]] || fail "$f exists: that step should not have run"
done
for f in "$B"/merge/f0002/l1_g2.mcstat "$B"/merge/f0001/l1_g1.mcstat "$B"/out/fault.0003.mcstat "$B"/out/fault.0003.gmon.exr; do
  [[ -s $f ]] || fail "$f missing: the steps that do not read the failed task should have run"
done
# `report` prints the same and exits 1.
rc=0; "$farm/mcstat-farm" report "$B" >report_again.txt || rc=$?
[[ $rc -eq 1 ]] && cmp -s report_again.txt "$B/report.txt" || fail "mcstat-farm report: exit 1 and the same report expected"

step "resubmit: only the missing renders and their frames' downstream jobs"
rm -f "$trig/fail" "$trig/kill"
keep=("$B/out/fault.0003.mcstat" "$B/out/fault.0003.gmon.exr" "$B/render/f0002/s0001.mcstat"
      "$B/merge/f0002/l1_g2.mcstat" "$B/merge/f0001/l1_g1.mcstat")
before=$(stat -c '%i %Y' "${keep[@]}")
rc=0
run "$farm/mcstat-farm" submit "$B" --wait 300 >fault2.log 2>&1 || rc=$?
cat fault2.log
[[ $rc -eq 0 ]] || fail "the resubmitted shot did not complete"
grep -q "submission 2 of shot fault: 2 render tasks, 4 merge jobs, 2 estimate jobs" fault2.log ||
  fail "the rerun should submit 2 render tasks, 4 merge jobs and 2 estimate jobs"
[[ $(json "$B/submissions.json" '" ".join(sorted(d[1]["jobs"]))') == \
   "estimate.f0001 estimate.f0002 merge.f0001.l1.g2 merge.f0001.l2.g1 merge.f0002.l1.g1 merge.f0002.l2.g1 render.f0001.s0005 render.f0002.s0003" ]] ||
  fail "the rerun submitted other jobs than the missing ones: $(json "$B/submissions.json" 'sorted(d[1]["jobs"])')"
[[ $(json "$B/submissions.json" 'd[1]["arrays"][0]["array"]') == "4,8" ]] || fail "the rerun's array should be 4,8"
[[ $(stat -c '%i %Y' "${keep[@]}") == "$before" ]] || fail "the rerun rewrote files that were complete"
[[ ! -e $B/tmp ]] || [[ -z $(ls -A "$B/tmp") ]] || fail "the killed task's partial file should be gone after the rerun"
check_stats_shot "$B" fault 3
out3=$("$farm/mcstat-farm" submit "$B")
[[ $out3 == *"is complete: nothing to submit"* ]] || fail "a third submit should find nothing to do"

step "a seed run again (as a requeue runs it) replaces its own file; the merge refuses a seed twice"
cp "$B/render/f0001/s0003.mcstat" requeue_before.mcstat
ino=$(stat -c %i "$B/render/f0001/s0003.mcstat")
SLURM_ARRAY_JOB_ID=999 SLURM_ARRAY_TASK_ID=2 SLURM_JOB_ID=1000 SLURMD_NODENAME=$host \
  "$farm/mcstat-farm" run-task "$B" render >/dev/null || fail "run-task of frame 1 seed 3 failed"
[[ $(stat -c %i "$B/render/f0001/s0003.mcstat") != "$ino" ]] || fail "the rerun seed did not replace its file"
cmp -s requeue_before.mcstat "$B/render/f0001/s0003.mcstat" || fail "the rerun seed's file differs (same seed)"
[[ $(ls "$B/render/f0001" | wc -l) -eq 6 ]] || fail "render/f0001 should still hold 6 files"
[[ $(json "$B/status/render.f0001.s0003.json" 'd["attempt"]') -eq 2 ]] || fail "the status record should count 2 attempts"
cp "$B/render/f0001/s0003.mcstat" "$work/s0003-copy.mcstat"
if "$mcstat" -q "$B"/render/f0001/s*.mcstat "$work/s0003-copy.mcstat" --merge -o twice.mcstat 2>twice.err; then
  fail "the merge took a seed twice"
fi
grep -q "1003" twice.err || { cat twice.err; fail "the merge's refusal should name seed 1003"; }
[[ ! -e twice.mcstat ]] || fail "the refused merge wrote a file"

step "the EXR kind: renders as EXRs, one mcstat --ingest per frame"
C=$work/exrshot
run "$farm/mcstat-farm" submit "$C" --name exrshot --frames 1,3 --seeds 4 --spp 16 --res 64 48 \
  --template-file "$farm/templates/fixture-exr.tmpl" --wait 300 >exr.log 2>&1 || { cat exr.log; fail "the EXR shot failed"; }
cat exr.log
grep -q "8 render tasks, 2 ingest jobs, 2 estimate jobs" exr.log || fail "EXR shot: 8 renders, 2 ingests, 2 estimates expected"
check_exr_shot "$C" exrshot

step "the Blender/Cycles template: 1 frame x 2 seeds, ingested, the estimate with its AOVs"
D=$work/cycles
run "$farm/mcstat-farm" submit "$D" --name cyc --frames 7 --seeds 2 --spp 8 --res 48 36 \
  --template-file "$farm/templates/cycles.tmpl" --wait 300 >cycles.log 2>&1 || { cat cycles.log; fail "the Cycles shot failed"; }
cat cycles.log
check_exr_shot "$D" cyc
"$mcstat" "$D/out/cyc.0007.mcstat" --info >cycles_info.txt
grep -q "M = 2 sub-buffers, spp = 16" cycles_info.txt || { cat cycles_info.txt; fail "Cycles shot: M = 2, 16 spp expected"; }
grep -q 'renderer "Blender/Cycles' cycles_info.txt || fail "Cycles shot: not rendered by Cycles?"
nch=$(oiiotool --info "$D/out/cyc.0007.gmon.exr" | sed -n 's/.*, \([0-9]*\) channel.*/\1/p')
[[ ${nch:-0} -gt 4 ]] || fail "the Cycles estimate should carry the AOVs (found ${nch:-no} channels)"

step "tree shapes without Slurm (run-local): 9 seeds fan-in 8 (a group of one passes through), 10 seeds fan-in 3, 1 seed"
for combo in "9 8" "10 3" "1 2"; do
  set -- $combo
  T=$work/tree-s$1-k$2
  run "$farm/mcstat-farm" run-local "$T" --name t --frames 5 --seeds "$1" --spp 8 --res 32 24 \
    --template-file "$farm/templates/fixture-stats.tmpl" --fanin "$2" --estimate none >"$T.log" 2>&1 ||
    { cat "$T.log"; fail "run-local of $1 seeds, fan-in $2 failed"; }
  if [[ $1 -gt 1 ]]; then
    "$mcstat" -q "$T"/render/f0005/s*.mcstat --merge:fanin="$2" -o "$T.single.mcstat"
  else
    cp "$T/render/f0005/s0001.mcstat" "$T.single.mcstat"   # one seed: the frame's file is that render
  fi
  cmp "$T.single.mcstat" "$T/out/t.0005.mcstat" || fail "$1 seeds, fan-in $2: the tree differs from --merge:fanin=$2"
done

step "report on a shot run without Slurm: complete, and no word of the queue when no controller answers"
rc=0; SLURM_CONF=/nonexistent/slurm.conf "$farm/mcstat-farm" report "$T" >"$T.report" 2>&1 || rc=$?
[[ $rc -eq 0 ]] || { cat "$T.report"; fail "report of a complete run-local shot: exit 0 expected, got $rc"; }
! grep -q "queue could not be read" "$T.report" ||
  { cat "$T.report"; fail "report of a run-local shot asked squeue"; }

step "a compact shot (run-local --compact): the frame's file is the merge compacted, in the same job"
T=$work/compact
run "$farm/mcstat-farm" run-local "$T" --name c --frames 2 --seeds 3 --spp 16 --res 32 24 \
  --template-file "$farm/templates/fixture-stats.tmpl" --fanin 2 --compact >"$T.log" 2>&1 ||
  { cat "$T.log"; fail "run-local of a compact shot failed"; }
"$mcstat" -q "$T"/render/f0002/s*.mcstat --merge:fanin=2 --compact -o "$T.single.mcstat"
cmp "$T.single.mcstat" "$T/out/c.0002.mcstat" || fail "compact shot: the frame's file differs from --merge --compact"
"$mcstat" "$T/out/c.0002.mcstat" --info | grep -q "^  compact: a pixel keeps its buffers" || fail "compact shot: the frame's file is not compact"
[[ -f "$T/out/c.0002.gmon.exr" ]] || fail "compact shot: no estimate"

step "stop the cluster"
trap 'stop_watchdog' EXIT
"$farm/local-slurm.sh" stop "$slurm" || fail "local-slurm.sh stop failed"
for d in munged slurmctld slurmd; do [[ ! -e $slurm/$d.pid ]] || fail "$d.pid left after stop"; done
echo "test_farm: PASS in $((SECONDS - t_start)) s"
