#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for the cluster tests (docs/cluster.md): installs
# munge and slurm-wlm (Debian) when missing, writes a slurm.conf for this host into a state folder,
# and starts munged, slurmctld and slurmd as root. Prints the `export SLURM_CONF=...` line that
# clients (sbatch, squeue, scontrol) need. Idempotent: a cluster already answering is left alone.
#
# Usage: tools/slurm_single_node.sh [STATE_DIR]      (default: /tmp/bbsplat-slurm)
#        tools/slurm_single_node.sh --stop [STATE_DIR]
set -euo pipefail
stop=0
if [ "${1:-}" = "--stop" ]; then stop=1; shift; fi
dir="${1:-/tmp/bbsplat-slurm}"
conf="$dir/slurm.conf"
if [ "$stop" = 1 ]; then
  for pid in "$dir/slurmd.pid" "$dir/slurmctld.pid"; do
    [ -f "$pid" ] && kill "$(cat "$pid")" 2>/dev/null || true
  done
  exit 0
fi
[ "$(id -u)" = 0 ] || { echo "slurm_single_node.sh: must run as root (the daemons are root's here)" >&2; exit 1; }
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null
fi
mkdir -p "$dir/state" "$dir/spool"
host="$(hostname -s)"
cpus="$(nproc)"
# Leave 2 GiB to the system.
mem_mb=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 2048 ))
cat > "$conf" <<CONF
ClusterName=bbsplat
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
SchedulerType=sched/backfill
ReturnToService=2
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
# A job past its time limit gets SIGTERM, then SIGKILL this many seconds later.
KillWait=30
NodeName=$host CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$conf"
if ! pgrep -x munged >/dev/null; then
  mkdir -p /run/munge && chown munge:munge /run/munge 2>/dev/null || true
  [ -s /etc/munge/munge.key ] || { dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2>/dev/null; chmod 400 /etc/munge/munge.key; }
  chown munge:munge /etc/munge/munge.key 2>/dev/null || true
  if id munge >/dev/null 2>&1; then
    su -s /bin/sh munge -c "/usr/sbin/munged" || /usr/sbin/munged --force
  else
    /usr/sbin/munged --force
  fi
fi
if ! scontrol ping 2>/dev/null | grep -q "is UP"; then
  slurmctld -f "$conf"
  slurmd -f "$conf"
fi
# Wait (bounded) for the node to take jobs.
for _ in $(seq 1 60); do
  if sinfo -h -o %T 2>/dev/null | grep -qE "^(idle|mixed|allocated)"; then
    echo "export SLURM_CONF=$conf"
    exit 0
  fi
  sleep 1
done
echo "slurm_single_node.sh: the node did not come up; see $dir/slurmctld.log and $dir/slurmd.log" >&2
sinfo >&2 || true
exit 1
