//! The per-joint PINN estimator from Python: [`Estimator`], one sample per call, with the semantics of
//! frictiond's per-joint path.
//!
//! What it is: `frictionless::model::PinnEstimator` plus the daemon's enable edge — the first
//! [`Estimator::push`] after construction or [`Estimator::reset`] is a bumpless enable (history
//! cleared, Δθ offset latched at that sample unless a fixed offset is set), then the sample is
//! pushed and the network runs (or, under `hold_zero`, returns 0 until H samples arrived).
//! What it is not: the control law or any filtering of τ̂_F (that is `frictionless::law`).

use frictionless::features::{JointSample, WarmupPolicy};
use frictionless::model::{FrictionModel, PinnEstimator};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::model::Model;
use crate::{ModelError, message};

fn parse_warmup(s: &str) -> PyResult<WarmupPolicy> {
    match s {
        "hold_zero" => Ok(WarmupPolicy::HoldZero),
        "zero_pad" => Ok(WarmupPolicy::ZeroPad),
        _ => Err(PyValueError::new_err(format!(
            "warmup `{s}`: expected \"hold_zero\" or \"zero_pad\""
        ))),
    }
}

fn warmup_name(w: WarmupPolicy) -> &'static str {
    match w {
        WarmupPolicy::HoldZero => "hold_zero",
        WarmupPolicy::ZeroPad => "zero_pad",
    }
}

/// One joint's PINN friction estimator, stepped one sample per tick.
#[pyclass(module = "frictionless._native")]
pub struct Estimator {
    est: PinnEstimator,
    /// The next push is an enable edge (reset before it).
    fresh: bool,
    /// The estimate of the newest sample [Nm] (0 before the first push).
    last_nm: f64,
}

#[pymethods]
impl Estimator {
    /// An estimator for `model` with warm-up policy `warmup` (`"hold_zero"`, frictiond's default,
    /// or `"zero_pad"`) and an optional fixed Δθ offset θ_off [motor rad] (`None`: latched at
    /// every enable, as frictiond without `delta_theta_offset_motor_rad`).
    #[new]
    #[pyo3(signature = (model, warmup = "hold_zero", delta_theta_offset_motor_rad = None))]
    fn new(
        model: &Model,
        warmup: &str,
        delta_theta_offset_motor_rad: Option<f64>,
    ) -> PyResult<Self> {
        let mut est = PinnEstimator::from_model_file(model.file(), parse_warmup(warmup)?)
            .map_err(|e| ModelError::new_err(message(&e)))?;
        if let Some(off) = delta_theta_offset_motor_rad {
            if !off.is_finite() {
                return Err(PyValueError::new_err(format!(
                    "delta_theta_offset_motor_rad = {off} is not finite"
                )));
            }
            est.fix_delta_theta_offset(Some(off));
        }
        Ok(Self {
            est,
            fresh: true,
            last_nm: 0.0,
        })
    }

    /// One tick: joint position s [rad], joint velocity ṡ [rad/s], motor position θ [motor rad],
    /// motor velocity ω_m [motor rad/s], motor temperature [°C] (NaN: no sensor). Returns the
    /// friction estimate [Nm] of this sample (also kept for [`Estimator::estimate`]).
    #[pyo3(signature = (s_rad, sdot_rad_s, theta_motor_rad, omega_motor_rad_s, temperature_c = f64::NAN))]
    fn push(
        &mut self,
        s_rad: f64,
        sdot_rad_s: f64,
        theta_motor_rad: f64,
        omega_motor_rad_s: f64,
        temperature_c: f64,
    ) -> f64 {
        let x = JointSample {
            s_rad,
            sdot_rad_s,
            theta_motor_rad,
            omega_motor_rad_s,
            temperature_c,
        };
        if self.fresh {
            self.est.reset(&x);
            self.fresh = false;
        }
        self.last_nm = self.est.estimate(&x);
        self.last_nm
    }

    /// The friction estimate [Nm] of the newest sample (0 before the first push).
    fn estimate(&self) -> f64 {
        self.last_nm
    }

    /// Disable: the next push is an enable edge (history cleared, Δθ re-latched unless fixed).
    fn reset(&mut self) {
        self.fresh = true;
        self.last_nm = 0.0;
    }

    /// Whether the history holds H samples (frictiond clears `FLAG_WARMING_UP` from then on).
    #[getter]
    fn warm(&self) -> bool {
        !self.fresh && self.est.history().is_full()
    }

    /// Whether the warm-up policy lets the network run (always after one sample under `zero_pad`).
    #[getter]
    fn ready(&self) -> bool {
        !self.fresh && self.est.is_ready()
    }

    /// Samples held since the last enable (≤ H).
    #[getter]
    fn n_samples(&self) -> usize {
        if self.fresh {
            0
        } else {
            self.est.history().len()
        }
    }

    /// The warm-up policy name.
    #[getter]
    fn warmup(&self) -> &'static str {
        warmup_name(self.est.warmup())
    }

    /// The Δθ offset θ_off [motor rad] in use (latched or fixed; 0 before the first latch).
    #[getter]
    fn delta_theta_offset_motor_rad(&self) -> f64 {
        self.est.history().latch().offset_motor_rad()
    }

    /// The input vector of the last inference (zeros before the first one), float32.
    fn last_input(&self) -> Vec<f32> {
        self.est.last_input().to_vec()
    }

    fn __repr__(&self) -> String {
        format!(
            "Estimator(joint={:?}, warmup={}, samples={}/{})",
            self.est.meta().joint_name,
            warmup_name(self.est.warmup()),
            self.n_samples(),
            self.est.history().spec().history
        )
    }
}
