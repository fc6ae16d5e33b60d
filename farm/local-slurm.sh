#!/usr/bin/env bash
# A one-node Slurm cluster in a folder, for the farm recipe's demo and test (docs/farm.md).
#
#   farm/local-slurm.sh start DIR    start munged, slurmctld and slurmd with everything in DIR;
#                                    prints: export SLURM_CONF=DIR/slurm.conf
#   farm/local-slurm.sh stop DIR     stop them by their pid files in DIR, wait until they exited
#   farm/local-slurm.sh status DIR   say which daemons of DIR run (exit 0 when all three run)
#
# As root (Debian 12: apt-get install -y slurm-wlm munge; /etc/munge/munge.key must exist).
# The configuration, state, spool, pid and log files all live in DIR; munged listens on its own
# socket in DIR and Slurm talks to it through AuthInfo=socket=...; the TCP ports are free ones
# chosen at start, so two clusters (or a leftover) never collide. Nothing is stopped by name.
set -euo pipefail

prog=local-slurm.sh
die() { echo "$prog: $*" >&2; exit 1; }
usage() { sed -n '4,12p' "$0" | sed 's/^# \{0,1\}//'; }

[[ $# -ge 1 ]] || { usage >&2; exit 2; }
case $1 in -h|--help) usage; exit 0 ;; esac
[[ $# -eq 2 ]] || { usage >&2; exit 2; }
cmd=$1
dir=$2
mkdir -p "$dir" 2>/dev/null || die "cannot create $dir"
dir=$(cd "$dir" && pwd)
conf=$dir/slurm.conf
daemons=(munged slurmctld slurmd)

pidfile() { echo "$dir/$1.pid"; }
# The pid of daemon $1 when its pid file names a live process, else nothing.
live_pid() {
  local f pid
  f=$(pidfile "$1")
  [[ -s $f ]] || return 1
  pid=$(tr -dc '0-9' <"$f")
  [[ -n $pid ]] && kill -0 "$pid" 2>/dev/null || return 1
  # Only a process started for DIR (its command line names a file in DIR): a stale pid file
  # whose number now belongs to another process is not ours to report or to stop.
  [[ $(tr '\0' ' ' <"/proc/$pid/cmdline" 2>/dev/null) == *"$dir/"* ]] || return 1
  echo "$pid"
}

log_tail() {  # the last lines of daemon $1's log, indented, for an error message
  local f=$dir/$1.log
  if [[ -s $f ]]; then tail -n 15 "$f" | sed 's/^/    /'; else echo "    ($f is empty or missing)"; fi
}

# Stop the daemons named in "$@" together: SIGTERM, then wait (10 s), then SIGKILL.
stop_these() {
  local name pid i rc=0 pids=() names=()
  for name in "$@"; do
    if pid=$(live_pid "$name"); then
      kill -TERM "$pid" 2>/dev/null || true
      pids+=("$pid") names+=("$name")
    else
      rm -f "$(pidfile "$name")"
    fi
  done
  for i in "${!pids[@]}"; do
    pid=${pids[$i]}
    for ((t = 0; t < 100; t++)); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    if kill -0 "$pid" 2>/dev/null; then
      kill -KILL "$pid" 2>/dev/null || true
      for ((t = 0; t < 50; t++)); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    fi
    if kill -0 "$pid" 2>/dev/null; then
      echo "$prog: ${names[$i]} (pid $pid) did not exit" >&2; rc=1
    else
      rm -f "$(pidfile "${names[$i]}")"
    fi
  done
  return $rc
}

do_stop() {
  local rc=0 i
  # Jobs still queued or running are cancelled first (this cluster is private to DIR, so every
  # job in it is ours), and their processes given a few seconds to end, so that no job step
  # outlives the daemons.
  if live_pid slurmctld >/dev/null && [[ -f $conf ]]; then
    SLURM_CONF=$conf scancel --user="$(id -un)" >/dev/null 2>&1 || true
    for ((i = 0; i < 100; i++)); do  # 10 s
      [[ -z $(SLURM_CONF=$conf squeue -h -o %i 2>/dev/null) ]] && break
      sleep 0.1
    done
  fi
  stop_these slurmd slurmctld || rc=1
  stop_these munged || rc=1
  return $rc
}

# A free TCP port (the kernel's choice on a bound socket, released at once), not equal to $1.
free_port() {
  local p
  for _ in 1 2 3 4 5; do
    p=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
    [[ $p != "${1:-}" ]] && { echo "$p"; return 0; }
  done
  return 1
}

do_start() {
  [[ $(id -u) -eq 0 ]] || die "must run as root (slurmd runs jobs as any user; this local cluster runs as root)"
  local b
  for b in munged slurmctld slurmd sinfo sbatch squeue scontrol python3; do
    command -v "$b" >/dev/null 2>&1 || die "$b not found (Debian 12: apt-get install -y slurm-wlm munge; scripts/install-deps.sh does it)"
  done
  [[ -r /etc/munge/munge.key ]] || die "/etc/munge/munge.key is missing (Debian's munge package creates it; or run: mungekey --create)"
  local n
  for n in "${daemons[@]}"; do
    if pid=$(live_pid "$n"); then
      die "$n of $dir already runs (pid $pid): '$prog stop $dir' first"
    fi
  done

  local host cpus ctld_port slurmd_port
  host=$(hostname -s)
  cpus=$(nproc)
  ctld_port=$(free_port) || die "no free TCP port found"
  slurmd_port=$(free_port "$ctld_port") || die "no free TCP port found"
  mkdir -p "$dir/state" "$dir/spool"
  # Whatever goes wrong from here on, nothing this start began keeps running.
  started=0
  trap '[[ $started -eq 1 ]] || do_stop' EXIT
  rm -f "$dir"/{munged,slurmctld,slurmd}.log

  # munged: its own socket, pid, log and seed in DIR (the system's /etc/munge/munge.key).
  munged --socket="$dir/munge.socket" --pid-file="$dir/munged.pid" --log-file="$dir/munged.log" \
    --seed-file="$dir/munged.seed" --force >"$dir/munged.out" 2>&1 ||
    { echo "$prog: munged did not start; its log:" >&2; cat "$dir/munged.out" >&2; log_tail munged >&2; exit 1; }
  for ((i = 0; i < 50; i++)); do [[ -S $dir/munge.socket ]] && break; sleep 0.1; done
  [[ -S $dir/munge.socket ]] || { echo "$prog: munged did not open $dir/munge.socket; its log:" >&2; log_tail munged >&2; do_stop; exit 1; }

  cat >"$conf" <<EOF
# Throwaway one-node cluster written by farm/local-slurm.sh (everything in $dir).
ClusterName=mcstatfarm
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$dir/munge.socket
CredType=cred/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
ReturnToService=2
# Short timeouts: a small test is fast; finished jobs leave squeue after MinJobAge seconds.
MinJobAge=10
KillWait=2
SlurmctldTimeout=10
SlurmdTimeout=10
InactiveLimit=0
Waittime=0
MessageTimeout=10
SchedulerType=sched/backfill
SchedulerParameters=bf_interval=1,sched_min_interval=100000,default_queue_depth=1000
MaxArraySize=100001
MaxJobCount=100000
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=farm Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
EOF

  if ! slurmctld -f "$conf" >"$dir/slurmctld.out" 2>&1; then
    echo "$prog: slurmctld did not start; the end of $dir/slurmctld.log:" >&2
    cat "$dir/slurmctld.out" >&2; log_tail slurmctld >&2; do_stop; exit 1
  fi
  if ! slurmd -f "$conf" >"$dir/slurmd.out" 2>&1; then
    echo "$prog: slurmd did not start; the end of $dir/slurmd.log:" >&2
    cat "$dir/slurmd.out" >&2; log_tail slurmd >&2; do_stop; exit 1
  fi
  # Wait (30 s at most) until the node is idle.
  local state=""
  for ((i = 0; i < 300; i++)); do
    for n in slurmctld slurmd; do
      if ! live_pid "$n" >/dev/null && (( i > 20 )); then
        echo "$prog: $n exited after starting; the end of $dir/$n.log:" >&2
        log_tail "$n" >&2; do_stop; exit 1
      fi
    done
    state=$(SLURM_CONF=$conf sinfo -h -n "$host" -o '%T' 2>/dev/null | head -n 1) || true
    [[ $state == idle ]] && break
    sleep 0.1
  done
  if [[ $state != idle ]]; then
    echo "$prog: the node $host is not idle after 30 s (state: '${state:-no answer}'); the end of the logs:" >&2
    for n in slurmctld slurmd; do echo "  $n:" >&2; log_tail "$n" >&2; done
    do_stop; exit 1
  fi
  started=1
  echo "export SLURM_CONF=$conf"
}

do_status() {
  local n rc=0 pid
  for n in "${daemons[@]}"; do
    if pid=$(live_pid "$n"); then echo "$n: running (pid $pid)"; else echo "$n: not running"; rc=1; fi
  done
  if [[ $rc -eq 0 ]]; then
    SLURM_CONF=$conf sinfo -h -o 'node %N: %T, %c CPUs, partition %P' 2>/dev/null || true
  fi
  return $rc
}

case $cmd in
  start) do_start ;;
  stop) do_stop ;;
  status) do_status ;;
  *) usage >&2; exit 2 ;;
esac
