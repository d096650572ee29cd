"""Shared fixtures: the repository's binaries (`frictl`, `frictiond`), shipped models and small random
networks written with `frictionless.write_fwt`.

Binaries: `$FRICTL` / `$FRICTIOND` if set, else `<target>/debug/<name>` (target = `$CARGO_TARGET_DIR`
or `<repo>/target`), built with `cargo build -p <package>` when missing.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import frictionless as fl

REPO = Path(__file__).resolve().parents[2]


def _binary(env: str, name: str, package: str) -> Path:
    if os.environ.get(env):
        p = Path(os.environ[env])
        assert p.is_file(), f"${env} = {p} does not exist"
        return p
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    p = target / "debug" / name
    if not p.is_file():
        cargo = shutil.which("cargo")
        if cargo is None:
            pytest.skip(f"{name}: set ${env} or install cargo")
        subprocess.run([cargo, "build", "-p", package, "--bin", name], cwd=REPO, check=True)
    assert p.is_file(), f"cargo build did not produce {p}"
    return p


@pytest.fixture(scope="session")
def frictl() -> Path:
    return _binary("FRICTL", "frictl", "frictl")


@pytest.fixture(scope="session")
def frictiond() -> Path:
    return _binary("FRICTIOND", "frictiond", "frictiond")


@pytest.fixture(scope="session")
def shipped_model_path() -> Path:
    """A shipped paper-size network: 40 → 268 → 215 → 1, [Δθ ×20, ṡ ×20], f16, r = −160."""
    return REPO / "config" / "models" / "stress32_paper_f16_r-160.fwt"


def random_layers(sizes, seed, amp=0.5):
    """Random (W, b) pairs for layer sizes, e.g. [20, 16, 12, 1]; W is (n_out, n_in)."""
    rng = np.random.default_rng(seed)
    return [
        (
            rng.uniform(-amp, amp, size=(n_out, n_in)).astype(np.float32),
            rng.uniform(-0.2, 0.2, size=n_out).astype(np.float32),
        )
        for n_in, n_out in zip(sizes[:-1], sizes[1:])
    ]


def numpy_forward(layers, norm, x):
    """Independent float64 reference of the MLP: normalise, ReLU hidden layers, linear output."""
    h = np.asarray(x, dtype=np.float64)
    if norm is not None:
        h = (h - np.asarray(norm[0], np.float64)) / np.asarray(norm[1], np.float64)
    for k, (w, b) in enumerate(layers):
        h = h @ np.asarray(w, np.float64).T + np.asarray(b, np.float64)
        if k + 1 < len(layers):
            h = np.maximum(h, 0.0)
    return h[:, 0]


@pytest.fixture
def small_model(tmp_path):
    """A random [Δθ ×10, ṡ ×10] → 16 → 12 → 1 f32 network with a normalisation, r = −100."""
    layers = random_layers([20, 16, 12, 1], seed=7)
    rng = np.random.default_rng(8)
    norm = (
        rng.normal(0, 0.1, 20).astype(np.float32),
        rng.uniform(0.5, 2.0, 20).astype(np.float32),
    )
    path = tmp_path / "small.fwt"
    model = fl.write_fwt(
        path, layers, norm=norm, joint="knee", gear_ratio=-100.0, kt=0.157, created_unix_s=1
    )
    return model, path, layers, norm
