"""CV / SCV fits on arrays (the fitter of `frictl fit`) recover known parameters."""

from __future__ import annotations

import json

import numpy as np
import pytest

import frictionless as fl


def cv_ref(p, v):
    """Independent reference: τ = kc·tanh(ka·v) + kv·v."""
    return p["kc"] * np.tanh(p["ka"] * v) + p["kv"] * v


def scv_ref(p, v):
    """Independent reference of the paper's SCV."""
    return p["kv"] * v + (p["kc"] + (p["ks"] - p["kc"]) * np.exp(-np.abs(v / p["vs"]) ** p["alpha"])) * np.tanh(p["ka"] * v)


def test_fit_cv_recovers_parameters():
    truth = dict(kc=8.1, ka=50.0, kv=5.55)
    rng = np.random.default_rng(0)
    v = rng.uniform(-2.0, 2.0, 20000)
    tau = cv_ref(truth, v) + rng.normal(0.0, 0.05, v.size)
    r = fl.fit_cv(v, tau)
    assert r.model == "Cv" and r.param_names == ("kc", "ka", "kv")
    assert r.params["kc"] == pytest.approx(truth["kc"], rel=0.01)
    assert r.params["kv"] == pytest.approx(truth["kv"], rel=0.01)
    assert r.params["ka"] == pytest.approx(truth["ka"], rel=0.1)
    assert r.rmse_fitted_nm == pytest.approx(0.05, rel=0.1)
    assert r.at_bounds == ()
    assert r.sliding_quadrants and r.v_min_rad_s == 0.03
    # Only sliding samples with friction opposing motion were fitted.
    assert r.n_samples == int(np.sum((np.abs(v) > 0.03) & (v * tau > 0)))
    np.testing.assert_allclose(r.torque(v), cv_ref(r.params, v), rtol=1e-12, atol=1e-12)
    # The JSON `frictl fit --json` readers take: `model` and `params`.
    j = json.loads(json.dumps(r.to_json()))
    assert j["model"] == "Cv" and set(j["params"]) == {"kc", "ka", "kv"}


def test_fit_scv_recovers_parameters():
    truth = dict(kc=5.0, ka=80.0, kv=2.0, ks=9.0, vs=0.15, alpha=1.5)
    v = np.concatenate([np.linspace(-1.5, -0.031, 4000), np.linspace(0.031, 1.5, 4000)])
    tau = scv_ref(truth, v) + np.where(np.arange(v.size) % 2 == 0, 0.02, -0.02)
    r = fl.fit_scv(v, tau)
    assert r.model == "Scv"
    for k in ("kc", "kv", "ks"):
        assert r.params[k] == pytest.approx(truth[k], rel=0.03), k
    assert r.params["vs"] == pytest.approx(truth["vs"], rel=0.1)
    assert r.params["alpha"] == pytest.approx(truth["alpha"], rel=0.15)
    assert r.rmse_fitted_nm < 0.03


def test_fit_options_bounds_and_errors():
    rng = np.random.default_rng(1)
    v = rng.uniform(-2.0, 2.0, 5000)
    tau = cv_ref(dict(kc=8.1, ka=50.0, kv=5.55), v)
    r = fl.fit_cv(v, tau, ka_max=10.0)
    assert r.params["ka"] == pytest.approx(10.0) and "ka=max" in r.at_bounds
    assert r.bounds["ka_max"] == 10.0
    r = fl.fit_cv(v, tau, sliding_quadrants=False)
    assert r.n_samples == v.size
    with pytest.raises(fl.FitError, match="need at least"):
        fl.fit_cv(v[:3], tau[:3], sliding_quadrants=False)
    bad = tau.copy()
    bad[10] = np.nan
    with pytest.raises(fl.FitError, match="sample 10 is not finite"):
        fl.fit_cv(v, bad, sliding_quadrants=False)
    with pytest.raises(ValueError, match="samples but tau_f_nm has"):
        fl.fit_cv(v, tau[:-1])
    with pytest.raises(ValueError, match="bound `ka_top`"):
        fl.fit_cv(v, tau, ka_top=1.0)


def test_friction_torque_matches_the_formulas():
    v = np.linspace(-1, 1, 101)
    p = dict(kc=5.0, ka=80.0, kv=2.0, ks=9.0, vs=0.15, alpha=1.5)
    np.testing.assert_allclose(fl.friction_torque("scv", p, v), scv_ref(p, v), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        fl.friction_torque("Cv", [1.0, 20.0, 0.5], v), cv_ref(dict(kc=1.0, ka=20.0, kv=0.5), v),
        rtol=1e-12, atol=1e-12,
    )
    with pytest.raises(ValueError):
        fl.friction_torque("cv", [1.0, 2.0], v)


def test_every_model_kind_of_the_core_is_exported():
    native = {n for n in dir(fl._native) if n.startswith("MODEL_KIND_")}
    assert "MODEL_KIND_LUGRE" in native
    for n in native:
        assert getattr(fl, n) == getattr(fl._native, n), n
        assert n in fl.__all__, n
    assert len({getattr(fl, n) for n in native}) == len(native)


LUGRE = dict(kc=1.0, kv=0.3, ks=1.6, vs=0.1, alpha=1.5, sigma0=1.0e4, sigma1=30.0)


def test_lugre_starts_at_rest_and_reaches_the_steady_state_curve():
    assert fl.LUGRE_PARAM_NAMES == ("kc", "kv", "ks", "vs", "alpha", "sigma0", "sigma1")
    for v in (0.05, -0.4, 1.2):
        tau = fl.lugre_friction_torque(LUGRE, np.full(2000, v), dt_s=1e-3)
        # Independent reference: at steady state dz/dt = 0, τ = g(v)·sign(v) + kv·v.
        g = LUGRE["kc"] + (LUGRE["ks"] - LUGRE["kc"]) * np.exp(-abs(v / LUGRE["vs"]) ** LUGRE["alpha"])
        assert tau[-1] == pytest.approx(g * np.sign(v) + LUGRE["kv"] * v, rel=1e-6)
        # From rest the bristles still deflect on the first tick: not yet the steady state.
        assert abs(tau[0] - tau[-1]) > 1e-3
    seq = [LUGRE[n] for n in fl.LUGRE_PARAM_NAMES]
    v = 0.3 * np.sin(np.linspace(0.0, 6.0, 500))
    np.testing.assert_array_equal(fl.lugre_friction_torque(seq, v), fl.lugre_friction_torque(LUGRE, v))


def test_lugre_refuses_a_bad_parameter_naming_it():
    with pytest.raises(ValueError, match="sigma0"):
        fl.lugre_friction_torque(dict(LUGRE, sigma0=-1.0), np.zeros(3))
    with pytest.raises(ValueError, match="dt_s"):
        fl.lugre_friction_torque(LUGRE, np.zeros(3), dt_s=0.0)
    with pytest.raises(ValueError, match="7"):
        fl.lugre_friction_torque([1.0, 2.0], np.zeros(3))
