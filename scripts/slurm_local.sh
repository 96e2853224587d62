#!/usr/bin/env bash
# A single-node Slurm on this machine, for the Slurm backend's tests and for trying
# `synth render --backend slurm` without a cluster.
#
#   scripts/slurm_local.sh start [STATE_DIR]   install (if missing), configure, start; prints
#                                              the `export SLURM_CONF=...` line to use
#   scripts/slurm_local.sh stop  [STATE_DIR]   cancel its jobs and stop the daemons it started
#   scripts/slurm_local.sh status [STATE_DIR]
#
# Installs Debian's slurm-wlm and munge with apt when they are missing (needs root). Every
# file lives in STATE_DIR (default /tmp/synth-slurm): a munge key made here, munged on its
# own socket, slurm.conf for one node (this host, on 127.0.0.1, ports 16817/16818) with
# ProctrackType=proctrack/linuxproc, TaskPlugin=task/none and no accounting; nothing under
# /etc is changed. Exit status 3 means it cannot run here (not root, no apt, install
# failed), with one line saying why on stderr.
set -euo pipefail

cmd=${1:-start}
STATE=${2:-${SYNTH_SLURM_DIR:-/tmp/synth-slurm}}
CONF=$STATE/slurm.conf
HOST=$(hostname -s)

cannot() { echo "slurm_local: cannot run a local Slurm here: $*" >&2; exit 3; }

pid_alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

install() {
  command -v slurmctld >/dev/null 2>&1 && command -v slurmd >/dev/null 2>&1 \
    && command -v munged >/dev/null 2>&1 && command -v sbatch >/dev/null 2>&1 && return 0
  [ "$(id -u)" = 0 ] || cannot "slurm-wlm/munge are not installed and installing them needs root"
  command -v apt-get >/dev/null 2>&1 || cannot "slurm-wlm/munge are not installed and there is no apt-get"
  export DEBIAN_FRONTEND=noninteractive
  if ! apt-get install -y -qq --no-install-recommends slurm-wlm munge >"$STATE/apt.log" 2>&1; then
    apt-get update -qq >>"$STATE/apt.log" 2>&1 || true
    apt-get install -y -qq --no-install-recommends slurm-wlm munge >>"$STATE/apt.log" 2>&1 \
      || cannot "apt-get install slurm-wlm munge failed (see $STATE/apt.log)"
  fi
}

write_conf() {
  local cpus
  cpus=$(nproc)
  cat >"$CONF" <<EOF
# written by scripts/slurm_local.sh: one node, this host
ClusterName=synthlocal
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=16817
SlurmdPort=16818
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$STATE/munge.socket
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/spool
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
ReturnToService=2
MinJobAge=600
KillWait=5
SlurmdTimeout=60
NodeName=$HOST NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=local Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
EOF
}

start() {
  mkdir -p "$STATE/ctld" "$STATE/spool"
  [ "$(id -u)" = 0 ] || cannot "the daemons run as root here (SlurmUser=root); run as root"
  install
  if [ ! -s "$STATE/munge.key" ]; then
    umask 077
    dd if=/dev/urandom of="$STATE/munge.key" bs=1024 count=1 status=none
    chmod 400 "$STATE/munge.key"
  fi
  write_conf
  if ! pid_alive "$STATE/munged.pid"; then
    munged --force --socket="$STATE/munge.socket" --key-file="$STATE/munge.key" \
      --pid-file="$STATE/munged.pid" --log-file="$STATE/munged.log" --seed-file="$STATE/munge.seed" \
      || cannot "munged did not start (see $STATE/munged.log)"
  fi
  export SLURM_CONF=$CONF
  pid_alive "$STATE/slurmctld.pid" || slurmctld -f "$CONF" || cannot "slurmctld did not start (see $STATE/slurmctld.log)"
  pid_alive "$STATE/slurmd.pid" || slurmd -f "$CONF" || cannot "slurmd did not start (see $STATE/slurmd.log)"
  for _ in $(seq 60); do
    state=$(sinfo -h -n "$HOST" -o %T 2>/dev/null | head -1 || true)
    case "$state" in
      idle*|mixed*|alloc*) echo "export SLURM_CONF=$CONF"; return 0 ;;
      down*|drain*) scontrol update nodename="$HOST" state=resume >/dev/null 2>&1 || true ;;
    esac
    sleep 1
  done
  cannot "the node did not become idle (state: ${state:-none}; see $STATE/slurmctld.log, $STATE/slurmd.log)"
}

stop() {
  export SLURM_CONF=$CONF
  if pid_alive "$STATE/slurmctld.pid"; then
    scancel --full -u "$(id -un)" >/dev/null 2>&1 || true
  fi
  for d in slurmd slurmctld munged; do
    if pid_alive "$STATE/$d.pid"; then
      pid=$(cat "$STATE/$d.pid")
      kill "$pid" 2>/dev/null || true
      for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.2; done
      kill -9 "$pid" 2>/dev/null || true
    fi
    rm -f "$STATE/$d.pid"
  done
}

case "$cmd" in
  start) start ;;
  stop) stop ;;
  status)
    for d in munged slurmctld slurmd; do
      if pid_alive "$STATE/$d.pid"; then echo "$d: running (pid $(cat "$STATE/$d.pid"))"; else echo "$d: stopped"; fi
    done ;;
  *) echo "usage: $0 start|stop|status [STATE_DIR]" >&2; exit 2 ;;
esac
