#!/usr/bin/env python3
"""Reference vectors for frictl's Butterworth / sosfilt / sosfiltfilt (tools/ident/src/filter.rs).

Writes DIR/scipy_filters.json: a list of cases, each with the design (order, cutoff_hz, fs_hz), scipy's
sos matrix, a seeded random input signal and scipy.signal.sosfilt / sosfiltfilt outputs.
Usage: gen_scipy_refs.py --out DIR
"""
import argparse
import json
import os

import numpy as np
import scipy
import scipy.signal as sig

CASES = [
    # (order, cutoff_hz, fs_hz, n_samples) — first is the label pipeline default.
    (5, 100.0, 1000.0, 3000),
    (1, 30.0, 1000.0, 500),
    (2, 10.0, 500.0, 1000),
    (3, 200.0, 1000.0, 800),
    (4, 50.0, 500.0, 1200),
    (6, 5.0, 1000.0, 4000),
    (7, 120.0, 1000.0, 2000),
    (5, 100.0, 1000.0, 19),  # shortest signal accepted with the default padlen 18
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(20240917)
    cases = []
    for order, fc, fs, n in CASES:
        sos = sig.butter(order, fc, fs=fs, output="sos")
        t = np.arange(n) / fs
        x = rng.normal(0.0, 1.0, n) + 3.0 * np.sin(2 * np.pi * 2.0 * t) + 1.5
        cases.append(
            {
                "order": order,
                "cutoff_hz": fc,
                "fs_hz": fs,
                "sos": sos.tolist(),
                "x": x.tolist(),
                "sosfilt": sig.sosfilt(sos, x).tolist(),
                "sosfiltfilt": sig.sosfiltfilt(sos, x).tolist(),
                "sosfilt_zi": sig.sosfilt_zi(sos).tolist(),
            }
        )
    out = {"generator": "gen_scipy_refs.py", "scipy": scipy.__version__, "cases": cases}
    path = os.path.join(args.out, "scipy_filters.json")
    with open(path, "w") as f:
        json.dump(out, f)
    print(f"wrote {path} ({len(cases)} cases)")


if __name__ == "__main__":
    main()
