//! CV / SCV fits on NumPy arrays: [`fit_static`] runs `frictionless-ident`'s fitter (the one `frictl
//! fit` runs) and answers with the `model` / `params` of the fit JSON; [`friction_torque`] evaluates a
//! static model with the core's `StaticFriction::torque_nm`; [`lugre_friction_torque`] steps the
//! core's `LugreEstimator` (the one frictiond runs) through a velocity sequence.
//!
//! What it is: argument conversion and the sliding-quadrant selection `frictl fit` applies by
//! default. What it is not: a fitter or a friction model of its own.

use std::collections::BTreeMap;

use frictionless::friction::{CvParams, ScvCodeParams, ScvParams, StaticFriction};
use frictionless::lugre::{LugreEstimator, LugreParams};
use frictionless_ident::fit::{
    FitBounds, FitOptions, FitResult, Fittable, Loss, Method, fit, select, sliding_quadrant_mask,
};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::{FitError, message};

/// The fit JSON's `model` tag for a model name (`"cv"`, `"scv"`, `"scv_code"`).
fn tag(model: &str) -> PyResult<&'static str> {
    match model {
        "cv" | "Cv" => Ok("Cv"),
        "scv" | "Scv" => Ok("Scv"),
        "scv_code" | "ScvCode" => Ok("ScvCode"),
        _ => Err(PyValueError::new_err(format!(
            "model `{model}`: expected \"cv\", \"scv\" or \"scv_code\""
        ))),
    }
}

/// What one fit hands back to Python.
struct Fitted {
    tag: &'static str,
    names: &'static [&'static str],
    params: Vec<f64>,
    rmse_nm: f64,
    mae_nm: f64,
    n_samples: usize,
    iterations: usize,
    at_bounds: Vec<String>,
}

fn fitted<M: Fittable>(tag: &'static str, r: FitResult<M>) -> Fitted {
    Fitted {
        tag,
        names: M::PARAM_NAMES,
        params: r.model.params().as_ref().to_vec(),
        rmse_nm: r.rmse_nm,
        mae_nm: r.mae_nm,
        n_samples: r.n_samples,
        iterations: r.iterations,
        at_bounds: r.at_bounds,
    }
}

/// Fits `model` (`"cv"`, `"scv"`, `"scv_code"`) to joint velocity `sdot_rad_s` and friction label
/// `tau_f_nm`. The Python `frictionless.fit_cv` / `fit_scv` / `fit_scv_code` document the options.
#[pyfunction]
#[pyo3(signature = (model, sdot_rad_s, tau_f_nm, sliding_quadrants, v_min_rad_s, method, loss, epochs, lr, bounds))]
#[allow(clippy::too_many_arguments)]
pub fn fit_static<'py>(
    py: Python<'py>,
    model: &str,
    sdot_rad_s: PyReadonlyArray1<'py, f64>,
    tau_f_nm: PyReadonlyArray1<'py, f64>,
    sliding_quadrants: bool,
    v_min_rad_s: f64,
    method: &str,
    loss: &str,
    epochs: usize,
    lr: f64,
    bounds: BTreeMap<String, f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let tag = tag(model)?;
    let method = parse_method(method)?;
    let adam_loss = parse_loss(loss)?;
    let b = parse_bounds(&bounds)?;
    let opts = FitOptions {
        method,
        adam_loss,
        adam_epochs: epochs,
        adam_lr: lr,
        bounds: b,
        ..FitOptions::default()
    };
    let v_all = sdot_rad_s.as_array().to_vec();
    let t_all = tau_f_nm.as_array().to_vec();
    if v_all.len() != t_all.len() {
        return Err(PyValueError::new_err(format!(
            "sdot_rad_s has {} samples but tau_f_nm has {}",
            v_all.len(),
            t_all.len()
        )));
    }
    let result = py.detach(|| {
        let (v, t) = if sliding_quadrants {
            let mask = sliding_quadrant_mask(&v_all, &t_all, v_min_rad_s);
            (select(&v_all, &mask), select(&t_all, &mask))
        } else {
            (v_all, t_all)
        };
        match tag {
            "Cv" => fit::<CvParams>(&v, &t, &opts).map(|r| fitted(tag, r)),
            "Scv" => fit::<ScvParams>(&v, &t, &opts).map(|r| fitted(tag, r)),
            _ => fit::<ScvCodeParams>(&v, &t, &opts).map(|r| fitted(tag, r)),
        }
    });
    let f = result.map_err(|e| FitError::new_err(message(&e)))?;
    let d = PyDict::new(py);
    d.set_item("model", f.tag)?;
    let params = PyDict::new(py);
    for (n, v) in f.names.iter().zip(&f.params) {
        params.set_item(*n, *v)?;
    }
    d.set_item("params", params)?;
    d.set_item(
        "method",
        match method {
            Method::Lm => "lm",
            Method::Adam => "adam",
        },
    )?;
    d.set_item("param_names", f.names.to_vec())?;
    d.set_item("rmse_fitted_nm", f.rmse_nm)?;
    d.set_item("mae_fitted_nm", f.mae_nm)?;
    d.set_item("n_samples", f.n_samples)?;
    d.set_item("iterations", f.iterations)?;
    d.set_item("bounds", bounds_dict(py, &b)?)?;
    d.set_item("at_bounds", f.at_bounds)?;
    d.set_item("sliding_quadrants", sliding_quadrants)?;
    d.set_item("v_min_rad_s", v_min_rad_s)?;
    Ok(d)
}

