#!/usr/bin/env bash
# Soak: frictiond (clock trigger, 1 kHz, two paper-size PINN joints) in closed loop with the plant
# (`frictl sim serve`, knee + ankle roll) and a controller answering every state
# (daemon/benches/soak_controller.rs), for N periods of 1 ms (N/1000 s of wall time: the report
# gives the ticks run and the periods missed), with a SIGHUP every SOAK_HUP_S seconds. The
# reloads cycle through: a valid change (kfc), the original config, and a config naming a corrupt
# model (must be refused, the running model kept).
#
#   bash benches/soak.sh [TICKS]        (or env SOAK_TICKS; default 1000000 = 16.7 min)
#
# Reports: ticks, missed ticks, wake lateness p99 / max, RSS of frictiond shortly after READY and at
# the end (and at every tenth of the run: does it plateau?), reloads applied / refused (from its
# log), RT-thread allocations counted after READY
# (FRICTIOND_ALLOC_REPORT; must be 0), stale-input log lines. Exit status non-zero if frictiond
# did not exit cleanly, a reload was applied or refused against the plan, or the RT thread allocated.
# Not part of CI (it takes N/1000 s).
#
# Environment: SOAK_TICKS, SOAK_HUP_S (10), SOAK_PROFILE (release; `dev` reuses a debug build — the
# dev profile of this workspace is optimised), SOAK_KEEP=1 keeps the work directory (logs, configs).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
TICKS="${1:-${SOAK_TICKS:-1000000}}"
HUP_S="${SOAK_HUP_S:-10}"
PROFILE="${SOAK_PROFILE:-release}"
TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"
case "$PROFILE" in dev) PDIR=debug ;; *) PDIR="$PROFILE" ;; esac

echo "soak: building frictiond, frictl and the soak controller ($PROFILE)" >&2
cargo build -q --profile "$PROFILE" -p frictiond -p frictl --bins
cargo build -q --profile "$PROFILE" -p frictiond --bench soak_controller
CONTROLLER=$(ls -t "$TARGET/$PDIR"/deps/soak_controller-* | grep -v '\.d$' | head -1)
FRICTIOND="$TARGET/$PDIR/frictiond"
FRICTL="$TARGET/$PDIR/frictl"

WORK=$(mktemp -d /tmp/fld_soak.XXXXXX)
PREFIX="fld_soak_$$"
mkdir -p "$WORK/iox"
PLANT_PID="" CTRL_PID="" D_PID=""
cleanup() {
    # Only the processes this script started, by PID.
    for p in "$D_PID" "$CTRL_PID" "$PLANT_PID"; do
        [ -n "$p" ] && kill -TERM "$p" 2>/dev/null || true
    done
    if [ -z "${SOAK_KEEP:-}" ]; then rm -rf "$WORK"; else echo "soak: kept $WORK" >&2; fi
}
trap cleanup EXIT

# Two joints with the paper-size PINN templates of config/stress32.toml (their k_t: the models'), the
# plant's presets knee (r = -100) and ankle_roll (r = -160).
config() {  # $1 = knee kfc, $2 = knee model file
    cat <<TOML
[backend]
kind = "shm"
service_prefix = "$PREFIX"
root_path = "$WORK/iox"

[loop]
period_us = 1000
lock_memory = false
status_every_ticks = 100
ready_after_ticks = 100

[safety]
stale_after_ticks = 50
on_stale = "zero"

[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.156977705
max_curr = 5.0
kfc = $1
max_output_friction = 25.0
lpf = { order = 2, cutoff_hz = 30.0 }
friction_model = "pinn"
model = "$2"
model_for = "stress32_r-100"
warmup = "zero_pad"

[[joint]]
name = "ankle_roll"
index = 1
gear_ratio = -160.0
kt = 0.066468037
max_curr = 3.0
kfc = 0.8
max_output_friction = 8.0
lpf = { order = 2, cutoff_hz = 30.0 }
friction_model = "pinn"
model = "$ROOT/config/models/stress32_paper_f16_r-160.fwt"
model_for = "stress32_r-160"
warmup = "zero_pad"
TOML
}
KNEE_MODEL="$ROOT/config/models/stress32_paper_f16_r-100.fwt"
printf 'not a weight file' >"$WORK/corrupt.fwt"
config 0.8 "$KNEE_MODEL" >"$WORK/frictiond.toml"
"$FRICTIOND" --config "$WORK/frictiond.toml" --check >/dev/null

rss_kb() { awk '/^VmRSS:/ { print $2 }' "/proc/$1/status"; }

"$FRICTL" sim serve --preset knee,ankle_roll --prefix "$PREFIX" --root-path "$WORK/iox" \
    2>"$WORK/plant.log" &
PLANT_PID=$!
FLD_SOAK_PREFIX="$PREFIX" FLD_SOAK_ROOT="$WORK/iox" FLD_SOAK_JOINTS=2 "$CONTROLLER" \
    2>"$WORK/controller.log" &
CTRL_PID=$!
FRICTIOND_ALLOC_REPORT="$WORK/alloc.txt" FRICTIOND_LATENCY_REPORT="$WORK/latency.txt" RUST_LOG=info \
    "$FRICTIOND" --config "$WORK/frictiond.toml" 2>"$WORK/frictiond.log" &
D_PID=$!

# READY (ready_after_ticks) within 30 s.
for _ in $(seq 300); do
    grep -q "ready after" "$WORK/frictiond.log" && break
    kill -0 "$D_PID" 2>/dev/null || { cat "$WORK/frictiond.log" >&2; echo "soak: frictiond died" >&2; exit 1; }
    sleep 0.1
done
grep -q "ready after" "$WORK/frictiond.log" || { echo "soak: frictiond not ready" >&2; exit 1; }
sleep 1
RSS_START=$(rss_kb "$D_PID")
T0=$(date +%s.%N)
SECS=$(awk -v t="$TICKS" 'BEGIN { printf "%.3f", t / 1000 }')
echo "soak: $TICKS ticks (${SECS} s), SIGHUP every ${HUP_S} s, frictiond PID $D_PID, RSS ${RSS_START} kB after READY" >&2

HUPS=0 WANT_APPLIED=0 WANT_REFUSED=0
elapsed() { awk -v a="$T0" -v b="$(date +%s.%N)" 'BEGIN { print b - a }'; }
while awk -v e="$(elapsed)" -v s="$SECS" 'BEGIN { exit !(e + 0 < s + 0) }'; do
    left=$(awk -v e="$(elapsed)" -v s="$SECS" -v h="$HUP_S" 'BEGIN { l = s - e; print (l < h ? l : h) }')
    sleep "$left"
    awk -v e="$(elapsed)" -v s="$SECS" 'BEGIN { exit !(e + 0 < s + 0) }' || break
    kill -0 "$D_PID" 2>/dev/null || { echo "soak: frictiond died" >&2; tail -n 20 "$WORK/frictiond.log" >&2; exit 1; }
    case $((HUPS % 3)) in
        0) config 0.7 "$KNEE_MODEL"; WANT_APPLIED=$((WANT_APPLIED + 1)) ;;
        1) config 0.7 "$WORK/corrupt.fwt"; WANT_REFUSED=$((WANT_REFUSED + 1)) ;;
        2) config 0.8 "$KNEE_MODEL"; WANT_APPLIED=$((WANT_APPLIED + 1)) ;;
    esac >"$WORK/frictiond.toml.new"
    mv "$WORK/frictiond.toml.new" "$WORK/frictiond.toml"
    kill -HUP "$D_PID"
    HUPS=$((HUPS + 1))
    echo "$(elapsed) $(rss_kb "$D_PID")" >>"$WORK/rss.txt"
