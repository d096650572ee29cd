#!/usr/bin/env bash
# Builds the Python package and runs its tests (python/tests, pytest) — what CI calls.
#
#   bash python/ci.sh [PYTHON]          # PYTHON: the interpreter to test with (default python3, ≥ 3.9)
#
# Steps: a venv from PYTHON in <target>/venv-python (<target> = $CARGO_TARGET_DIR or ./target);
# pip installs maturin, numpy, pytest; `cargo build -p frictl -p frictiond` (debug; the tests run
# them as processes — skipped when $FRICTL and $FRICTIOND are set); `pip install ./python` (maturin,
# cargo profile $FRICTIONLESS_PY_PROFILE, default `dev` so it reuses the workspace's debug
# dependencies; `release` for benchmarking); then pytest.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(dirname "$HERE")
PY=${1:-python3}
TARGET=${CARGO_TARGET_DIR:-$ROOT/target}
VENV="$TARGET/venv-python"
PROFILE=${FRICTIONLESS_PY_PROFILE:-dev}

if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
"$VENV/bin/pip" install -q --disable-pip-version-check "maturin>=1.9,<2" numpy pytest
# Set up the venv only (CI does it in the background while other stages build).
[ -z "${PY_SETUP_ONLY:-}" ] || exit 0
# The maturin build backend runs the `maturin` executable from PATH.
export PATH="$VENV/bin:$PATH"

if [ -z "${FRICTL:-}" ] || [ -z "${FRICTIOND:-}" ]; then
  echo "== cargo build -p frictl -p frictiond (the tests start them as processes)"
  (cd "$ROOT" && cargo build -p frictl -p frictiond)
  PROFILE_DIR=debug
  export FRICTL=${FRICTL:-$TARGET/$PROFILE_DIR/frictl}
  export FRICTIOND=${FRICTIOND:-$TARGET/$PROFILE_DIR/frictiond}
fi

echo "== pip install ./python (maturin, cargo profile $PROFILE)"
MATURIN_PEP517_ARGS="--profile $PROFILE" \
  "$VENV/bin/pip" install -q --disable-pip-version-check --no-build-isolation --force-reinstall --no-deps "$HERE"

echo "== pytest python/tests"
# Run from the repository root with the venv's pytest: python/ must not be on sys.path, or the source
# package (without the compiled extension) would shadow the installed one.
cd "$ROOT"
"$VENV/bin/pytest" -q -p no:cacheprovider "$HERE/tests"