/// The fitting method of its name (`"lm"`, `"adam"`).
fn parse_method(method: &str) -> PyResult<Method> {
    Ok(match method {
        "lm" => Method::Lm,
        "adam" => Method::Adam,
        _ => {
            return Err(PyValueError::new_err(format!(
                "method `{method}`: expected \"lm\" or \"adam\""
            )));
        }
    })
}

/// Adam's loss of its name (`"l1"`, `"mse"`).
fn parse_loss(loss: &str) -> PyResult<Loss> {
    Ok(match loss {
        "l1" => Loss::L1,
        "mse" => Loss::Mse,
        _ => {
            return Err(PyValueError::new_err(format!(
                "loss `{loss}`: expected \"l1\" or \"mse\""
            )));
        }
    })
}

/// The default bounds with those of `bounds` (by key) in their place.
fn parse_bounds(bounds: &BTreeMap<String, f64>) -> PyResult<FitBounds> {
    let mut b = FitBounds::default();
    for (k, v) in bounds {
        let slot = match k.as_str() {
            "ka_min" => &mut b.ka_min,
            "ka_max" => &mut b.ka_max,
            "vs_min" => &mut b.vs_min,
            "vs_max" => &mut b.vs_max,
            "alpha_min" => &mut b.alpha_min,
            "alpha_max" => &mut b.alpha_max,
            "ks_max_ratio" => &mut b.ks_max_ratio,
            _ => {
                return Err(PyValueError::new_err(format!(
                    "bound `{k}`: expected ka_min, ka_max, vs_min, vs_max, alpha_min, alpha_max or ks_max_ratio"
                )));
            }
        };
        *slot = *v;
    }
    Ok(b)
}

/// The bounds as a dict, keyed as [`parse_bounds`] reads them.
fn bounds_dict<'py>(py: Python<'py>, b: &FitBounds) -> PyResult<Bound<'py, PyDict>> {
    let bd = PyDict::new(py);
    bd.set_item("ka_min", b.ka_min)?;
    bd.set_item("ka_max", b.ka_max)?;
    bd.set_item("vs_min", b.vs_min)?;
    bd.set_item("vs_max", b.vs_max)?;
    bd.set_item("alpha_min", b.alpha_min)?;
    bd.set_item("alpha_max", b.alpha_max)?;
    bd.set_item("ks_max_ratio", b.ks_max_ratio)?;
    Ok(bd)
}

fn eval<M: StaticFriction>(params: &[f64], v: &[f64]) -> PyResult<Vec<f64>> {
    let m = M::from_params(params).map_err(|e| PyValueError::new_err(message(&e)))?;
    Ok(v.iter().map(|&x| m.torque_nm(x)).collect())
}

/// τ_F(ṡ) [Nm] of a static model (`"cv"`, `"scv"`, `"scv_code"`) with parameters in the fit
/// JSON's order, for every velocity of `sdot_rad_s`.
#[pyfunction]
pub fn friction_torque<'py>(
    py: Python<'py>,
    model: &str,
    params: Vec<f64>,
    sdot_rad_s: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let v = sdot_rad_s.as_array().to_vec();
    let tau = match tag(model)? {
        "Cv" => eval::<CvParams>(&params, &v)?,
        "Scv" => eval::<ScvParams>(&params, &v)?,
        _ => eval::<ScvCodeParams>(&params, &v)?,
    };
    Ok(PyArray1::from_vec(py, tau))
}

/// τ_F [Nm] of a LuGre model (parameters in `LugreParams::PARAM_NAMES` order) stepped through
/// `sdot_rad_s` [rad/s], one sample every `dt_s` [s], from bristle state 0 (frictiond's joint after
/// an enable). `ValueError` naming a bad parameter, step or parameter count.
#[pyfunction]
pub fn lugre_friction_torque<'py>(
    py: Python<'py>,
    params: Vec<f64>,
    sdot_rad_s: PyReadonlyArray1<'py, f64>,
    dt_s: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let names = LugreParams::PARAM_NAMES;
    let [kc, kv, ks, vs, alpha, sigma0, sigma1] = params[..] else {
        return Err(PyValueError::new_err(format!(
            "LuGre: {} parameters given, expected {} ({})",
            params.len(),
            names.len(),
            names.join(", ")
        )));
    };
    let p = LugreParams {
        kc,
        kv,
        ks,
        vs,
        alpha,
        sigma0,
        sigma1,
    };
    let mut est = LugreEstimator::new(p, dt_s).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let tau = sdot_rad_s.as_array().iter().map(|&v| est.step(v)).collect();
    Ok(PyArray1::from_vec(py, tau))
}
