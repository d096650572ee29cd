"""Batch inference: `frictionless.Model.predict` vs ONNX Runtime (1 thread) on the same network.

    python python/bench/predict_vs_onnxruntime.py [--n 100000] [--repeats 15] [--frictl PATH]

The network is paper size (40 → 268 → 215 → 1, inputs [Δθ ×20, ṡ ×20]) with seeded random f32
weights, written with `frictionless.write_fwt` and exported with `frictl export onnx` (so both run the
same weights). ONNX Runtime runs with `intra_op_num_threads = inter_op_num_threads = 1` and sequential
execution; `predict` is single-threaded by construction. Each side runs the whole batch `--repeats`
times after a warm-up (the two sides alternate); the script prints the median wall time per batch and
per window, the per-call time for batches of 1 and 100 windows, the largest output difference, and
(for the per-tick path) the median cost of `Estimator.push` called from Python.
Needs: numpy, onnxruntime, the built extension, and `frictl` ($FRICTL, --frictl, or on PATH /
target/{release,debug}).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import frictionless as fl

REPO = Path(__file__).resolve().parents[2]


def find_frictl(arg):
    cands = [arg, os.environ.get("FRICTL"), shutil.which("frictl")]
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    cands += [str(target / "release" / "frictl"), str(target / "debug" / "frictl")]
    for c in cands:
        if c and Path(c).is_file():
            return c
    sys.exit("frictl not found: build it (cargo build -p frictl) or pass --frictl / $FRICTL")


def medians_s(fs, repeats):
    """Median wall time of each callable; the callables alternate so load drifts hit both alike."""
    for f in fs:
        f()  # warm-up
    times = [[] for _ in fs]
    for _ in range(repeats):
        for f, t in zip(fs, times):
            t0 = time.perf_counter()
            f()
            t.append(time.perf_counter() - t0)
    return [statistics.median(t) for t in times]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000, help="windows per batch")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--frictl")
    args = ap.parse_args()

    import onnxruntime as ort

    rng = np.random.default_rng(0)
    sizes = [40, 268, 215, 1]
    layers = [
        (rng.uniform(-1, 1, (o, i)).astype(np.float32) / np.sqrt(i),
         rng.uniform(-0.1, 0.1, o).astype(np.float32))
        for i, o in zip(sizes[:-1], sizes[1:])
    ]
    norm = (rng.normal(0, 0.01, 40).astype(np.float32), rng.uniform(0.02, 0.5, 40).astype(np.float32))
    x = rng.normal(0, 0.1, (args.n, 40)).astype(np.float32)

    with tempfile.TemporaryDirectory() as d:
        fwt = Path(d) / "paper.fwt"
        onnx_path = Path(d) / "paper.onnx"
        model = fl.write_fwt(fwt, layers, norm=norm, gear_ratio=-160.0, kt=0.0665, joint="bench")
        subprocess.run([find_frictl(args.frictl), "export", "onnx", str(fwt), "-o", str(onnx_path)],
                       check=True, stdout=subprocess.DEVNULL)
        so = ort.SessionOptions()
        so.intra_op_num_threads = 1
        so.inter_op_num_threads = 1
        so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        sess = ort.InferenceSession(str(onnx_path), so, providers=["CPUExecutionProvider"])
        inp = sess.get_inputs()[0].name

        y_fl = model.predict(x)
        y_ort = sess.run(None, {inp: x})[0].reshape(-1)
        t_fl, t_ort = medians_s(
            [lambda: model.predict(x), lambda: sess.run(None, {inp: x})], args.repeats
        )
        # Small batches: per-call overhead (one window is what a control tick asks for).
        small = {}
        for b in (1, 100):
            xb = x[:b]
            reps = 2000 // b
            def fl_calls():
                for _ in range(reps):
                    model.predict(xb)
            def ort_calls():
                for _ in range(reps):
                    sess.run(None, {inp: xb})
            tf, to = medians_s([fl_calls, ort_calls], args.repeats)
            small[b] = (tf / reps, to / reps)

        est = fl.Estimator(model)
        s = rng.normal(0, 0.1, 20_000)
        pushes = []
        for _ in range(5):
            t0 = time.perf_counter()
            for v in s:
                est.push(v, v, -160.0 * v, -160.0 * v)
            pushes.append((time.perf_counter() - t0) / s.size)

    print(f"paper-size MLP 40-268-215-1 f32, {args.n} windows, median of {args.repeats}, 1 thread")
    print(f"kernel path: {model.kernel_path}; onnxruntime {ort.__version__}")
    print(f"frictionless Model.predict : {t_fl * 1e3:8.1f} ms/batch  {t_fl / args.n * 1e9:7.0f} ns/window")
    print(f"onnxruntime  (1 thread)    : {t_ort * 1e3:8.1f} ms/batch  {t_ort / args.n * 1e9:7.0f} ns/window")
    print(f"ratio onnxruntime/frictionless: {t_ort / t_fl:.2f}")
    for b, (tf, to) in small.items():
        print(f"batch {b:>3}: frictionless {tf * 1e6:8.1f} µs/call, onnxruntime {to * 1e6:8.1f} µs/call, "
              f"ratio {to / tf:.2f}")
    print(f"max |difference| [Nm]: {float(np.max(np.abs(y_fl - y_ort))):.3g}")
    print(f"Estimator.push (one sample, from Python): {statistics.median(pushes) * 1e9:.0f} ns")


if __name__ == "__main__":
    main()
