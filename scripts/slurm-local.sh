#!/usr/bin/env bash
# slurm-local.sh — bring up / tear down a throw-away single-node Slurm cluster
# on localhost, for CI tests.  Written for Debian 12 (bookworm), Slurm 22.05,
# MUNGE 0.5.15, run as root.
#
# Usage:
#   slurm-local.sh start  STATE_DIR   # install if needed, start munged+slurmctld+slurmd
#   slurm-local.sh stop   STATE_DIR   # cancel jobs, stop exactly the daemons we started
#   slurm-local.sh status STATE_DIR   # show our daemons and sinfo (exit 1 if not all up)
#   slurm-local.sh env    STATE_DIR   # print the "export SLURM_CONF=..." line
#
# `start` prints ONE line on stdout, `export SLURM_CONF=<STATE_DIR>/slurm.conf`,
# so a caller can do:   eval "$(slurm-local.sh start /tmp/slurm)"
# The same line is written to STATE_DIR/env (`. STATE_DIR/env`).
# Every progress / diagnostic message goes to stderr.
#
# Design (see NOTES.md for the reasons):
#   * Everything lives in STATE_DIR: slurm.conf, a *private* munge key, the munge
#     socket, pid files, logs, slurmctld state and slurmd spool.  Nothing is
#     written to /etc by this script.  (Debian's munge package itself creates
#     /etc/munge/munge.key at install time; we do not use or change it.)
#   * Our munged listens on STATE_DIR/munge/munge.socket.2 and Slurm is pointed
#     at it with AuthInfo=socket=... (honoured by auth/munge and cred/munge), so
#     it never collides with a system munged on /run/munge/munge.socket.2.
#   * The three daemons daemonise themselves and write their pid files into
#     STATE_DIR/run.  `stop` only signals pids read from those files, and only
#     after checking /proc/PID/cmdline still names that daemon *and* this
#     STATE_DIR (so a stale pid file whose pid was reused is never acted on).
#   * No cgroups: ProctrackType=proctrack/linuxproc, TaskPlugin=task/none,
#     JobAcctGatherType=jobacct_gather/none; no accounting.
#
# Tunables (environment):
#   SLURM_LOCAL_CTLD_PORT   slurmctld port          (default 6817)
#   SLURM_LOCAL_SLURMD_PORT slurmd port             (default 6818)
#   SLURM_LOCAL_CPUS        CPUs of the node        (default: nproc)
#   SLURM_LOCAL_MEM_MB      RealMemory of the node  (default 1000)
#   SLURM_LOCAL_TIMEOUT     seconds to wait for the node to become idle (default 60)
#   SLURM_LOCAL_SCHED_PARAMS SchedulerParameters (default batch_sched_delay=0)
#   SLURM_LOCAL_KEEP_STATE  1 = let slurmctld recover jobs from a previous run
#                           (default 0: start with a clean job state, slurmctld -c)

set -euo pipefail

# Daemons live in /usr/sbin, which is not on every PATH.
export PATH="${PATH}:/usr/local/sbin:/usr/sbin:/sbin"

