#!/usr/bin/env bash
# Fuzz every target for SECONDS each (default 60):
#   fuzz/run.sh 60                     # all targets, 60 s each (8 targets = 8 min)
#   fuzz/run.sh 30 candump_parse       # only the named targets
#   FUZZ_RUNS=1000000 fuzz/run.sh 0 onnx_import   # a fixed number of executions instead of a time
# Targets: weights_reader (.fwt reader), can_mit_decode (MIT command/reply/special decoders),
# can_odrive_decode (ODrive CAN Simple decoder), can_cia402_decode (CANopen / CiA 402 decoders and
# state machine), candump_parse (candump -L line parser),
# frictiond_config (the TOML config through what `frictiond --check` runs), dataset_readers (dataset
# CSV, JSON sidecar and fit file), onnx_import (ONNX and safetensors importers), log_importers (the CSV
# and ROS 2 MCAP robot-log importers of `frictl import csv|mcap`, with the column/unit/sign spec taken
# from the input). The last four start from the files in fuzz/seeds/<target>/ (shipped configs, a small
# dataset + sidecar, small exports, small CSV logs and MCAP bags written by
# tools/logs/tests/fixtures/make_fixtures.py mcap-seed). mat_import (the YARP `.mat` importer of
# `frictl import mat`, cargo feature `mat`) is structure-aware: each input is the plan of an HDF5 file
# that the target writes and imports; it needs the system HDF5 library and is left out of the default
# list, with a message, where pkg-config finds none.
# Installs cargo-fuzz if missing, seeds each corpus (the .fwt corpus with valid files written by the test
# `fuzz_seed_files_are_valid` in tests/weights_bad_input.rs; the CAN corpora with a few valid frames and
# log lines written here), builds all targets once, then runs libFuzzer with ASan on the stable toolchain
# (RUSTC_BOOTSTRAP=1 unlocks the -Z flags cargo-fuzz needs) and prints each target's execution count.
# Runs FUZZ_JOBS targets at a time (default: the CPU count). FUZZ_BUILD=dev builds the targets without
# optimisation (cargo-fuzz --dev: quicker to build, fewer executions per second; what CI's short smoke
# run uses); the default, release, is for fuzzing at length. FUZZ_SANITIZER (default
# address) is passed to cargo-fuzz's --sanitizer. Exits non-zero when a target crashes; the reproducer
# is left in fuzz/artifacts/<target>/.
set -euo pipefail
SECS="${1:-60}"
shift || true
ALL=(weights_reader can_mit_decode can_odrive_decode can_cia402_decode candump_parse frictiond_config dataset_readers onnx_import log_importers urdf_robot)
FEATURES=()
TEST_FEATURES=()
# Flags of both `cargo fuzz build` and `cargo fuzz run` (the same, or run builds again).
BUILD_FLAGS=(--sanitizer "${FUZZ_SANITIZER:-address}")
case "${FUZZ_BUILD:-release}" in
  release) ;;
  dev) BUILD_FLAGS+=(--dev) ;;
  *) echo "FUZZ_BUILD=${FUZZ_BUILD}: expected release or dev" >&2; exit 2 ;;
esac
if mat=$(bash "$(dirname "$0")/../tests/have-hdf5.sh"); then
  read -r -a TEST_FEATURES <<< "$mat"
  ALL+=(mat_import)
  # Every target is built with it (one build; it only adds what mat_import needs).
  FEATURES=(--features=mat)
else
  echo "fuzz: no system HDF5 (apt install libhdf5-dev): mat_import left out"
