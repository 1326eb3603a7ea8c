#!/usr/bin/env bash
# A one-node SLURM cluster on this machine, for the live executor test (tests/cluster/test_slurm_live.py) and by hand.
#
#   tests/cluster/slurm.sh start DIR   install SLURM + munge from the distribution if missing (root + apt-get),
#                                      write DIR/slurm.conf for this host, start munged, slurmctld and slurmd,
#                                      wait until the node is idle; prints `export SLURM_CONF=DIR/slurm.conf`
#   tests/cluster/slurm.sh stop DIR    stop the slurmd and slurmctld started for DIR (munged is left running
#                                      when it was running before `start`)
#
# Everything SLURM writes (state, spool, logs, the job-completion record) stays under DIR. Clients find the cluster
# through SLURM_CONF, and /etc/slurm/slurm.conf links to DIR/slurm.conf while the cluster runs: the executor's
# job step (snakemake-executor-plugin-slurm-jobstep 0.6.1) drops SLURM_CONF before its inner `srun`, which then
# reads the default path. An existing /etc/slurm/slurm.conf (a real cluster) is never replaced: start refuses.
# Ports 16817/16818 on the loopback address only.
# No accounting database: jobs are recorded by jobcomp/filetxt (DIR/jobcomp.log), and Snakemake's SLURM executor
# polls with squeue (MinJobAge=600 keeps finished jobs visible), so slurmdbd and MariaDB are not needed.
set -euo pipefail

usage() { echo "usage: $0 start|stop DIR" >&2; exit 2; }
[[ $# -eq 2 ]] || usage
cmd=$1
mkdir -p "$2"
dir=$(cd "$2" && pwd)
conf=$dir/slurm.conf
export SLURM_CONF=$conf
etc_conf=/etc/slurm/slurm.conf

log() { echo "slurm.sh: $*" >&2; }

install_packages() {
    local missing=()
    for tool in sbatch squeue sinfo scontrol slurmctld slurmd munged munge unmunge; do
        command -v "$tool" >/dev/null 2>&1 || PATH=$PATH:/usr/sbin command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
    done
    [[ ${#missing[@]} -eq 0 ]] && return 0
    if [[ $(id -u) -ne 0 ]] || ! command -v apt-get >/dev/null; then
        log "missing ${missing[*]}: install slurmctld slurmd slurm-client munge (Debian/Ubuntu) as root"
        exit 1
    fi
    log "installing slurmctld slurmd slurm-client munge (missing: ${missing[*]})"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge >"$dir/apt.log" 2>&1 ||
        { tail -20 "$dir/apt.log" >&2; exit 1; }
}

start_munge() {
    if munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
        log "munged already running"
        return 0
    fi
    if [[ ! -s /etc/munge/munge.key ]]; then
        runuser -u munge -- mungekey --create --keyfile=/etc/munge/munge.key
    fi
    install -d -o munge -g munge -m 0755 /run/munge
    runuser -u munge -- /usr/sbin/munged
    touch "$dir/munged.started-here"
    for _ in $(seq 50); do
        munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && return 0
        sleep 0.1
    done
    log "munged did not answer"; exit 1
}

write_config() {
    local node host
    host=$(hostname -s)
    # slurmd -C prints this machine's NodeName/CPUs/sockets/cores/threads/RealMemory line.
    node=$(PATH=$PATH:/usr/sbin slurmd -C | head -1)
    [[ $node == NodeName=* ]] || { log "slurmd -C gave: $node"; exit 1; }
    mkdir -p "$dir/state" "$dir/spool/slurmd-$host" "$dir/log"
    # A stand-in GPU: slurmd drops a GPU without a device file, so /dev/null is that file. The scheduler then
    # places `--gpus=1` jobs (the profile's GPU requests go through the real path); the job itself finds no
    # CUDA device and runs on the CPU. Test-only: a real cluster's gres.conf names /dev/nvidia*.
    cat >"$dir/gres.conf" <<EOF
NodeName=$host Name=gpu File=/dev/null
EOF
    cat >"$conf" <<EOF
# One-node test cluster written by tests/cluster/slurm.sh
ClusterName=eigs
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=16817
SlurmdPort=16818
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool/slurmd-%n
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
# Containers have no cgroup delegation: track processes by /proc, bind no tasks.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
GresTypes=gpu
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$dir/jobcomp.log
# Finished jobs stay in slurmctld's memory (squeue --states=all) for 10 minutes.
MinJobAge=600
ReturnToService=2
SlurmctldTimeout=30
SlurmdTimeout=30
MpiDefault=none
$node NodeAddr=127.0.0.1 Gres=gpu:1 State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
}

wait_idle() {
    local state="" deadline=$((SECONDS + 60))
    while ((SECONDS < deadline)); do
        for d in slurmctld slurmd; do
            # A daemon writes its pid file once it has forked; a pid file whose process is gone means it died.
            if [[ -s $dir/$d.pid ]] && ! kill -0 "$(cat "$dir/$d.pid")" 2>/dev/null; then
                log "$d is not running; last lines of its log:"
                tail -n 5 "$dir/log/$d.log" >&2 || true
                exit 1
            fi
        done
        state=$(timeout 5 sinfo -h -o %T 2>/dev/null | head -1 || true)
        [[ $state == idle ]] && return 0
        sleep 0.5
    done
    log "node not idle after 60 s (state: ${state:-none}); last log lines:"
    tail -n 5 "$dir/log/slurmctld.log" "$dir/log/slurmd.log" >&2 || true
    exit 1
}

stop_pid() {
    local file=$1 pid
    [[ -s $file ]] || return 0
    pid=$(cat "$file")
    if kill -0 "$pid" 2>/dev/null; then
        kill "$pid"
        for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
        # A slurmd still retrying to register ignores SIGTERM for a while.
        kill -0 "$pid" 2>/dev/null && kill -9 "$pid" 2>/dev/null || true
    fi
    rm -f "$file"
}

case $cmd in
start)
    install_packages
    export PATH=$PATH:/usr/sbin
    if [[ -e $etc_conf || -L $etc_conf ]] && [[ $(readlink "$etc_conf" || true) != "$conf" ]]; then
        log "$etc_conf exists and is not this test cluster's: not starting (run this on a machine without SLURM)"
        exit 1
    fi
    start_munge
    write_config
    mkdir -p /etc/slurm
    ln -sfn "$conf" "$etc_conf"
    rm -f "$dir/slurmctld.pid" "$dir/slurmd.pid"
    # -c: start from a clean state (no jobs left from an earlier cluster in DIR); -i: ignore state errors.
    slurmctld -c -i
    slurmd -N "$(hostname -s)"
    wait_idle
    echo "export SLURM_CONF=$conf"
    ;;
stop)
    export PATH=$PATH:/usr/sbin
    stop_pid "$dir/slurmd.pid"
    stop_pid "$dir/slurmctld.pid"
    [[ $(readlink "$etc_conf" || true) == "$conf" ]] && rm -f "$etc_conf"
    if [[ -e $dir/munged.started-here ]]; then
        pid=$(cat /run/munge/munged.pid 2>/dev/null || true)
        [[ -n $pid ]] && kill "$pid" 2>/dev/null || true
        rm -f "$dir/munged.started-here"
    fi
    ;;
*) usage ;;
esac
