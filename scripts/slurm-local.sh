#!/usr/bin/env bash
# A single-node SLURM on localhost from Debian's packages, for the SLURM tests and `make bench`:
#
#   scripts/slurm-local.sh up       # munged, slurmctld, slurmd; waits until the node is idle
#   scripts/slurm-local.sh down     # stops the daemons this script started, nothing else
#   scripts/slurm-local.sh status   # exit 0 when the local SLURM answers
#   scripts/slurm-local.sh conf     # print its slurm.conf (for SLURM_CONF)
#   scripts/slurm-local.sh install  # apt-get install munge slurmctld slurmd slurm-client
#
# Everything lives under $BREVE_SLURM_DIR: its own munge key and socket, slurm.conf, spool,
# state, logs and pid files; no accounting. The default folder is one per checkout,
# /tmp/breve-slurm-<8 hex digits of the checkout's path>, so that `make slurm-up`, the tests
# and `make slurm-down` of one checkout find the same cluster and another checkout's runs
# never stop it; `.ci/run` and the tests' own cluster use a fresh folder per run (mktemp).
# Each cluster has its own pair of ports (slurmctld, slurmd), chosen free at `up` from
# 20000-31999 by a hash of the folder (BREVE_SLURM_CTLD_PORT, BREVE_SLURM_SLURMD_PORT override),
# and kept in its slurm.conf while it runs. `up` is idempotent: a daemon whose pid file names
# a live process is left running. /etc/slurm/slurm.conf is a symlink to our slurm.conf only
# if no other slurm.conf was there (so that sbatch, squeue and dask-jobqueue find the first
# cluster without SLURM_CONF); with several clusters up, set SLURM_CONF=$(... conf) (the
# tests do); `down` removes only that symlink.
#
# Settings that a single node without systemd needs (docs/sweeps.md): proctrack/linuxproc and
# task/none (no cgroups), RealMemory from /proc/meminfo (so that `--mem` is accepted), the node
# name from `hostname -s`, KillWait=5 (a job at its walltime is SIGKILLed 5 s after SIGTERM).
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd -P)
DIR=${BREVE_SLURM_DIR:-/tmp/breve-slurm-$(printf %s "$ROOT" | sha1sum | cut -c1-8)}
CONF=$DIR/slurm.conf
SOCK=$DIR/munge/munge.socket.2
ETC_CONF=/etc/slurm/slurm.conf
PACKAGES="munge slurmctld slurmd slurm-client"

say() { echo "slurm-local: $*" >&2; }

