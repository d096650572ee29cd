"""`write_fwt` / `fwt_bytes`: NumPy weights → `.fwt` → `Model.load`, metadata and values preserved."""

from __future__ import annotations

import math

import numpy as np
import pytest

import frictionless as fl
from conftest import numpy_forward, random_layers


def test_round_trip_f32_is_exact(small_model):
    model, path, layers, norm = small_model
    loaded = fl.Model.load(path)
    got_layers, (mean, scale) = loaded.weights()
    assert len(got_layers) == len(layers)
    for (w, b), (w0, b0) in zip(got_layers, layers):
        assert w.shape == w0.shape and w.dtype == np.float32
        np.testing.assert_array_equal(w, w0)
        np.testing.assert_array_equal(b, b0)
    np.testing.assert_array_equal(mean, norm[0])
    np.testing.assert_array_equal(scale, norm[1])
    i = loaded.info
    assert (i.joint, i.gear_ratio, i.kt_nm_per_a) == ("knee", -100.0, 0.157)
    assert (i.feature_set, i.history, i.temperature) == ("delta-theta-joint-vel", 10, False)
    assert i.layers == (20, 16, 12, 1) and i.dtype == "f32"
    assert i.created_unix_s == 1 and i.tool_version.startswith("frictionless-py")
    assert i.scv_prior is None and math.isnan(i.val_rmse_nm)
    x = np.random.default_rng(1).normal(size=(64, 20))
    np.testing.assert_array_equal(loaded.predict(x), model.predict(x))


@pytest.mark.parametrize("dtype,half", [("f16", np.float16), ("bf16", None)])
def test_round_trip_reduced_precision_rounds_weights(dtype, half, tmp_path):
    layers = random_layers([40, 32, 1], seed=11)
    path = tmp_path / f"m_{dtype}.fwt"
    fl.write_fwt(path, layers, gear_ratio=160.0, kt=0.0665, dtype=dtype, joint="ankle_roll")
    m = fl.Model.load(path)
    assert m.info.dtype == dtype and m.info.history == 20
    w, b = m.weights()[0][0]
    if half is not None:
        np.testing.assert_array_equal(w, layers[0][0].astype(half).astype(np.float32))
    else:
        # bfloat16 keeps the top 16 bits (round to nearest even): within 2^-8 relative.
        np.testing.assert_allclose(w, layers[0][0], rtol=2.0**-8)
        assert not np.array_equal(w, layers[0][0])
    # Biases are stored in the dtype too; the normalisation stays f32.
    if half is not None:
        np.testing.assert_array_equal(b, layers[0][1].astype(half).astype(np.float32))
    else:
        np.testing.assert_allclose(b, layers[0][1], rtol=2.0**-8)
    x = np.random.default_rng(2).normal(size=(50, 40))
    rounded = [(wr, br) for wr, br in m.weights()[0]]
    np.testing.assert_allclose(m.predict(x), numpy_forward(rounded, None, x), rtol=1e-5, atol=1e-5)


def test_int16_quantises_hidden_rows_per_channel(tmp_path):
    """int16: hidden weights within half a step of max |w| / 8191 per output row, biases and the output
    layer f32, and predictions within the 15-bit activations' error of the dequantised model."""
    layers = random_layers([40, 32, 24, 1], seed=12)
    path = tmp_path / "m_int16.fwt"
    fl.write_fwt(path, layers, gear_ratio=160.0, kt=0.0665, dtype="int16", joint="ankle_roll")
    m = fl.Model.load(path)
    assert m.info.dtype == "int16"
    got = m.weights()[0]
    for k, ((w, b), (w0, b0)) in enumerate(zip(got, layers)):
        np.testing.assert_array_equal(b, b0.astype(np.float32))
        if k == len(layers) - 1:
            np.testing.assert_array_equal(w, w0.astype(np.float32))
            continue
        step = np.abs(w0).max(axis=1, keepdims=True) / 8191.0
        assert np.all(np.abs(w - w0) <= 0.5 * step + 4 * np.finfo(np.float32).eps * np.abs(w0))
        assert not np.array_equal(w, w0.astype(np.float32))
    x = np.random.default_rng(3).normal(size=(50, 40))
    want = numpy_forward(got, None, x)
    np.testing.assert_allclose(m.predict(x), want, rtol=1e-3, atol=1e-3 * np.abs(want).max())


def test_metadata_options_and_inferred_history(tmp_path):
    sets = fl.feature_sets()
    assert "delta-theta-joint-vel" in sets and "motor-vel-joint-vel" in sets
    assert sets["motor-vel-joint-vel"][0] == fl.FeatureBlock("motor-vel", "motor rad/s")
    prior = dict(kc=8.1, ka=50.0, kv=5.5, ks=9.0, vs=0.1, alpha=2.0)
    layers = random_layers([2 * 7 + 1, 8, 1], seed=3)
    m = fl.write_fwt(
        tmp_path / "t.fwt", layers, features="motor-vel-joint-vel", temperature=True,
        joint="hip", gear_ratio=-50.0, kt=0.1, scv_prior=prior, val_rmse_nm=0.5,
        test_rmse_nm=0.75, filtering="causal", created_unix_s=1700000000, tool_version="my trainer",
    )
    i = fl.Model.load(tmp_path / "t.fwt").info
    assert i == m.info
    assert (i.history, i.temperature, i.n_inputs) == (7, True, 15)
    assert i.input_labels[-1].startswith("motor_temperature")
    assert i.scv_prior == pytest.approx(prior)
    assert (i.val_rmse_nm, i.test_rmse_nm, i.filtering) == (0.5, 0.75, "causal")
    assert (i.created_unix_s, i.tool_version) == (1700000000, "my trainer")


def test_torch_like_tensors_are_accepted(tmp_path):
    class FakeTensor:
        """What write_fwt needs of a torch tensor: detach().cpu().numpy()."""

        def __init__(self, a):
            self.a = a

        def detach(self):
            return self

        def cpu(self):
            return self

        def numpy(self):
            return self.a

    layers = random_layers([20, 4, 1], seed=4)
    m = fl.write_fwt(tmp_path / "t.fwt", [(FakeTensor(w), FakeTensor(b)) for w, b in layers],
                     gear_ratio=100.0, kt=0.1)
    np.testing.assert_array_equal(m.weights()[0][0][0], layers[0][0])


def test_invalid_models_are_refused_with_the_rust_message(tmp_path):
    good = random_layers([20, 8, 1], seed=5)
    with pytest.raises(fl.WeightFileError, match="layer 1"):
        fl.fwt_bytes([good[0], random_layers([7, 1], seed=1)[0]], gear_ratio=100.0, kt=0.1)
    nan = [(good[0][0].copy(), good[0][1]), good[1]]
    nan[0][0][3, 2] = np.nan
    with pytest.raises(fl.WeightFileError, match="not finite"):
        fl.fwt_bytes(nan, gear_ratio=100.0, kt=0.1)
    with pytest.raises(fl.WeightFileError, match="gear_ratio"):
        fl.fwt_bytes(good, gear_ratio=0.0, kt=0.1)
    with pytest.raises(ValueError, match="feature set `nope`"):
        fl.fwt_bytes(good, features="nope", gear_ratio=100.0, kt=0.1)
    with pytest.raises(ValueError, match="dtype"):
        fl.fwt_bytes(good, dtype="f8", gear_ratio=100.0, kt=0.1)
    with pytest.raises(ValueError, match="do not split"):
        fl.fwt_bytes(random_layers([21, 1], seed=1), gear_ratio=100.0, kt=0.1)
    assert not (tmp_path / "x.fwt").exists()