fi
if [ $# -gt 0 ]; then TARGETS=("$@"); else TARGETS=("${ALL[@]}"); fi
cd "$(dirname "$0")/.."
ROOT="$(pwd)"
if ! command -v cargo-fuzz >/dev/null 2>&1; then
  # A debug build of the tool is enough: it only drives cargo.
  cargo install cargo-fuzz --locked --debug
fi

seed() { # seed <target> <name> <printf-format>
  mkdir -p "$ROOT/fuzz/corpus/$1"
  # shellcheck disable=SC2059
  printf "$3" > "$ROOT/fuzz/corpus/$1/seed-$2"
}
for t in "${TARGETS[@]}"; do
  mkdir -p "$ROOT/fuzz/corpus/$t"
  case "$t" in
    weights_reader)
      echo "== seeding fuzz/corpus/weights_reader"
      # The harness from tests/run.sh's own build (`cargo test --workspace` with its features), found in
      # cargo's list: after tests/run.sh nothing is rebuilt. Selecting it with `-p frictionless` or
      # `--test frictionless_tests` changes the unit graph and rebuilds dependencies (docs/decisions.md).
      harness=$(cargo test --workspace "${TEST_FEATURES[@]}" --no-run --message-format=json 2>/dev/null |
        python3 -c 'import json,sys
for l in sys.stdin:
    try: m=json.loads(l)
    except Exception: continue
    t=m.get("target",{})
    if m.get("reason")=="compiler-artifact" and m.get("executable") and t.get("name")=="frictionless_tests" and "test" in t.get("kind",[]):
        print(m["executable"])')
      [ -n "$harness" ] || { echo "fuzz: building the frictionless_tests harness failed" >&2; exit 1; }
      FWT_FUZZ_SEED_DIR="$ROOT/fuzz/corpus/weights_reader" \
        "$harness" -q --exact weights_bad_input::fuzz_seed_files_are_valid ;;
    can_mit_decode)
      # byte 0: flags (bit 0 extended, bit 1 RTR) | length << 4; bytes 1..4 id (LE); 4..12 data; then
      # f64 fields for commands and ranges.
      seed "$t" command '\x80\x01\x00\x00\x7f\xff\x7f\xf0\x00\x00\x07\xff'
      seed "$t" enter '\x80\x01\x00\x00\xff\xff\xff\xff\xff\xff\xff\xfc'
      seed "$t" allff '\x80\x01\x00\x00\xff\xff\xff\xff\xff\xff\xff\xff'
      seed "$t" reply '\x60\x00\x00\x00\x01\x80\x00\x80\x08\x00\x00\x00' ;;
    can_odrive_decode)
      seed "$t" torque '\x40\x2e\x00\x00\x00\x00\x80\x3f\x00\x00\x00\x00'
      seed "$t" state '\x40\x27\x00\x00\x08\x00\x00\x00\x00\x00\x00\x00'
      seed "$t" encoder '\x80\x29\x00\x00\x00\x00\x80\x3f\x00\x00\x00\xbf'
      seed "$t" heartbeat '\x80\x21\x00\x00\x00\x08\x00\x00\x08\x00\x00\x00'
      seed "$t" rtr '\x02\x29\x00\x00' ;;
    can_cia402_decode)
      # SDO write 0x6040 = 6 to node 0x7F; TPDO1 of node 5 (mapping from bytes 13..); NMT start;
      # EMCY 0x4310 of node 3.
      seed "$t" sdo '\x80\x7f\x06\x00\x2b\x40\x60\x00\x06\x00\x00\x00\x00'
      seed "$t" tpdo '\x80\x85\x01\x00\x37\x02\xfe\xff\xff\xff\x70\xfe\x00\x03\x41\x64\x77'
      seed "$t" nmt '\x20\x00\x00\x00\x01\x05'
      seed "$t" emcy '\x80\x83\x00\x00\x10\x43\x08\x01\x02\x03\x04\x05' ;;
    candump_parse)
      seed "$t" classic '(1700000000.123456) vcan0 001#7FFF7FF0000007FF\n(1700000000.124456) vcan0 000#018000800800\n'
      seed "$t" ext_rtr '(0.000001) can0 12345678#R\n(0.000002) can0 02C#R8\n'
      seed "$t" fd '(1.000000) vcan1 123##1DEADBEEF\n(1.000001) vcan1 123#0011223344556677_C\n' ;;
    frictiond_config|dataset_readers|onnx_import|log_importers|urdf_robot)
      cp "$ROOT/fuzz/seeds/$t/"* "$ROOT/fuzz/corpus/$t/" ;;
    mat_import) ;; # structure-aware: libFuzzer starts from the empty plan
    *) echo "unknown fuzz target $t (known: ${ALL[*]})" >&2; exit 2 ;;
  esac