done
RSS_END=$(rss_kb "$D_PID")
kill -TERM "$D_PID"
rc=0; wait "$D_PID" || rc=$?
D_PID=""
kill -TERM "$CTRL_PID" 2>/dev/null || true; wait "$CTRL_PID" 2>/dev/null || true; CTRL_PID=""
kill -TERM "$PLANT_PID" 2>/dev/null || true; wait "$PLANT_PID" 2>/dev/null || true; PLANT_PID=""

get() { sed -n "s/^$2=//p" "$WORK/$1"; }
APPLIED=$(grep -c "reloaded " "$WORK/frictiond.log" || true)
REFUSED=$(grep -c "reload rejected" "$WORK/frictiond.log" || true)
STALE_LINES=$(grep -c "input stale" "$WORK/frictiond.log" || true)
ALLOCS=$(get alloc.txt rt_allocations)
echo "soak results ($(date -u +%Y-%m-%dT%H:%MZ), load average $(cut -d' ' -f1-3 /proc/loadavg), $PROFILE build):"
echo "  ticks                 $(get latency.txt ticks) (asked $TICKS), missed $(get latency.txt missed)"
echo "  wake lateness         p99 <= $(get latency.txt lateness_p99_ns) ns, p99.9 <= $(get latency.txt lateness_p999_ns) ns, max $(get latency.txt lateness_max_ns) ns"
echo "  compute               p99 <= $(get latency.txt compute_p99_ns) ns, max $(get latency.txt compute_max_ns) ns"
echo "  RSS                   ${RSS_START} kB after READY, ${RSS_END} kB at the end"
# RSS sampled at every SIGHUP: the value at each tenth of the run shows whether it plateaus.
if [ -s "$WORK/rss.txt" ]; then
    echo "  RSS by tenth of run   $(awk '{ t[NR] = $1; r[NR] = $2 } END { for (k = 1; k <= 10; k++) { i = int(NR * k / 10); if (i < 1) i = 1; printf "%s%d", (k > 1 ? " " : ""), r[i] } print " kB" }' "$WORK/rss.txt")"
fi
echo "  reloads               $HUPS SIGHUPs: $APPLIED applied (plan $WANT_APPLIED), $REFUSED refused (plan $WANT_REFUSED)"
echo "  RT-thread allocations ${ALLOCS:-?} over $(get alloc.txt rt_counted_ticks) counted ticks ($(get alloc.txt rt_exempt_allocations) exempt: iceoryx2's documented per-sample Box)"
echo "  stale-input log lines $STALE_LINES; frictiond exit status $rc"
fail=0
[ "$rc" = 0 ] || { echo "soak: frictiond exit status $rc" >&2; fail=1; }
[ "$APPLIED" = "$WANT_APPLIED" ] && [ "$REFUSED" = "$WANT_REFUSED" ] || { echo "soak: reloads differ from the plan" >&2; fail=1; }
[ "${ALLOCS:-x}" = 0 ] || { echo "soak: RT thread allocated" >&2; fail=1; }
exit "$fail"