alive() {  # alive PIDFILE: the pid file names a running process
    [ -s "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null
}

have_packages() {
    command -v munged >/dev/null && command -v slurmctld >/dev/null \
        && command -v slurmd >/dev/null && command -v sbatch >/dev/null
}

install_packages() {
    if have_packages; then say "packages present"; return 0; fi
    if [ "$(id -u)" -ne 0 ]; then say "not root: cannot apt-get install $PACKAGES"; return 1; fi
    say "apt-get install $PACKAGES"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $PACKAGES >/dev/null
}

listening() {  # listening PORT: something accepts TCP connections on it (bash's /dev/tcp)
    (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null
}

conf_port() {  # conf_port KEY: the port of our slurm.conf (a cluster that is up keeps its own)
    sed -n "s/^$1=//p" "$CONF" 2>/dev/null | head -1
}

pick_ports() {  # sets CTLD_PORT and SLURMD_PORT: free, from a hash of $DIR, 2 apart per try
    local base i
    if [ -n "${BREVE_SLURM_CTLD_PORT:-}" ] || [ -n "${BREVE_SLURM_SLURMD_PORT:-}" ]; then
        CTLD_PORT=${BREVE_SLURM_CTLD_PORT:-6817}; SLURMD_PORT=${BREVE_SLURM_SLURMD_PORT:-6818}
        return 0
    fi
    # 20000-31999: below Linux's ephemeral ports (32768-60999), which outgoing connections take
    base=$(( 2 * ($(printf %s "$DIR" | cksum | cut -d' ' -f1) % 6000) ))
    for i in $(seq 0 49); do
        CTLD_PORT=$(( 20000 + (base + 2 * i) % 12000 )); SLURMD_PORT=$((CTLD_PORT + 1))
        if ! listening "$CTLD_PORT" && ! listening "$SLURMD_PORT"; then return 0; fi
    done
    say "no free pair of ports found from $((20000 + base))"; return 1
}

write_conf() {
    local host cpus mem
    host=$(hostname -s)
    # the cores this process may use, whatever OMP_NUM_THREADS says: GNU nproc obeys it, and a
    # test process that ran a Dask nanny has it set to 1 (a one-CPU node ran one job at a time)
    cpus=$(env -u OMP_NUM_THREADS -u OMP_THREAD_LIMIT nproc)
    # MiB, less 10 % for the system: a job's --mem up to this is accepted
    mem=$(awk '/^MemTotal:/ {printf "%d", $2 / 1024 * 0.9}' /proc/meminfo)
    cat >"$CONF.tmp" <<EOF
# Written by scripts/slurm-local.sh: a single-node SLURM on localhost for tests and benches.
ClusterName=breve
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$SOCK
CredType=cred/munge
StateSaveLocation=$DIR/ctld
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd.pid
SlurmctldLogFile=$DIR/slurmctld.log
SlurmdLogFile=$DIR/slurmd.log
# no systemd, no cgroups in a container
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
# walltime: SIGTERM at the limit, SIGKILL KillWait s later; no grace beyond the limit
KillWait=5
OverTimeLimit=0
InactiveLimit=0
MinJobAge=300
SlurmctldTimeout=30
SlurmdTimeout=30
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
    mv "$CONF.tmp" "$CONF"
}

start_munge() {
    if alive "$DIR/munged.pid"; then return 0; fi
    mkdir -p "$DIR/munge"
    chmod 700 "$DIR/munge"
    if [ ! -s "$DIR/munge/munge.key" ]; then
        dd if=/dev/urandom of="$DIR/munge/munge.key" bs=1024 count=1 status=none
        chmod 400 "$DIR/munge/munge.key"
    fi
    # --force: the state folder may sit under /tmp (world-writable, sticky)
    munged --force --socket="$SOCK" --key-file="$DIR/munge/munge.key" \
        --pid-file="$DIR/munged.pid" --log-file="$DIR/munged.log" \
        --seed-file="$DIR/munge/munged.seed"
}

up() {
    if ! have_packages; then
        say "munge/slurm packages missing: run '$0 install' (root, apt-get)"; return 1
    fi
    mkdir -p "$DIR/ctld" "$DIR/spool"
    chmod 755 "$DIR"
    if alive "$DIR/slurmctld.pid" || alive "$DIR/slurmd.pid"; then
        # running: its slurm.conf, ports included, stays as it is
        CTLD_PORT=$(conf_port SlurmctldPort); SLURMD_PORT=$(conf_port SlurmdPort)
    else
        pick_ports
        write_conf
    fi
    if [ ! -e "$ETC_CONF" ] && [ ! -L "$ETC_CONF" ]; then
        mkdir -p "$(dirname "$ETC_CONF")"
        ln -s "$CONF" "$ETC_CONF"
    elif [ "$(readlink "$ETC_CONF" 2>/dev/null)" != "$CONF" ]; then
        say "$ETC_CONF is not ours: use SLURM_CONF=$CONF"
    fi
    export SLURM_CONF=$CONF
    start_munge
    if ! alive "$DIR/slurmctld.pid"; then
        slurmctld -f "$CONF"
    fi
    if ! alive "$DIR/slurmd.pid"; then
        slurmd -f "$CONF"
    fi
    local i state=""
    for i in $(seq 1 60); do
        state=$(sinfo -h -N -o '%t' 2>/dev/null | head -1 || true)
        case "$state" in
            idle|mix|alloc) say "up: node $(hostname -s) $state, ports $CTLD_PORT/$SLURMD_PORT" \
                                    "(SLURM_CONF=$CONF)"; return 0 ;;
            drain*|down*) scontrol update nodename="$(hostname -s)" state=resume 2>/dev/null || true ;;
        esac
        sleep 1
    done
    say "node not idle after 60 s (state '${state}'); see $DIR/slurmctld.log, $DIR/slurmd.log"
    return 1
}

stop_pid() {  # stop_pid NAME: TERM the pid of our pid file, KILL after 10 s
    local f=$DIR/$1.pid pid i
    alive "$f" || { rm -f "$f"; return 0; }
    pid=$(cat "$f")
    kill -TERM "$pid" 2>/dev/null || true
    for i in $(seq 1 20); do kill -0 "$pid" 2>/dev/null || break; sleep 0.5; done
    kill -KILL "$pid" 2>/dev/null || true
    rm -f "$f"
}

down() {
    if alive "$DIR/slurmctld.pid"; then
        # no job outlives the cluster that ran it
        SLURM_CONF=$CONF scancel --full --quiet --user="$(id -un)" 2>/dev/null || true
    fi
    stop_pid slurmd
    stop_pid slurmctld
    stop_pid munged
    if [ "$(readlink "$ETC_CONF" 2>/dev/null)" = "$CONF" ]; then rm -f "$ETC_CONF"; fi
    say "down"
}

status() {
    alive "$DIR/slurmctld.pid" && alive "$DIR/slurmd.pid" \
        && SLURM_CONF=$CONF sinfo -h -N -o '%N %t %c %m' 2>/dev/null
}

case "${1:-}" in
    up) up ;;
    down) down ;;
    status) status ;;
    conf) echo "$CONF" ;;
    install) install_packages ;;
    *) echo "usage: $0 up|down|status|conf|install" >&2; exit 2 ;;
esac
