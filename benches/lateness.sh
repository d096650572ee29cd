#!/usr/bin/env bash
# Wake lateness of frictiond's RT loop next to cyclictest, like for like, on the same machine.
#
#   bash benches/lateness.sh [SECONDS]        (or env LATENESS_SECONDS; default 60)
#
# Both measurements run under the SAME conditions, interleaved in LATENESS_CHUNKS (3) chunks each
# (frictiond, cyclictest, frictiond, …; SECONDS in total each, so load drift hits both alike), and
# both quantile sets come from the merged 1 µs histograms computed by one awk function:
#   - the same load: a 1 kHz plant process (daemon/benches/lateness_plant.rs) publishing joint states
#     and torque requests, pinned to the "plant CPU" (default 0), SCHED_OTHER;
#   - the measuring thread pinned to the "RT CPU" (default 1) with SCHED_FIFO 80 and mlockall when
#     permitted; every other thread of the measured process on the plant CPU (frictiond's supervisor
#     via taskset, cyclictest's main thread via --mainaffinity);
#   - the same PM QoS: /dev/cpu_dma_latency held at 0 µs when writable (cyclictest does this by
#     default; frictiond via `[loop] cpu_dma_latency_us = 0`), so neither wakes from a deep idle state
#     (in a VM: an HLT exit) that the other avoids.
# 1. frictiond (release, clock trigger, 1 kHz, the two-joint fixture config/bench_two_joint.toml) runs
#    while the plant feeds it (its full compute + publish path every tick); at exit it writes its loop
#    statistics to $FRICTIOND_LATENCY_REPORT (wake lateness against the absolute deadline in 1 µs
#    buckets, compute time, the RT thread's page faults and context switches, policy, CPU, PM QoS).
# 2. cyclictest -m -i1000 -q -h 20000 -p 80 -a RT_CPU --mainaffinity PLANT_CPU, with the plant running
#    again (it then has no subscriber; its CPU load on the plant CPU is the same).
# While each runs, the script prints every thread of the measured process with its policy, priority,
# affinity and the CPU it is on (from ps/taskset, i.e. /proc), and whether the PM QoS was held.
# Prints p50 / p99 / p99.9 / max [µs] of both side by side. No pass/fail; results in docs/performance.md.
# Each frictiond chunk is a fresh process (its first ticks after start-up included), like each
# cyclictest chunk.
#
# Environment: LATENESS_RT_CPU (1), LATENESS_PLANT_CPU (0), LATENESS_PRIO (80),
# LATENESS_ORDER=cyclictest-first to swap the order within each chunk pair, LATENESS_CHUNKS (3),
# LATENESS_CONFIG (config/bench_two_joint.toml; its [backend] and [loop] are replaced) with
# LATENESS_JOINTS (2) joints published by the plant: e.g. LATENESS_CONFIG=config/stress32.toml
# LATENESS_JOINTS=32 for the 32-PINN tick, LATENESS_PM_QOS=off (neither holds cpu_dma_latency).
set -euo pipefail
cd "$(dirname "$0")/.."
SECS="${1:-${LATENESS_SECONDS:-60}}"
TARGET="${CARGO_TARGET_DIR:-$PWD/target}"
RT_CPU="${LATENESS_RT_CPU:-1}"
PLANT_CPU="${LATENESS_PLANT_CPU:-0}"
PRIO="${LATENESS_PRIO:-80}"
ORDER="${LATENESS_ORDER:-frictiond-first}"
CHUNKS="${LATENESS_CHUNKS:-3}"
CONFIG="${LATENESS_CONFIG:-config/bench_two_joint.toml}"
JOINTS="${LATENESS_JOINTS:-2}"

if ! command -v cyclictest >/dev/null; then
    echo "installing rt-tests (cyclictest) with apt-get" >&2
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    $SUDO apt-get install -y rt-tests >/dev/null || { $SUDO apt-get update >/dev/null && $SUDO apt-get install -y rt-tests >/dev/null; }
fi

