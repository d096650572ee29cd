#!/usr/bin/env bash
# The project's test command (README): sets up the Python reference tools in a venv, writes reference
# vectors with independent implementations (ONNX Runtime, SciPy, Pinocchio), then runs the Rust tests.
#
#   bash tests/run.sh            # everything
#   SKIP_PY=1 bash tests/run.sh  # Rust tests only (the reference-vector tests are reported as ignored)
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export FRICTIONLESS_REFS="$ROOT/target/refs"
mkdir -p "$FRICTIONLESS_REFS"

PY_PID=""
if [ -z "${SKIP_PY:-}" ]; then
  VENV="$ROOT/target/venv"
  # The log importers' tests build their .mat (h5py) and MCAP (mcap) fixtures with this interpreter.
  export FRICTIONLESS_PY="$VENV/bin/python"
  # In the background while cargo builds: neither needs the other until the tests run.
  PY_LOG="$ROOT/target/python-refs.log"
  echo "== Python reference tools and vectors (in the background; log: $PY_LOG)"
  (
    if [ ! -x "$VENV/bin/python" ]; then
      python3 -m venv "$VENV"
    fi
    "$VENV/bin/pip" install -q --disable-pip-version-check -r tests/python/requirements.txt
    for gen in tests/python/gen_*.py; do
      [ -e "$gen" ] || continue
      echo "== reference vectors: $gen"
      "$VENV/bin/python" "$gen" --out "$FRICTIONLESS_REFS"
    done
  ) > "$PY_LOG" 2>&1 &
  PY_PID=$!
  trap 'kill "$PY_PID" 2>/dev/null || true' EXIT
else
  unset FRICTIONLESS_REFS
fi

# `frictl import mat` needs the system HDF5 library (cargo feature `mat`, off by default so the first
# command needs no C library): where libhdf5-dev is installed (CI installs it), the whole run is built
# with it, so the .mat tests run in the same build instead of a second one.
FEATURES=()
if mat=$(bash tests/have-hdf5.sh); then
  read -r -a FEATURES <<< "$mat"
  echo "== with the .mat importer (system HDF5 found): ${FEATURES[*]}"
else
  echo "== skipped: .mat import tests (no system HDF5; apt install libhdf5-dev)"
fi

# One build: `cargo test --workspace --no-run` compiles every test harness and, for the end-to-end
# tests, the `frictiond` and `frictl` binaries (cargo builds a package's binaries for its integration
# tests; the frictiond tests that run `frictl` find it in target/<profile>/). A separate
# `cargo build --bins` would resolve the dependencies' features without the dev-dependencies' and
# compile most of them a second time (docs/decisions.md, "one feature resolution per build").
echo "== cargo test --no-run (test harnesses and the binaries the end-to-end tests start)"
cargo test --workspace "${FEATURES[@]}" --no-run
for bin in frictiond frictl; do
  exe="${CARGO_TARGET_DIR:-$ROOT/target}/debug/$bin"
  [ -x "$exe" ] || { echo "tests/run.sh: cargo test --no-run left no $exe" >&2; exit 1; }
done
# The frictiond the experiments and the demo in the tests start: this build's. Without it, a `frictl`
# started by a test harness inherits cargo's CARGO and CARGO_MANIFEST_DIR, takes itself for a
# `cargo run`, and builds frictiond again in the middle of the test run, with other features.
export FRICTIOND="${CARGO_TARGET_DIR:-$ROOT/target}/debug/frictiond"

if [ -n "$PY_PID" ]; then
  if ! wait "$PY_PID"; then
    cat "$PY_LOG" >&2
    echo "tests/run.sh: setting up the Python reference tools failed (log above, $PY_LOG)" >&2
    exit 1
  fi
  cat "$PY_LOG"
fi

# Tests that need this script's environment (the reference vectors, the Python fixtures, the frictl
# binary beside frictiond) are `#[ignore = "needs …"]`, so a plain `cargo test` reports them as
# ignored rather than passed; here they run with the rest. The `vcan_*` tests need a kernel with CAN
# and run in the VM (tests/canvm/run.sh).
IGNORED=(--include-ignored --skip vcan_)
if [ -z "${FRICTIONLESS_REFS:-}" ]; then
  IGNORED=()
  echo "== SKIP_PY: the tests that need the Python references stay ignored"
fi
echo "== cargo test"
cargo test --workspace "${FEATURES[@]}" --no-fail-fast -- "${IGNORED[@]}" 2>&1 | tee target/cargo-test.log
