#!/usr/bin/env bash
# Fuzz the .fwt weight reader for SECONDS (default 60):
#   fuzz/run.sh 60
# Installs cargo-fuzz if missing, seeds the corpus with valid files written by the test
# `fuzz_seed_files_are_valid` (tests/weights_bad_input.rs), then runs libFuzzer with ASan on the stable
# toolchain (RUSTC_BOOTSTRAP=1 unlocks the -Z flags cargo-fuzz needs). Exits non-zero on a crash; the
# reproducer is left in fuzz/artifacts/weights_reader/.
set -euo pipefail
SECS="${1:-60}"
cd "$(dirname "$0")/.."
ROOT="$(pwd)"
if ! command -v cargo-fuzz >/dev/null 2>&1; then
  cargo install cargo-fuzz --locked
fi
CORPUS="$ROOT/fuzz/corpus/weights_reader"
mkdir -p "$CORPUS"
echo "== seeding $CORPUS"
FWT_FUZZ_SEED_DIR="$CORPUS" cargo test -q -p frictionless --test weights_bad_input fuzz_seed_files_are_valid
echo "== fuzzing weights_reader for ${SECS}s"
RUSTC_BOOTSTRAP=1 cargo fuzz run weights_reader "$CORPUS" -- -max_total_time="$SECS"
