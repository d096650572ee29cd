"""`Model`: loading, metadata, inference equal to `frictl predict`, errors with the Rust message."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

import frictionless as fl
from conftest import numpy_forward


def frictl_predict(frictl, model_path, x, tmp_path):
    csv = tmp_path / "x.csv"
    np.savetxt(csv, x, delimiter=",", fmt="%.9g")
    out = subprocess.run(
        [str(frictl), "predict", str(model_path), "--input", str(csv)],
        check=True, capture_output=True, text=True,
    ).stdout
    # frictl prints Rust's shortest round-trip f32; parsing it as float32 gives the exact value.
    return np.array([np.float32(v) for v in out.split()], dtype=np.float32), np.loadtxt(
        csv, delimiter=",", ndmin=2
    )


def test_shipped_model_info(shipped_model_path):
    m = fl.Model.load(shipped_model_path)
    i = m.info
    assert i.feature_set == "delta-theta-joint-vel"
    assert [b.name for b in i.blocks] == ["delta-theta", "joint-vel"]
    assert [b.unit for b in i.blocks] == ["motor rad", "rad/s"]
    assert i.history == 20 and not i.temperature
    assert i.n_inputs == m.n_inputs == 40
    assert i.layers == (40, 268, 215, 1)
    assert i.gear_ratio == -160.0
    assert i.dtype == "f16"
    assert i.kt_nm_per_a > 0
    assert len(i.input_labels) == 40 and i.input_labels[19].startswith("delta-theta[t]")
    assert m.kernel_path in ("avx512vnni", "avx512", "avx2fma", "portable")


@pytest.mark.parametrize("which", ["shipped", "small"])
def test_predict_equals_frictl_predict(which, shipped_model_path, small_model, frictl, tmp_path):
    if which == "shipped":
        path = shipped_model_path
    else:
        path = small_model[1]
    m = fl.Model.load(path)
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 0.5, size=(257, m.n_inputs))
    want, x_csv = frictl_predict(frictl, path, x, tmp_path)
    assert want.shape == (257,)
    got32 = m.predict(x_csv.astype(np.float32))
    got64 = m.predict(x_csv)
    assert got32.dtype == np.float32 and got32.shape == (257,)
    np.testing.assert_array_equal(got32, want)
    np.testing.assert_array_equal(got64, want)
    assert np.ptp(want) > 0, "outputs vary with the input"


def test_predict_matches_an_independent_forward(small_model):
    model, _, layers, norm = small_model
    x = np.random.default_rng(5).normal(size=(100, 20)).astype(np.float32)
    np.testing.assert_allclose(model.predict(x), numpy_forward(layers, norm, x), rtol=1e-5, atol=1e-5)


def test_predict_shapes_layouts_and_single_row(small_model):
    model = small_model[0]
    x = np.random.default_rng(6).normal(size=(10, 20))
    full = model.predict(x)
    # Non-contiguous (Fortran order, strided) and integer inputs give the same numbers.
    np.testing.assert_array_equal(model.predict(np.asfortranarray(x)), full)
    np.testing.assert_array_equal(model.predict(np.repeat(x, 2, axis=0)[::2]), full)
    np.testing.assert_array_equal(model.predict(x[3]), full[3:4])
    assert model.predict(np.zeros((0, 20))).shape == (0,)
    np.testing.assert_array_equal(model(x), full)


def test_predict_errors(small_model):
    model = small_model[0]
    with pytest.raises(ValueError, match="19 columns, the model takes 20"):
        model.predict(np.zeros((2, 19)))
    x = np.zeros((3, 20))
    x[2, 4] = np.nan
    with pytest.raises(ValueError, match="row 2, column 4"):
        model.predict(x)
    with pytest.raises(ValueError, match="2-D"):
        model.predict(np.zeros((2, 2, 20)))


def test_load_errors_carry_the_rust_message(tmp_path, small_model):
    with pytest.raises(fl.WeightFileError, match="missing.fwt"):
        fl.Model.load(tmp_path / "missing.fwt")
    bad = tmp_path / "bad.fwt"
    bad.write_bytes(b"not a weight file" * 30)
    with pytest.raises(fl.WeightFileError, match="magic"):
        fl.Model.load(bad)
    data = bytearray(small_model[0].to_bytes())
    data[-1] ^= 0xFF
    with pytest.raises(fl.WeightFileError, match="(?i)crc"):
        fl.Model.from_bytes(bytes(data))
    assert issubclass(fl.WeightFileError, fl.FrictionlessError)


def test_bytes_round_trip(small_model):
    model = small_model[0]
    b = model.to_bytes()
    again = fl.Model.from_bytes(b)
    assert again.to_bytes() == b
    assert repr(again.info) == repr(model.info)  # repr: NaN RMSEs compare unequal


def test_predict_from_threads(shipped_model_path):
    # Several threads on one model give the same results as one thread (they take turns on the
    # kernel's scratch; the GIL is released while the kernel runs).
    import concurrent.futures

    m = fl.Model.load(shipped_model_path)
    xs = [np.random.default_rng(k).normal(size=(2000, 40)).astype(np.float32) for k in range(4)]
    want = [m.predict(x) for x in xs]
    with concurrent.futures.ThreadPoolExecutor(4) as ex:
        got = list(ex.map(m.predict, xs))
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)


def test_predict_releases_the_gil(shipped_model_path):
    # While a worker thread is inside predict, this thread keeps waking up (each wake-up needs the
    # GIL); if predict held the GIL, the wake-ups would wait for it to return.
    import threading

    m = fl.Model.load(shipped_model_path)
    x = np.random.default_rng(0).normal(size=(50_000, 40)).astype(np.float32)
    started, done = threading.Event(), threading.Event()

    def work():
        started.set()
        m.predict(x)
        done.set()

    t = threading.Thread(target=work)
    t.start()
    started.wait()
    wakeups = 0
    while not done.wait(0.001):
        wakeups += 1
    t.join()
    assert wakeups >= 5, wakeups