NCPU=$(nproc)
if [ "$NCPU" -lt 2 ] || [ "$RT_CPU" -ge "$NCPU" ] || [ "$PLANT_CPU" -ge "$NCPU" ]; then
    echo "need 2 CPUs for the pinned layout (have $NCPU): RT and plant share CPU 0" >&2
    RT_CPU=0; PLANT_CPU=0
fi

# Real-time priority only when permitted (root, or an RLIMIT_RTPRIO >= PRIO).
RTPRIO=$(ulimit -r)
if [ "$(id -u)" = 0 ] || [ "$RTPRIO" = unlimited ] || [ "$RTPRIO" -ge "$PRIO" ]; then
    PRIO_TOML="priority = $PRIO"; PRIO_CT="-p $PRIO"; SCHED="SCHED_FIFO $PRIO"
else
    PRIO_TOML=""; PRIO_CT=""; SCHED="SCHED_OTHER (no RT priority permitted)"
fi
# PM QoS: both hold cpu_dma_latency = 0 when the device is writable (LATENESS_PM_QOS=off: neither
# does, for the A/B of deep idle states); otherwise neither does.
if [ "${LATENESS_PM_QOS:-on}" != off ] && [ -w /dev/cpu_dma_latency ]; then
    QOS_TOML="cpu_dma_latency_us = 0"; QOS_CT=""; QOS="cpu_dma_latency=0 held"
else
    QOS_TOML=""; QOS_CT="--laptop"; QOS="cpu_dma_latency not held by either (LATENESS_PM_QOS=${LATENESS_PM_QOS:-on}, writable: $([ -w /dev/cpu_dma_latency ] && echo yes || echo no))"
fi

cargo build --release -q -p frictiond --bin frictiond
# From here on this script (and the sleeps, ps, awk it runs) stays on the plant CPU.
taskset -pc "$PLANT_CPU" $$ >/dev/null
PLANT_LOG=$(mktemp)
cargo bench -q -p frictiond --bench lateness_plant --no-run 2>"$PLANT_LOG" || { cat "$PLANT_LOG" >&2; exit 1; }
PLANT=$(ls -t "$TARGET"/release/deps/lateness_plant-* | grep -v '\.d$' | head -1)

