#!/usr/bin/env bash
# ONNX Runtime vs the hand-written kernel (single sample, one thread), in one run:
#   1. a Python venv in target/venv with onnxruntime (its wheel ships libonnxruntime.so), onnx, numpy;
#   2. benches/make_paper_onnx.py writes the paper-size random model as ONNX + raw weights and extracts
#      the real ergoCub model's weights to a raw file (target/ort-bench/);
#   3. cargo bench --features ort-bench --bench inference -- ^ort  (prints agreement, p50/p99, ratio).
# Extra arguments replace the bench filter (e.g. `bash benches/ort_compare.sh .` runs every bench).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV="$ROOT/target/venv"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/python" -c "import onnxruntime, onnx, numpy" 2>/dev/null \
  || "$VENV/bin/pip" install -q --disable-pip-version-check onnxruntime onnx numpy
ORT_PKG=$("$VENV/bin/python" -c "import onnxruntime,os;print(os.path.dirname(onnxruntime.__file__))")
LIB=$(ls "$ORT_PKG"/capi/libonnxruntime.so* | sort | tail -n 1)
echo "== ONNX Runtime $("$VENV/bin/python" -c "import onnxruntime;print(onnxruntime.__version__)"): $LIB"
export ORT_DYLIB_PATH="$LIB"
export FRICTIONLESS_ORT_DIR="$ROOT/target/ort-bench"
"$VENV/bin/python" benches/make_paper_onnx.py --out "$FRICTIONLESS_ORT_DIR" \
  --ergocub "$ROOT/tests/fixtures/ergocub/blf_jtc_ergoCubSN002_l_ankle_roll_pinn_2024-06.onnx"
FILTER=("${@:-^ort}")
cargo bench -p frictionless --features ort-bench --bench inference -- "${FILTER[@]}"
