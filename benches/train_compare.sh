#!/usr/bin/env bash
# Training throughput: the hand-written trainer (tools/train/benches/train.rs) against PyTorch CPU
# (benches/train_vs_pytorch.py) on the same workload in the same run: 200k x 40 synthetic friction
# samples, 268/215 hidden, batch 4096, dropout 0.1, Adam lr 1e-3, lambda 0.1, 2 threads each.
#
#   bash benches/train_compare.sh                 # 5 epochs each (the first is a warm-up), 1 round
#   EPOCHS=10 ROUNDS=3 bash benches/train_compare.sh
#
# ROUNDS > 1 alternates frictl / PyTorch and reports the median per engine, so a load spike hits both.
# Prints per engine the median epoch wall time and CPU time (all threads), the throughput ratio
# (> 1: frictl faster) by wall and by CPU time, and the projection to the paper-size run (350 epochs
# over 300k samples; the project's target is <= 6 min and >= 1.5x PyTorch; results in
# docs/performance.md). On a loaded machine trust the
# CPU-time ratio more: wall time then measures the scheduler.
#
# Fresh machine: needs python3 with venv (Debian: apt-get install python3-venv) and PyPI access. torch
# and numpy are installed into target/venv (the tests' venv) if missing. PyPI's Linux torch wheel pulls
# the CUDA libraries (several GB); only its CPU path runs here. TORCH_SPEC pins a version, e.g.
# TORCH_SPEC='torch==2.15.0'.
set -euo pipefail
cd "$(dirname "$0")/.."
EPOCHS=${EPOCHS:-5}
ROUNDS=${ROUNDS:-1}
THREADS=${THREADS:-2}
VENV=${VENV:-target/venv}
TORCH_SPEC=${TORCH_SPEC:-torch}

if [ ! -x "$VENV/bin/python" ]; then
  if ! python3 -m venv "$VENV"; then
    echo "cannot create $VENV: install python3-venv (Debian: apt-get install -y python3-venv)" >&2
    exit 1
  fi
fi
if ! "$VENV/bin/python" -c 'import torch, numpy' 2>/dev/null; then
  echo "== installing $TORCH_SPEC and numpy into $VENV (PyPI)"
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check "$TORCH_SPEC" numpy
fi

echo "== building the frictl bench (release)"
cargo bench -q -p frictionless-train --bench train --no-run

export RAYON_NUM_THREADS=$THREADS OMP_NUM_THREADS=$THREADS MKL_NUM_THREADS=$THREADS
echo "== machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')"
echo "== load average before: $(cut -d' ' -f1-3 /proc/loadavg)"

rust_wall=() rust_cpu=() py_wall=() py_cpu=()
for round in $(seq 1 "$ROUNDS"); do
  echo "== round $round/$ROUNDS: frictl (hand-written trainer on gemm), $THREADS threads"
  out=$(FRICTL_BENCH_EPOCHS=$EPOCHS FRICTL_BENCH_THREADS=$THREADS cargo bench -q -p frictionless-train --bench train)
  echo "$out"
  rust_wall+=("$(sed -n 's/^FRICTL_EPOCH_S=//p' <<<"$out")")
  rust_cpu+=("$(sed -n 's/^FRICTL_EPOCH_CPU_S=//p' <<<"$out")")

  echo "== round $round/$ROUNDS: PyTorch CPU, $THREADS threads"
  out=$("$VENV/bin/python" benches/train_vs_pytorch.py --epochs "$EPOCHS" --threads "$THREADS")
  echo "$out"
  py_wall+=("$(sed -n 's/^PYTORCH_EPOCH_S=//p' <<<"$out")")
  py_cpu+=("$(sed -n 's/^PYTORCH_EPOCH_CPU_S=//p' <<<"$out")")
done
echo "== load average after: $(cut -d' ' -f1-3 /proc/loadavg)"

python3 - "${rust_wall[*]}" "${rust_cpu[*]}" "${py_wall[*]}" "${py_cpu[*]}" <<'EOF'
import statistics
import sys

rw, rc, pw, pc = ([float(x) for x in a.split()] for a in sys.argv[1:5])
r, p = statistics.median(rw), statistics.median(pw)
r_cpu, p_cpu = statistics.median(rc), statistics.median(pc)
paper = 350 * 1.5 / 60  # minutes per (s/epoch at 200k): 350 epochs over 300k samples
print("== summary (median over rounds; 200k-sample epochs)")
print(f"frictl : {r:.3f} s/epoch wall, {r_cpu:.3f} s/epoch CPU")
print(f"PyTorch: {p:.3f} s/epoch wall, {p_cpu:.3f} s/epoch CPU")
print(f"frictl throughput = {p / r:.2f}x PyTorch by wall time, {p_cpu / r_cpu:.2f}x by CPU time (target >= 1.5x)")
print(f"paper-size run (350 epochs x 300k samples): frictl {r * paper:.1f} min, PyTorch {p * paper:.1f} min (target <= 6 min)")
EOF
