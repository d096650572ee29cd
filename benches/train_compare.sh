#!/usr/bin/env bash
# Compares training throughput of the hand-written trainer (tools/benches/train.rs) with PyTorch CPU
# (benches/train_vs_pytorch.py) on the same workload, 2 threads each, run one after the other.
#
#   bash benches/train_compare.sh            # 5 epochs each (first is warm-up)
#   EPOCHS=10 bash benches/train_compare.sh
#
# Installs torch from PyPI into target/venv if missing (large download: the PyPI wheel pulls CUDA
# libraries, though only the CPU path is used here).
set -euo pipefail
cd "$(dirname "$0")/.."
EPOCHS=${EPOCHS:-5}
VENV=target/venv
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
if ! "$VENV/bin/python" -c 'import torch, numpy' 2>/dev/null; then
  "$VENV/bin/pip" install -q --disable-pip-version-check torch numpy
fi
export RAYON_NUM_THREADS=2 OMP_NUM_THREADS=2

echo "== frictl (hand-written trainer on gemm)"
rust_out=$(FRICTL_BENCH_EPOCHS=$EPOCHS FRICTL_BENCH_THREADS=2 cargo bench -q -p frictl --bench train)
echo "$rust_out"
rust=$(sed -n 's/^FRICTL_EPOCH_S=//p' <<<"$rust_out")

echo "== PyTorch CPU"
py_out=$("$VENV/bin/python" benches/train_vs_pytorch.py --epochs "$EPOCHS" --threads 2)
echo "$py_out"
py=$(sed -n 's/^PYTORCH_EPOCH_S=//p' <<<"$py_out")

python3 -c "r, p = float('$rust'), float('$py'); print(f'frictl {r:.3f} s/epoch, PyTorch {p:.3f} s/epoch: frictl throughput = {p / r:.2f}x PyTorch')"
