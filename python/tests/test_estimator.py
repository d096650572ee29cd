"""`Estimator` sample by sample equals `Model.predict` on windows built independently in NumPy, with
frictiond's enable semantics (Δθ latched at the first sample after a reset, warm-up policies)."""

from __future__ import annotations

import numpy as np
import pytest

import frictionless as fl
from conftest import random_layers

R = -100.0


def motion(n, seed=0):
    t = np.arange(n) * 1e-3
    s = 0.3 * np.sin(3 * t + seed)
    sdot = 0.9 * np.cos(3 * t + seed)
    theta = R * s + 0.02 * np.sin(7 * t) + 1.5
    omega = R * sdot + 0.14 * np.cos(7 * t)
    temp = 40.0 + 0.01 * np.arange(n)
    return s, sdot, theta, omega, temp


def windows(blocks, h, start, end, temperature=None, pad=False):
    """Rows for ticks start..end-1 of the block series (each already in its unit), block-major,
    oldest → newest; ticks before `start` read as 0 when `pad` (history since the enable only)."""
    rows = []
    for t in range(start, end):
        row = []
        for series in blocks:
            w = np.zeros(h)
            lo = max(start, t - h + 1)
            seg = series[lo : t + 1]
            w[h - len(seg) :] = seg
            row.append(w)
        if temperature is not None:
            row.append([temperature[t]])
        rows.append(np.concatenate(row))
    return np.asarray(rows)


def delta_theta(s, theta, at):
    """Δθ = r·s − (θ − θ_off), θ_off = θ − r·s latched at sample `at` (the core's operation order)."""
    off = theta[at] - R * s[at]
    return R * s - (theta - off)


@pytest.fixture
def model(small_model):
    return small_model[0]


def test_hold_zero_equals_predict_on_full_windows(model):
    h = model.info.history
    s, sdot, theta, omega, _ = motion(300)
    est = fl.Estimator(model)
    assert est.warmup == "hold_zero" and not est.warm and est.estimate() == 0.0
    got = np.array([est.push(*x) for x in zip(s, sdot, theta, omega)])
    dth = delta_theta(s, theta, 0).astype(np.float32)
    x = windows([dth, sdot.astype(np.float32)], h, 0, 300)
    want = model.predict(x.astype(np.float32))
    assert np.all(got[: h - 1] == 0.0), "hold_zero: no estimate before H samples"
    np.testing.assert_array_equal(got[h - 1 :], want[h - 1 :].astype(np.float64))
    assert est.warm and est.ready and est.n_samples == h
    assert est.estimate() == got[-1]
    np.testing.assert_array_equal(est.last_input(), x[-1].astype(np.float32))
    assert np.ptp(got[h:]) > 0


def test_zero_pad_warm_flag_and_reset_relatches(model):
    h = model.info.history
    s, sdot, theta, omega, _ = motion(120, seed=1)
    est = fl.Estimator(model, warmup="zero_pad")
    got, warm = [], []
    for k in range(60):
        got.append(est.push(s[k], sdot[k], theta[k], omega[k]))
        warm.append(est.warm)
    assert warm == [False] * (h - 1) + [True] * (60 - h + 1)
    dth = delta_theta(s, theta, 0).astype(np.float32)
    want = model.predict(windows([dth, sdot.astype(np.float32)], h, 0, 60).astype(np.float32))
    np.testing.assert_array_equal(np.array(got), want.astype(np.float64))

    # Disable at 60, enable at 80: history restarts and Δθ is latched again at sample 80.
    est.reset()
    assert not est.warm and est.n_samples == 0 and est.estimate() == 0.0
    got2 = [est.push(s[k], sdot[k], theta[k], omega[k]) for k in range(80, 120)]
    dth2 = delta_theta(s, theta, 80).astype(np.float32)
    want2 = model.predict(
        windows([dth2, sdot.astype(np.float32)], h, 80, 120, pad=True).astype(np.float32)
    )
    np.testing.assert_array_equal(np.array(got2), want2.astype(np.float64))
    assert est.delta_theta_offset_motor_rad == pytest.approx(theta[80] - R * s[80])


def test_fixed_offset_is_not_relatched(model):
    h = model.info.history
    s, sdot, theta, omega, _ = motion(80, seed=2)
    est = fl.Estimator(model, delta_theta_offset_motor_rad=1.5)
    for k in range(40):
        est.push(s[k], sdot[k], theta[k], omega[k])
    est.reset()
    got = [est.push(s[k], sdot[k], theta[k], omega[k]) for k in range(40, 80)]
    dth = (R * s - (theta - 1.5)).astype(np.float32)
    want = model.predict(windows([dth, sdot.astype(np.float32)], h, 40, 80, pad=True).astype(np.float32))
    np.testing.assert_array_equal(np.array(got[h - 1 :]), want[h - 1 :].astype(np.float64))
    assert est.delta_theta_offset_motor_rad == 1.5


def test_generic_feature_set_with_temperature(tmp_path):
    # [ω_m ×H, ṡ ×H, T]: blocks taken from model.info, not hard-coded per set.
    h = 6
    layers = random_layers([2 * h + 1, 10, 1], seed=9, amp=0.05)
    m = fl.write_fwt(tmp_path / "mv.fwt", layers, features="motor-vel-joint-vel", temperature=True,
                     gear_ratio=R, kt=0.1)
    assert [b.name for b in m.info.blocks] == ["motor-vel", "joint-vel"]
    s, sdot, theta, omega, temp = motion(50, seed=3)
    est = fl.Estimator(m)
    got = [est.push(*x) for x in zip(s, sdot, theta, omega, temp)]
    x = windows([omega.astype(np.float32), sdot.astype(np.float32)], h, 0, 50,
                temperature=temp.astype(np.float32))
    want = m.predict(x.astype(np.float32))
    np.testing.assert_array_equal(np.array(got[h - 1 :]), want[h - 1 :].astype(np.float64))


def test_bad_arguments(model):
    with pytest.raises(ValueError, match="warmup"):
        fl.Estimator(model, warmup="later")
    with pytest.raises(ValueError, match="not finite"):
        fl.Estimator(model, delta_theta_offset_motor_rad=float("nan"))