done

echo "== [${SECONDS} s] building ${TARGETS[*]}"
if [ $# -gt 0 ]; then
  for t in "${TARGETS[@]}"; do RUSTC_BOOTSTRAP=1 cargo fuzz build "${BUILD_FLAGS[@]}" "${FEATURES[@]}" "$t"; done
else
  RUSTC_BOOTSTRAP=1 cargo fuzz build "${BUILD_FLAGS[@]}" "${FEATURES[@]}"   # every target in one cargo build
fi
# One libFuzzer process per core (FUZZ_JOBS, default: the CPU count): each is single-threaded.
JOBS=${FUZZ_JOBS:-$(nproc)}
mkdir -p "$ROOT/fuzz/artifacts"
fuzz_one() { # fuzz_one <target>: runs it, prints one line; non-zero on a crash
  local t=$1 log="$ROOT/fuzz/artifacts/$1.log" limit runs secs
  if [ -n "${FUZZ_RUNS:-}" ]; then
    limit=(-runs="$FUZZ_RUNS")
  else
    limit=(-max_total_time="$SECS")
  fi
  # The text, protobuf and log targets: inputs up to 64 KiB (their seeds are a few KB).
  case "$t" in frictiond_config|dataset_readers|onnx_import|log_importers) limit+=(-max_len=65536) ;; esac
  # An HDF5 file per input: a plan that makes the importer read for more than 10 s is a hang.
  case "$t" in mat_import) limit+=(-max_len=4096 -timeout=10) ;; esac
  RUSTC_BOOTSTRAP=1 cargo fuzz run "${BUILD_FLAGS[@]}" "${FEATURES[@]}" "$t" "$ROOT/fuzz/corpus/$t" -- "${limit[@]}" \
    -print_final_stats=1 > "$log" 2>&1 || { tail -n 60 "$log" >&2; echo "fuzz: $t FAILED (see $log)"; return 1; }
  runs=$(grep -oE 'stat::number_of_executed_units: *[0-9]+' "$log" | grep -oE '[0-9]+$' | tail -n1)
  secs=$(grep -oE 'Done [0-9]+ runs in [0-9]+ second' "$log" | grep -oE '[0-9]+ second' | grep -oE '[0-9]+' | tail -n1)
  echo "fuzz: $t ok, ${runs:-?} executions in ${secs:-$SECS}s, corpus $(ls "$ROOT/fuzz/corpus/$t" | wc -l) inputs"
}
if [ -n "${FUZZ_RUNS:-}" ]; then
  echo "== [${SECONDS} s] fuzzing ${TARGETS[*]} for ${FUZZ_RUNS} executions each, $JOBS at a time"
else
  echo "== [${SECONDS} s] fuzzing ${TARGETS[*]} for ${SECS}s each, $JOBS at a time"
fi
failed=0
running=0
for t in "${TARGETS[@]}"; do
  if [ "$running" -ge "$JOBS" ]; then
    wait -n || failed=1
    running=$((running - 1))
  fi
  [ "$failed" -eq 0 ] || break
  fuzz_one "$t" &
  running=$((running + 1))
done
while [ "$running" -gt 0 ]; do
  wait -n || failed=1
  running=$((running - 1))
done
[ "$failed" -eq 0 ] || { echo "fuzz: a target crashed; its reproducer is in fuzz/artifacts/<target>/" >&2; exit 1; }
echo "== [${SECONDS} s] fuzz: every target ok"
