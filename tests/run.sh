#!/usr/bin/env bash
# The project's test command (README): sets up the Python reference tools in a venv, writes reference
# vectors with independent implementations (ONNX Runtime, SciPy, Pinocchio), then runs the Rust tests.
#
#   bash tests/run.sh            # everything
#   SKIP_PY=1 bash tests/run.sh  # Rust tests only (reference-vector tests then say they were skipped)
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export FRICTIONLESS_REFS="$ROOT/target/refs"
mkdir -p "$FRICTIONLESS_REFS"

if [ -z "${SKIP_PY:-}" ]; then
  VENV="$ROOT/target/venv"
  if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
  fi
  "$VENV/bin/pip" install -q --disable-pip-version-check -r tests/python/requirements.txt
  for gen in tests/python/gen_*.py; do
    [ -e "$gen" ] || continue
    echo "== reference vectors: $gen"
    "$VENV/bin/python" "$gen" --out "$FRICTIONLESS_REFS"
  done
else
  unset FRICTIONLESS_REFS
fi

# Cargo builds a package's own binaries for its integration tests (frictiond for daemon/tests), not
# another package's: the frictiond tests that run `frictl` find it in target/<profile>/, built here.
echo "== cargo build --bins (end-to-end tests start frictiond and frictl as processes)"
cargo build --workspace --bins

echo "== cargo test"
cargo test --workspace --no-fail-fast 2>&1 | tee target/cargo-test.log