PROG=${0##*/}
log() { printf '[%s %s] %s\n' "$PROG" "$(date +%T)" "$*" >&2; }
# die: report and exit 1.  During `start` (STARTING=1) it first dumps the
# daemons' logs and stops whatever this start already launched, so a failed
# start never leaks daemons (state and logs stay in STATE_DIR).
STARTING=0
die() {
    log "ERROR: $*"
    if (( STARTING )); then
        STARTING=0
        dump_logs
        log "stopping what this start launched (logs kept in ${STATE_DIR:-?})"
        do_stop quiet || true
        log "ERROR: $*"
    fi
    exit 1
}

usage() {
    sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//' >&2
    exit 2
}

# ---------------------------------------------------------------------------
# Paths inside STATE_DIR (set by init_paths)
# ---------------------------------------------------------------------------
init_paths() {
    local dir=$1
    mkdir -p "$dir"
    STATE_DIR=$(cd "$dir" && pwd -P)           # absolute, symlink-free
    CONF=$STATE_DIR/slurm.conf
    ENV_FILE=$STATE_DIR/env
    MUNGE_DIR=$STATE_DIR/munge
    MUNGE_KEY=$MUNGE_DIR/munge.key
    MUNGE_SOCKET=$MUNGE_DIR/munge.socket.2
    MUNGE_PID=$MUNGE_DIR/munged.pid
    MUNGE_LOG=$MUNGE_DIR/munged.log
    MUNGE_SEED=$MUNGE_DIR/munged.seed
    RUN_DIR=$STATE_DIR/run
    LOG_DIR=$STATE_DIR/log
    CTLD_PID=$RUN_DIR/slurmctld.pid
    SLURMD_PID=$RUN_DIR/slurmd.pid
    CTLD_LOG=$LOG_DIR/slurmctld.log
    SLURMD_LOG=$LOG_DIR/slurmd.log
    CTLD_STATE=$STATE_DIR/spool/slurmctld
    SLURMD_SPOOL=$STATE_DIR/spool/slurmd
    NODE=$(hostname -s)
    export SLURM_CONF=$CONF                    # for every client command below
}

# ---------------------------------------------------------------------------
# Process helpers
# ---------------------------------------------------------------------------

# alive PID: true if PID exists and is not a zombie.  (A daemonised process is
# re-parented to PID 1; if PID 1 is not a real init it may never be reaped, so
# `kill -0` alone would report a dead daemon as alive.)
alive() {
    local pid=$1 state
    [[ -r /proc/$pid/stat ]] || return 1
    state=$(sed -E 's/^[0-9]+ \(.*\) ([A-Za-z]).*/\1/' "/proc/$pid/stat" 2>/dev/null) || return 1
    [[ -n $state && $state != Z && $state != X ]]
}

# our_pid PIDFILE BINARY MARKER: print the pid recorded in PIDFILE if that
# process is alive, runs BINARY and has MARKER (a path inside STATE_DIR) in its
# command line; otherwise print nothing.  Never trusts a bare pid.
our_pid() {
    local pidfile=$1 binary=$2 marker=$3 pid cmdline argv0
    [[ -s $pidfile ]] || return 0
    pid=$(tr -dc '0-9' < "$pidfile")
    [[ -n $pid ]] || return 0
    alive "$pid" || return 0
    cmdline=$(tr '\0' '\n' 2>/dev/null < "/proc/$pid/cmdline") || return 0
    argv0=${cmdline%%$'\n'*}
    [[ ${argv0##*/} == "$binary" && $cmdline == *"$marker"* ]] && echo "$pid"
    return 0
}

ctld_pid()   { our_pid "$CTLD_PID"   slurmctld "$CONF"; }
slurmd_pid() { our_pid "$SLURMD_PID" slurmd    "$CONF"; }
munged_pid() { our_pid "$MUNGE_PID"  munged    "$MUNGE_SOCKET"; }

# wait_gone PID SECONDS: wait until PID has exited; 1 on timeout.
wait_gone() {
    local pid=$1 t=$(( $2 * 10 ))
    while alive "$pid"; do
        (( t-- > 0 )) || return 1
        sleep 0.1
    done
}

# kill_daemon NAME PID: SIGTERM, wait up to 20 s, then SIGKILL.
kill_daemon() {
    local name=$1 pid=$2
    [[ -n $pid ]] || return 0
    log "stopping $name (pid $pid)"
    kill -TERM "$pid" 2>/dev/null || true
    if ! wait_gone "$pid" 20; then
        log "$name (pid $pid) ignored SIGTERM for 20 s, sending SIGKILL"
        kill -KILL "$pid" 2>/dev/null || true
        wait_gone "$pid" 10 || die "$name (pid $pid) did not exit"
    fi
}

# stepd_pids: slurmstepd processes belonging to *our* slurmd.  They are
# detached from slurmd, so they are found through the unix sockets they listen
# on in our SlurmdSpoolDir (/proc/net/unix gives the inode, /proc/PID/fd the
# owner).
stepd_pids() {
    [[ -d $SLURMD_SPOOL && -r /proc/net/unix ]] || return 0
    local inodes fd link pid
    inodes=$(awk -v d="$SLURMD_SPOOL/" 'index($8, d) == 1 { print $7 }' /proc/net/unix | sort -u)
    [[ -n $inodes ]] || return 0
    for fd in /proc/[0-9]*/fd/*; do
        link=$(readlink "$fd" 2>/dev/null) || continue
        [[ $link == socket:\[*\] ]] || continue
        link=${link#socket:[}; link=${link%]}
        if grep -qx "$link" <<<"$inodes"; then
            pid=${fd#/proc/}; echo "${pid%%/*}"
        fi
    done | sort -u
}

# proc_table: "PID PPID CMDLINE" for every process, read straight from /proc
# (procps is not guaranteed on minimal images).
proc_table() {
    local d stat ppid cmd
    for d in /proc/[0-9]*; do
        # (`read`, not `$(<file)`: under set -e, bash 5.2 exits silently when
        # `$(<file)` cannot open a file, e.g. of a process that just exited.)
        read -r stat 2>/dev/null < "$d/stat" || continue
        read -r _ ppid _ <<<"${stat##*) }"       # fields after "(comm) ": state ppid ...
        cmd=$(tr '\0' ' ' 2>/dev/null < "$d/cmdline") || continue
        echo "${d#/proc/} $ppid $cmd"
    done
}

# job_pids: every process of a job run by *our* slurmd: our slurmstepds, the
# batch scripts (their command line is $SLURMD_SPOOL/jobNNNNN/slurm_script, so
# they are recognisable even when their slurmstepd is already gone), and all
# descendants of those.  Used by `stop` so that no job process outlives the
# cluster, e.g. after slurmctld/slurmd crashed and could not cancel the jobs.
job_pids() {
    local roots table
    roots=$(stepd_pids)
    table=$(proc_table)
    # Breadth-first walk of the process tree from the roots.
    awk -v roots="$roots" -v spool="$SLURMD_SPOOL/job" '
        BEGIN { n = split(roots, r, "\n"); for (i = 1; i <= n; i++) if (r[i] != "") keep[r[i]] = 1 }
        { parent[$1] = $2 }
        index($0, spool) && index($0, "/slurm_script") { keep[$1] = 1 }
        END {
            do {
                changed = 0
                for (p in parent) if (!(p in keep) && (parent[p] in keep)) { keep[p] = 1; changed = 1 }
            } while (changed)
            for (p in keep) print p
        }' <<<"$table" | sort -n
}

dump_logs() {
    local f
    for f in "$MUNGE_LOG" "$CTLD_LOG" "$SLURMD_LOG" "$LOG_DIR"/*.stderr; do
        [[ -s $f ]] || continue
        printf '\n===== %s (last 40 lines) =====\n' "$f" >&2
        tail -n 40 "$f" >&2
    done
}

# ---------------------------------------------------------------------------
# Install
# ---------------------------------------------------------------------------
ensure_installed() {
    local missing=() b
    for b in slurmctld slurmd munged sbatch; do
        command -v "$b" >/dev/null 2>&1 || missing+=("$b")
    done
    if (( ${#missing[@]} == 0 )); then
        return 0
    fi
    local apt_log=$LOG_DIR/apt-get.log
    mkdir -p "$LOG_DIR"
    log "missing: ${missing[*]} -> apt-get install slurm-wlm munge (output: $apt_log)"
    export DEBIAN_FRONTEND=noninteractive
    if ! { apt-get update -qq && apt-get install -y -qq slurm-wlm munge; } >"$apt_log" 2>&1; then
        tail -n 30 "$apt_log" >&2
        die "apt-get failed (full output in $apt_log)"
    fi
    for b in slurmctld slurmd munged sbatch; do
        command -v "$b" >/dev/null 2>&1 || die "$b still missing after apt-get install"
    done
}

# ---------------------------------------------------------------------------
# Configuration
# ---------------------------------------------------------------------------
write_config() {
    local cpus=${SLURM_LOCAL_CPUS:-$(nproc)}
    local mem=${SLURM_LOCAL_MEM_MB:-1000}
    local ctld_port=${SLURM_LOCAL_CTLD_PORT:-6817}
    local slurmd_port=${SLURM_LOCAL_SLURMD_PORT:-6818}

    local out=${1:-$CONF}
    # Addresses are given explicitly (127.0.0.1) so nothing depends on how
    # `hostname -s` resolves; the *names* must still equal `hostname -s`,
    # because that is how slurmctld/slurmd recognise "their" entry.
    cat > "$out.tmp" <<EOF
# Generated by $PROG -- single-node CI cluster.  Do not edit: regenerated
# on every start (a start whose config differs restarts the daemons).
ClusterName=localci
SlurmctldHost=${NODE}(127.0.0.1)
SlurmctldPort=${ctld_port}
SlurmdPort=${slurmd_port}
SlurmUser=root
SlurmdUser=root

# Authentication through our private munged (see munge/ in this directory).
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=${MUNGE_SOCKET}

# Everything stateful lives in STATE_DIR.
StateSaveLocation=${CTLD_STATE}
SlurmdSpoolDir=${SLURMD_SPOOL}
SlurmctldPidFile=${CTLD_PID}
SlurmdPidFile=${SLURMD_PID}
SlurmctldLogFile=${CTLD_LOG}
SlurmdLogFile=${SLURMD_LOG}
SlurmctldDebug=info
SlurmdDebug=info

# No cgroups anywhere.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none

SwitchType=switch/none
MpiDefault=none
SchedulerType=sched/backfill
# batch_sched_delay defaults to 3 s: with it, a job that becomes runnable
# (array task slot freed, dependency satisfied) waits up to 3 s.  0 gives
# ~1 s turnaround (the slurmctld background loop ticks once per second).
SchedulerParameters=${SLURM_LOCAL_SCHED_PARAMS:-batch_sched_delay=0}
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MailProg=/bin/true
# Short grace period between SIGTERM and SIGKILL when a job is cancelled.
KillWait=5
# Keep finished jobs visible to squeue/scontrol for 5 min (default).
MinJobAge=300

NodeName=${NODE} NodeHostname=${NODE} NodeAddr=127.0.0.1 CPUs=${cpus} RealMemory=${mem} State=UNKNOWN
PartitionName=debug Nodes=${NODE} Default=YES MaxTime=INFINITE State=UP
EOF
    mv -f "$out.tmp" "$out"
    printf 'export SLURM_CONF=%q\n' "$CONF" > "$ENV_FILE"
}

# ---------------------------------------------------------------------------
# munge
# ---------------------------------------------------------------------------
start_munged() {
    # munged refuses insecure permissions: the key must be owned by the user
    # munged runs as (root here) and not be group/other accessible, and the
    # directories holding key/socket must not be writable by others.
    # The directory is 0755 (munged warns otherwise that non-root clients
    # cannot reach the socket); the key inside is 0400 root.
    mkdir -p "$MUNGE_DIR"
    chown root:root "$MUNGE_DIR"
    chmod 0755 "$MUNGE_DIR"
    if [[ ! -s $MUNGE_KEY ]]; then
        log "creating munge key $MUNGE_KEY"
        if command -v mungekey >/dev/null 2>&1; then
            mungekey --create --keyfile="$MUNGE_KEY" --force
        else
            dd if=/dev/urandom of="$MUNGE_KEY" bs=1024 count=1 status=none
        fi
    fi
    chown root:root "$MUNGE_KEY"
    chmod 0400 "$MUNGE_KEY"
    # A stale socket/lock from a crashed run would make munged refuse to start.
    rm -f "$MUNGE_SOCKET" "$MUNGE_SOCKET.lock" "$MUNGE_PID"

    # --force: tolerate group/world-writable parent directories of STATE_DIR
    #          (e.g. a CI workspace); the key itself is still 0400 root.
    # --origin: do not depend on `hostname` resolving to an IPv4 address.
    munged --force \
        --socket="$MUNGE_SOCKET" \
        --key-file="$MUNGE_KEY" \
        --pid-file="$MUNGE_PID" \
        --log-file="$MUNGE_LOG" \
        --seed-file="$MUNGE_SEED" \
        --origin=127.0.0.1 \
        </dev/null >/dev/null 2>>"$LOG_DIR/munged.stderr" 9>&- \
        || die "munged failed to start"

    local pid="" t=100
    while [[ -z $pid ]] && (( t-- > 0 )); do pid=$(munged_pid); [[ -n $pid ]] || sleep 0.1; done
    [[ -n $pid ]] || die "munged did not write $MUNGE_PID"
    # Round-trip a credential through our socket to prove it works.
    munge --socket="$MUNGE_SOCKET" -n </dev/null | unmunge --socket="$MUNGE_SOCKET" >/dev/null \
        || die "munge/unmunge round trip failed on $MUNGE_SOCKET"
    log "munged up (pid $pid)"
}

# ---------------------------------------------------------------------------
# start / stop / status
# ---------------------------------------------------------------------------
node_state() {
    sinfo -h -N -n "$NODE" -o '%T' 2>/dev/null | head -n 1 || true
}

all_up() {
    [[ -n $(munged_pid) && -n $(ctld_pid) && -n $(slurmd_pid) ]] \
        && [[ $(node_state) == idle || $(node_state) == mixed || $(node_state) == allocated ]]
}

# wait_pidfile NAME FUNC LOGFILE: wait (10 s) for a daemonised process to
# record its pid; give up at once if its log already shows a fatal error.
wait_pidfile() {
    local name=$1 fn=$2 logfile=$3 pid="" t=100
    while (( t-- > 0 )); do
        pid=$($fn)
        [[ -n $pid ]] && { log "$name up (pid $pid)"; return 0; }
        if grep -q 'fatal:' "$logfile" 2>/dev/null; then
            die "$name failed: $(grep 'fatal:' "$logfile" | tail -n 1)"
        fi
        sleep 0.1
    done
    die "$name did not start (no live pid in its pid file)"
}

# port_free PORT: true if nothing accepts TCP connections on 127.0.0.1:PORT.
port_free() {
    ! (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null
}

cmd_start() {
    [[ $EUID -eq 0 ]] || die "must run as root (SlurmUser=root, apt-get, munged)"
    local t0=$SECONDS
    ensure_installed

    # Already running with an identical configuration?  Then do nothing.
    if [[ -f $CONF ]] && all_up; then
        write_config "$CONF.candidate"
        if cmp -s "$CONF" "$CONF.candidate"; then
            rm -f "$CONF.candidate"
            log "cluster in $STATE_DIR already running; nothing to do"
            cat "$ENV_FILE"
            return 0
        fi
        rm -f "$CONF.candidate"
        log "configuration changed: restarting the cluster"
    fi

    # Leftovers of a crashed/partial previous run: stop whatever of *ours* is
    # still alive, then drop stale pid files.
    do_stop quiet
    rm -f "$CTLD_PID" "$SLURMD_PID" "$MUNGE_PID"

    # Someone else (a system slurmctld, another STATE_DIR) on our ports?
    local port
    for port in "${SLURM_LOCAL_CTLD_PORT:-6817}" "${SLURM_LOCAL_SLURMD_PORT:-6818}"; do
        port_free "$port" || die "TCP port $port on 127.0.0.1 is already in use" \
            "(another Slurm?); choose others with SLURM_LOCAL_CTLD_PORT / SLURM_LOCAL_SLURMD_PORT"
    done

    # Fresh logs for this run (the previous run's are kept as *.prev), so
    # that the error checks below only see messages of this start.
    local f
    for f in "$CTLD_LOG" "$SLURMD_LOG" "$MUNGE_LOG" "$LOG_DIR"/*.stderr; do
        [[ -f $f ]] && mv -f "$f" "$f.prev"
    done

    STARTING=1

    mkdir -p "$RUN_DIR" "$LOG_DIR" "$CTLD_STATE" "$SLURMD_SPOOL"
    write_config
    start_munged

    # Fresh job state unless asked otherwise (a crashed run's jobs would be
    # recovered and could confuse a test).
    local ctld_args=(-f "$CONF")
    [[ ${SLURM_LOCAL_KEEP_STATE:-0} == 1 ]] || ctld_args+=(-c)

    # Both daemons fork into the background themselves and write their pid
    # files (SlurmctldPidFile/SlurmdPidFile, inside STATE_DIR).  Their early
    # stderr (before the log file is open) is kept in log/*.stderr.
    slurmctld "${ctld_args[@]}" </dev/null >/dev/null 2>>"$LOG_DIR/slurmctld.stderr" 9>&- \
        || die "slurmctld exited with an error"
    wait_pidfile slurmctld ctld_pid "$CTLD_LOG"
    slurmd -f "$CONF" </dev/null >/dev/null 2>>"$LOG_DIR/slurmd.stderr" 9>&- \
        || die "slurmd exited with an error"
    wait_pidfile slurmd slurmd_pid "$SLURMD_LOG"

    # Bounded wait for the node to register and become idle.
    local timeout=${SLURM_LOCAL_TIMEOUT:-60} deadline state=""
    deadline=$(( SECONDS + timeout ))
    while (( SECONDS < deadline )); do
        state=$(node_state)
        [[ $state == idle ]] && break
        [[ -n $(ctld_pid) ]]   || die "slurmctld died during start-up"
        [[ -n $(slurmd_pid) ]] || die "slurmd died during start-up"
        sleep 0.5
    done
    if [[ $state != idle ]]; then
        log "node $NODE not idle after ${timeout}s (state: '${state:-unknown}')"
        sinfo -N -l >&2 || true
        scontrol show node "$NODE" >&2 || true
        die "cluster did not come up (node $NODE not idle after ${timeout}s)"
    fi
    STARTING=0
    log "cluster up in $(( SECONDS - t0 ))s: node $NODE idle, partition debug, SLURM_CONF=$CONF"
    cat "$ENV_FILE"
}

# do_stop [quiet]: cancel our jobs, then stop slurmd, slurmctld, munged.
do_stop() {
    local quiet=${1:-} p

    # 1. Cancel every job while slurmctld is still up, so that no job
    #    processes (slurmstepd + user processes) outlive the cluster.
    if [[ -n $(ctld_pid) && -f $CONF ]]; then
        if [[ -n $(squeue -h -o %i 2>/dev/null || true) ]]; then
            log "cancelling remaining jobs"
            scancel --full --partition=debug 2>/dev/null || true
            scancel --partition=debug 2>/dev/null || true
            local t=30
            while (( t-- > 0 )) && [[ -n $(squeue -h -t RUNNING,COMPLETING -o %i 2>/dev/null || true) ]]; do
                sleep 1
            done
        fi
    fi
    # 2. Job processes of ours still around (slurmctld was dead, or a job
    #    ignored the cancel)?  SIGKILL the whole set at once, so no child is
    #    orphaned before it is signalled.
    local leftovers
    leftovers=$(job_pids | tr '\n' ' ')
    if [[ -n ${leftovers// /} ]]; then
        log "killing leftover job processes: $leftovers"
        # shellcheck disable=SC2086
        kill -KILL $leftovers 2>/dev/null || true
        for p in $leftovers; do wait_gone "$p" 10 || log "pid $p did not exit"; done
    fi

    # 3. Daemons, in dependency order (munged last: Slurm needs it to shut down).
    kill_daemon slurmd    "$(slurmd_pid)"
    kill_daemon slurmctld "$(ctld_pid)"
    kill_daemon munged    "$(munged_pid)"
    rm -f "$CTLD_PID" "$SLURMD_PID" "$MUNGE_PID" "$MUNGE_SOCKET" "$MUNGE_SOCKET.lock"
    [[ $quiet == quiet ]] || log "stopped; state/logs kept in $STATE_DIR"
}

cmd_stop() {
    [[ -d $STATE_DIR ]] || { log "no $STATE_DIR, nothing to stop"; return 0; }
    do_stop
}

cmd_status() {
    local rc=0 p
    p=$(munged_pid);   log "munged:    ${p:-not running}";    [[ -n $p ]] || rc=1
    p=$(ctld_pid);     log "slurmctld: ${p:-not running}";    [[ -n $p ]] || rc=1
    p=$(slurmd_pid);   log "slurmd:    ${p:-not running}";    [[ -n $p ]] || rc=1
    if (( rc == 0 )); then sinfo -N >&2 || rc=1; fi
    return $rc
}

# ---------------------------------------------------------------------------
main() {
    (( $# == 2 )) || usage
    local cmd=$1
    case $cmd in start|stop|status|env) ;; *) usage ;; esac
    if [[ $cmd != start && ! -d $2 ]]; then
        log "$2 does not exist; nothing to $cmd"
        [[ $cmd == stop ]] && return 0 || return 1
    fi
    # slurm.conf cannot quote paths: refuse whitespace in STATE_DIR.
    [[ $2 != *[[:space:]]* ]] || die "STATE_DIR must not contain whitespace: '$2'"
    init_paths "$2"

    # Serialise start/stop on the same STATE_DIR.  (fd 9 is closed for every
    # daemon we launch, otherwise they would inherit and hold the lock.)
    exec 9>"$STATE_DIR/.lock"
    flock -w 120 9 || die "another $PROG holds $STATE_DIR/.lock"

    case $cmd in
        start)  cmd_start ;;
        stop)   cmd_stop ;;
        status) cmd_status ;;
        env)    [[ -f $ENV_FILE ]] || die "no $ENV_FILE (run start first)"; cat "$ENV_FILE" ;;
    esac
}

main "$@"
