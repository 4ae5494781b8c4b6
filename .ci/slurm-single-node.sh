#!/usr/bin/env bash
# A one-node SLURM cluster on this machine, for `pytest -m slurm` (tests/test_slurm.py) and for
# trying profiles/slurm without a real cluster. Debian/Ubuntu, as root:
#
#   sudo .ci/slurm-single-node.sh && .venv/bin/pytest -m slurm
#
# Installs Debian's slurm-wlm and munge, writes /etc/slurm/slurm.conf for this one node (all its
# CPUs and memory, one default partition `main`, no accounting database: as a site without
# slurmdbd), creates a munge key, starts munged, slurmctld and slurmd (through systemd when it
# runs, else directly) and waits until `sinfo` shows the node idle. Idempotent: run it again after
# a reboot; a slurm.conf this script did not write is never replaced (it stops instead), and
# running daemons are left alone.
set -euo pipefail

CONF=/etc/slurm/slurm.conf
MARK="# written by triaxtrack .ci/slurm-single-node.sh"

if [ "$(id -u)" -ne 0 ]; then
  echo "slurm-single-node.sh: run as root (sudo $0)" >&2
  exit 1
fi

# ---------------------------------------------------------------- packages
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v munged >/dev/null \
  || ! command -v sinfo >/dev/null; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q
  apt-get install -y -q slurm-wlm munge
fi

# ---------------------------------------------------------------- slurm.conf
node=$(hostname -s)
cpus=$(nproc)
mem_mb=$(awk '/^MemTotal:/ {print int($2 / 1024)}' /proc/meminfo)
mem_mb=$((mem_mb > 1024 ? mem_mb - 512 : mem_mb))   # leave the daemons some room

if [ -f "$CONF" ] && ! grep -qF "$MARK" "$CONF"; then
  echo "slurm-single-node.sh: $CONF exists and was not written by this script; not touching it" >&2
  echo "  (move it away to let this script write a one-node configuration)" >&2
  exit 1
fi
mkdir -p /etc/slurm /var/lib/slurm/slurmctld /var/lib/slurm/slurmd /var/log/slurm
chown slurm:slurm /var/lib/slurm/slurmctld /var/log/slurm 2>/dev/null || true
new_conf=$(cat <<EOF
$MARK
# One node, one default partition, no accounting database (squeue is the only job status).
ClusterName=single
SlurmctldHost=${node}(127.0.0.1)
AuthType=auth/munge
SlurmUser=slurm
SlurmdUser=root
StateSaveLocation=/var/lib/slurm/slurmctld
SlurmdSpoolDir=/var/lib/slurm/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
# finished jobs stay visible to squeue this long (s): Snakemake's squeue status needs >= 120
MinJobAge=300
ReturnToService=2
NodeName=${node} NodeAddr=127.0.0.1 CPUs=${cpus} RealMemory=${mem_mb} State=UNKNOWN
PartitionName=main Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
)
changed=0
if [ ! -f "$CONF" ] || [ "$(cat "$CONF")" != "$new_conf" ]; then
  printf '%s\n' "$new_conf" > "$CONF"
  changed=1
fi

# ---------------------------------------------------------------- munge
if [ ! -s /etc/munge/munge.key ]; then
  if command -v mungekey >/dev/null; then
    mungekey --create --force
  else
    dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key status=none
  fi
fi
chown munge:munge /etc/munge/munge.key
chmod 400 /etc/munge/munge.key
mkdir -p /run/munge && chown munge:munge /run/munge

systemd_runs() { [ -d /run/systemd/system ]; }

start() {  # start SERVICE [COMMAND...]: unless its process runs already
  local service=$1
  shift
  if pgrep -x "$service" >/dev/null; then
    return 0
  fi
  if systemd_runs; then
    systemctl start "$service"
  else
    "$@"
  fi
}

start munged runuser -u munge -- /usr/sbin/munged
for _ in $(seq 20); do munge -n >/dev/null 2>&1 && break; sleep 0.5; done
munge -n | unmunge >/dev/null || { echo "slurm-single-node.sh: munge does not work" >&2; exit 1; }

if [ "$changed" = 1 ] && pgrep -x slurmctld >/dev/null; then
  scontrol reconfigure || true
fi
start slurmctld /usr/sbin/slurmctld
start slurmd /usr/sbin/slurmd

# ---------------------------------------------------------------- wait for the node
for _ in $(seq 60); do
  state=$(sinfo -h -n "$node" -o %t 2>/dev/null | head -1 || true)
  case "$state" in
    idle | mix | alloc) break ;;
    down* | drain* | drng*) scontrol update nodename="$node" state=resume 2>/dev/null || true ;;
  esac
  sleep 1
done
sinfo
case "$state" in
  idle | mix | alloc) ;;
  *)
    echo "slurm-single-node.sh: node $node is '$state', not idle; see /var/log/slurm/*.log" >&2
    exit 1
    ;;
esac
srun -N1 -n1 hostname
echo "slurm-single-node.sh: one-node SLURM cluster ready (partition main, node $node, $cpus CPUs, ${mem_mb} MB)"
