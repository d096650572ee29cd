#!/usr/bin/env bash
# The Ray driver's tests (python/ray/tests/) on a real local Ray cluster: builds frictl and frictiond
# (unless $FRICTL and $FRICTIOND name them),
# makes (or reuses) a venv with the pinned `ray` and `pytest`, runs pytest.
#
#   bash tests/ray/run.sh                 # venv in target/venv-ray
#   RAY_VENV=/path/to/venv bash tests/ray/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$(pwd)
VENV="${RAY_VENV:-$ROOT/target/venv-ray}"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/pip" install -q --disable-pip-version-check -r python/ray/requirements.txt
# Set up the venv only (CI does it in the background while other stages build).
[ -z "${RAY_SETUP_ONLY:-}" ] || exit 0

# $FRICTL and $FRICTIOND, when both are set, name binaries already built (CI passes those of
# tests/run.sh); otherwise they are built here.
if [ -z "${FRICTL:-}" ] || [ -z "${FRICTIOND:-}" ]; then
  echo "== cargo build -p frictl -p frictiond"
  cargo build -p frictl -p frictiond
  TARGET_DIR=$(cargo metadata --format-version 1 --no-deps | "$VENV/bin/python" -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])')
  export FRICTL="$TARGET_DIR/debug/frictl" FRICTIOND="$TARGET_DIR/debug/frictiond"
fi
export RAY_USAGE_STATS_ENABLED=0

echo "== pytest python/ray/tests"
"$VENV/bin/python" -m pytest -q python/ray/tests "$@"
