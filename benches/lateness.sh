#!/usr/bin/env bash
# Wake lateness of frictiond's RT loop next to cyclictest, on the same machine, one after the other.
#
#   benches/lateness.sh [SECONDS]        (or env LATENESS_SECONDS; default 60)
#
# 1. frictiond (release, clock trigger, 1 kHz, two joints CV/SCV, SCHED_FIFO 80 + mlockall when
#    permitted) runs SECONDS while a 1 kHz plant (daemon/benches/lateness_plant.rs) feeds it; at exit
#    it writes its loop statistics to $FRICTIOND_LATENCY_REPORT (wake lateness against the absolute
#    deadline in 1 µs buckets, compute time, input age).
# 2. cyclictest -m -i1000 -l SECONDS*1000 -q -h 20000 [-p 80] (Debian rt-tests, installed with
#    apt-get if missing; it uses clock_nanosleep by default: rt-tests 2.x dropped the -n flag).
# Prints p50 / p99 / p99.9 / max [µs] of both side by side. No pass/fail: numbers for the README.
set -euo pipefail
cd "$(dirname "$0")/.."
SECS="${1:-${LATENESS_SECONDS:-60}}"
TARGET="${CARGO_TARGET_DIR:-$PWD/target}"

if ! command -v cyclictest >/dev/null; then
    echo "installing rt-tests (cyclictest) with apt-get" >&2
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    $SUDO apt-get install -y rt-tests >/dev/null || { $SUDO apt-get update >/dev/null && $SUDO apt-get install -y rt-tests >/dev/null; }
fi

# Real-time priority only when permitted (root, or an RLIMIT_RTPRIO >= 80).
RTPRIO=$(ulimit -r)
if [ "$(id -u)" = 0 ] || [ "$RTPRIO" = unlimited ] || [ "$RTPRIO" -ge 80 ]; then
    PRIO_TOML="priority = 80"; PRIO_CT="-p 80"; SCHED="SCHED_FIFO 80"
else
    PRIO_TOML=""; PRIO_CT=""; SCHED="SCHED_OTHER (no RT priority permitted)"
fi

cargo build --release -q -p frictiond --bin frictiond
PLANT_LOG=$(mktemp)
cargo bench -q -p frictiond --bench lateness_plant --no-run 2>"$PLANT_LOG" || { cat "$PLANT_LOG" >&2; exit 1; }
PLANT=$(ls -t "$TARGET"/release/deps/lateness_plant-* | grep -v '\.d$' | head -1)

WORK=$(mktemp -d /tmp/fld_lateness.XXXXXX)
trap 'rm -rf "$WORK" "$PLANT_LOG"' EXIT
PREFIX="fld_lateness_$$"
mkdir -p "$WORK/iox"
cat >"$WORK/frictiond.toml" <<TOML
[backend]
kind = "shm"
service_prefix = "$PREFIX"
root_path = "$WORK/iox"

[loop]
period_us = 1000
$PRIO_TOML
lock_memory = true
status_every_ticks = 100
ready_after_ticks = 100

[safety]
stale_after_ticks = 20
on_stale = "zero"

[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
kfc = 0.85
max_output_friction = 25.0
lpf = { order = 2, cutoff_hz = 30.0 }
friction_model = "cv"
kc = 8.1
ka = 50.84
kv = 5.55

[[joint]]
name = "ankle_roll"
index = 1
gear_ratio = -160.0
kt = 0.0665
max_curr = 3.0
kfc = 0.7
friction_model = "scv"
kc = 1.0005
ka = 2.78
kv = 0.29
ks = 6.0
vs = 0.13
alpha = 0.6
TOML

echo "frictiond: ${SECS} s, clock trigger, 1 kHz, $SCHED, load average $(cut -d' ' -f1-3 /proc/loadavg)" >&2
FRICTIOND_LATENCY_REPORT="$WORK/report.txt" RUST_LOG=warn \
    "$TARGET/release/frictiond" --config "$WORK/frictiond.toml" &
DPID=$!
sleep 0.5
FLD_PLANT_PREFIX="$PREFIX" FLD_PLANT_ROOT="$WORK/iox" FLD_PLANT_SECONDS="$((SECS + 2))" "$PLANT" 2>/dev/null &
PPID_=$!
sleep "$SECS"
kill -TERM "$DPID"
wait "$DPID"
wait "$PPID_" || true
get() { sed -n "s/^$1=//p" "$WORK/report.txt"; }
us() { awk -v x="$1" 'BEGIN { printf "%.1f", x / 1000 }'; }
D_N=$(get lateness_n)
D_ROW=$(printf "%-12s %8s %8s %8s %9s   n=%s, missed deadlines %s; compute p50/p99 <= %s/%s µs (power-of-two buckets)" \
    frictiond "$(us "$(get lateness_p50_ns)")" "$(us "$(get lateness_p99_ns)")" \
    "$(us "$(get lateness_p999_ns)")" "$(us "$(get lateness_max_ns)")" "$D_N" "$(get missed)" \
    "$(us "$(get compute_p50_ns)")" "$(us "$(get compute_p99_ns)")")

echo "cyclictest: ${SECS} s, -i1000, $SCHED, load average $(cut -d' ' -f1-3 /proc/loadavg)" >&2
# shellcheck disable=SC2086
cyclictest -m -i1000 -l "$((SECS * 1000))" -q -h 20000 $PRIO_CT >"$WORK/cyclictest.txt"
# Histogram lines: "<µs> <count>"; overflows counted separately. Quantiles = bucket upper edge.
C_ROW=$(awk '
    /^[0-9]+[ \t]+[0-9]+/ { c[$1 + 0] = $2 + 0; n += $2 }
    /^# Max Latencies:/ { mx = $4 + 0 }
    /^# Histogram Overflows:/ { ov = $4 + 0 }
    END {
        n += ov; split("0.5 0.99 0.999", q, " ");
        for (i = 1; i <= 3; i++) {
            want = q[i] * n; acc = 0; r[i] = mx;
            for (k = 0; k < 20000; k++) { acc += c[k]; if (acc >= want) { r[i] = k + 1; break } }
            if (r[i] > mx) r[i] = mx;
        }
        printf "%-12s %8.1f %8.1f %8.1f %9.1f   n=%d", "cyclictest", r[1], r[2], r[3], mx, n
    }' "$WORK/cyclictest.txt")

printf "\nwake lateness [µs]   %8s %8s %8s %9s\n" p50 p99 p99.9 max
echo "$D_ROW"
echo "$C_ROW"