WORK=$(mktemp -d /tmp/fld_lateness.XXXXXX)
PLANT_PID=""
MEASURED_PID=""
cleanup() {
    # Only the processes this script started, by PID.
    [ -n "$MEASURED_PID" ] && kill -TERM "$MEASURED_PID" 2>/dev/null || true
    [ -n "$PLANT_PID" ] && kill -TERM "$PLANT_PID" 2>/dev/null || true
    rm -rf "$WORK" "$PLANT_LOG"
}
trap cleanup EXIT
PREFIX="fld_lateness_$$"
mkdir -p "$WORK/iox"
# The config's [safety] and joints (its own [backend] and [loop] dropped, relative model paths made
# absolute), then this run's [backend] and [loop].
CFG_DIR=$(cd "$(dirname "$CONFIG")" && pwd)
awk -v dir="$CFG_DIR" '
    /^[ \t]*\[/ { skip = ($0 ~ /^[ \t]*\[(loop|backend)\][ \t]*(#.*)?$/) }
    skip { next }
    /^[ \t]*model[ \t]*=[ \t]*"[^\/]/ { sub(/"/, "\"" dir "/") }
    { print }' "$CONFIG" >"$WORK/frictiond.toml"
cat >>"$WORK/frictiond.toml" <<TOML
[backend]
kind = "shm"
service_prefix = "$PREFIX"
root_path = "$WORK/iox"

[loop]
period_us = 1000
cpu = $RT_CPU
$PRIO_TOML
lock_memory = true
$QOS_TOML
status_every_ticks = 100
ready_after_ticks = 100
TOML

start_plant() {
    FLD_PLANT_PREFIX="$PREFIX" FLD_PLANT_ROOT="$WORK/iox" FLD_PLANT_SECONDS="$((SECS + 5))" FLD_PLANT_JOINTS="$JOINTS" \
        taskset -c "$PLANT_CPU" "$PLANT" 2>/dev/null &
    PLANT_PID=$!
}
stop_plant() {
    kill -TERM "$PLANT_PID" 2>/dev/null || true
    wait "$PLANT_PID" 2>/dev/null || true
    PLANT_PID=""
}

# Every thread of process $1: tid, name, policy, RT priority, affinity, CPU it last ran on.
threads() {
    local pid=$1 tid line aff
    # Pinned to the plant CPU like everything else, so the listing does not disturb the RT CPU.
    taskset -c "$PLANT_CPU" ps -L -o tid=,comm=,cls=,rtprio=,psr= -p "$pid" | while read -r tid line; do
        aff=$(taskset -c "$PLANT_CPU" taskset -pc "$tid" 2>/dev/null | sed 's/.*: //')
        printf "    tid %-7s %-16s cls/rtprio/cpu-now: %-14s affinity: %s\n" "$tid" \
            "$(echo "$line" | awk '{print $1}')" "$(echo "$line" | awk '{print $2"/"$3"/"$4}')" "$aff"
    done
}
# Whether process $1 holds /dev/cpu_dma_latency open.
qos_held() {
    if ls -l "/proc/$1/fd" 2>/dev/null | grep -q cpu_dma_latency; then echo yes; else echo no; fi
}

D_THREADS="" C_THREADS="" D_EXTRA="" D_MISSED=0
: >"$WORK/d_hist"; : >"$WORK/c_hist"   # merged histograms: "<µs bucket> <count>" lines
D_OV=0; D_MAX_US=0; C_OV=0; C_MAX_US=0
get() { sed -n "s/^$1=//p" "$WORK/report.txt"; }
us() { awk -v x="$1" 'BEGIN { printf "%.1f", x / 1000 }'; }
fmax() { awk -v a="$1" -v b="$2" 'BEGIN { print (a > b ? a : b) }'; }

run_frictiond() {  # $1 = seconds
    echo "frictiond: ${1} s, $CONFIG ($JOINTS joints fed), clock trigger, 1 kHz, $SCHED on CPU $RT_CPU, plant on CPU $PLANT_CPU, $QOS, load average $(cut -d' ' -f1-3 /proc/loadavg)" >&2
    start_plant
    FRICTIOND_LATENCY_REPORT="$WORK/report.txt" RUST_LOG=warn \
        taskset -c "$PLANT_CPU" "$TARGET/release/frictiond" --config "$WORK/frictiond.toml" &
    MEASURED_PID=$!
    sleep 1
    D_THREADS="$(threads "$MEASURED_PID")
    PM QoS fd held: $(qos_held "$MEASURED_PID")"
    sleep "$(($1 > 1 ? $1 - 1 : 0))"
    kill -TERM "$MEASURED_PID"
    wait "$MEASURED_PID"
    MEASURED_PID=""
    stop_plant
    get lateness_hist_us | tr ',' '\n' | tr ':' ' ' | grep . >>"$WORK/d_hist" || true
    D_OV=$((D_OV + $(get lateness_overflow)))
    D_MAX_US=$(fmax "$D_MAX_US" "$(us "$(get lateness_max_ns)")")
    D_MISSED=$((D_MISSED + $(get missed)))
    D_EXTRA=$(printf "frictiond RT thread (last chunk): %s %s, CPU %s→%s, pinned %s, mlocked %s, PM QoS %s µs; during the loop: %s minor / %s major page faults, %s voluntary / %s involuntary context switches; compute p50/p99 <= %s/%s µs (power-of-two buckets)" \
        "$(get rt_policy)" "$(get rt_priority)" "$(get rt_cpu_start)" "$(get rt_cpu_end)" \
        "$(get rt_cpu_pinned)" "$(get rt_memory_locked)" "$(get rt_pm_qos_us)" \
        "$(get rt_minflt)" "$(get rt_majflt)" "$(get rt_nvcsw)" "$(get rt_nivcsw)" \
        "$(us "$(get compute_p50_ns)")" "$(us "$(get compute_p99_ns)")")
}

run_cyclictest() {  # $1 = seconds
    echo "cyclictest: ${1} s, -i1000, $SCHED on CPU $RT_CPU (main thread on CPU $PLANT_CPU), plant on CPU $PLANT_CPU, $QOS, load average $(cut -d' ' -f1-3 /proc/loadavg)" >&2
    start_plant
    # shellcheck disable=SC2086
    cyclictest -m -i1000 -l "$(($1 * 1000))" -q -h 20000 $PRIO_CT $QOS_CT \
        -a "$RT_CPU" --mainaffinity="$PLANT_CPU" >"$WORK/cyclictest.txt" 2>"$WORK/cyclictest.err" &
    MEASURED_PID=$!
    sleep 1
    C_THREADS="$(threads "$MEASURED_PID")
    PM QoS fd held: $(qos_held "$MEASURED_PID")"
    wait "$MEASURED_PID"
    MEASURED_PID=""
    stop_plant
    # Histogram lines "<µs> <count>" (bucket k = [k, k+1) µs, like frictiond's); overflows apart.
    awk '/^[0-9]+[ \t]+[0-9]+/ && $2 + 0 > 0 { print $1 + 0, $2 + 0 }' "$WORK/cyclictest.txt" >>"$WORK/c_hist"
    C_OV=$((C_OV + $(awk '/^# Histogram Overflows:/ { print $4 + 0 }' "$WORK/cyclictest.txt")))
    C_MAX_US=$(fmax "$C_MAX_US" "$(awk '/^# Max Latencies:/ { print $4 + 0 }' "$WORK/cyclictest.txt")")
}

# Quantiles of a merged histogram, the same way for both: the upper edge of the 1 µs bucket holding
# the quantile, capped by the max. $1 name, $2 file, $3 overflow count, $4 max [µs], $5 extra text.
row() {
    awk -v name="$1" -v ov="$3" -v mx="$4" -v extra="$5" '
        { c[$1 + 0] += $2; n += $2 }
        END {
            n += ov; split("0.5 0.99 0.999", q, " ");
            for (i = 1; i <= 3; i++) {
                want = q[i] * n; acc = 0; r[i] = mx;
                for (k = 0; k < 20000; k++) { acc += c[k]; if (acc >= want) { r[i] = k + 1; break } }
                if (r[i] > mx) r[i] = mx;
            }
            printf "%-12s %8.1f %8.1f %8.1f %9.1f   n=%d%s\n", name, r[1], r[2], r[3], mx, n, extra
        }' "$2"
}

# Interleaved chunks (F C F C … or C F C F …) so load drift hits both alike.
CHUNK=$(( (SECS + CHUNKS - 1) / CHUNKS ))
for _ in $(seq "$CHUNKS"); do
    if [ "$ORDER" = cyclictest-first ]; then run_cyclictest "$CHUNK"; run_frictiond "$CHUNK"
    else run_frictiond "$CHUNK"; run_cyclictest "$CHUNK"; fi
done

echo
echo "threads while measuring (cls: FF = SCHED_FIFO, TS = SCHED_OTHER):"
echo "  frictiond:"; echo "$D_THREADS"
echo "  cyclictest:"; echo "$C_THREADS"
echo "$D_EXTRA"
printf "\nwake lateness [µs], %s chunks x %s s each, interleaved (%s), %s on CPU %s, plant on CPU %s, %s\n" \
    "$CHUNKS" "$CHUNK" "$ORDER" "$SCHED" "$RT_CPU" "$PLANT_CPU" "$QOS"
printf "%-12s %8s %8s %8s %9s\n" "" p50 p99 p99.9 max
row frictiond "$WORK/d_hist" "$D_OV" "$D_MAX_US" ", missed deadlines $D_MISSED"
row cyclictest "$WORK/c_hist" "$C_OV" "$C_MAX_US" ""
echo "load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
