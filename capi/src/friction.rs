//! Static friction models, CV and SCV, with the BLF `JointTorqueControlDevice` parameter names.
//!
//! The fields are the device's configuration keys (groups `FRICTION_COULOMB_VISCOUS`: `kc`, `kv`,
//! `ka`; `FRICTION_COULOMB_VISCOUS_STRIBECK`: `kc`, `kv`, `vs`, `ka`, `ks`, `alpha`) in SI joint-side
//! units — the device's YARP configuration is in degrees, this library is in radians
//! (`docs/method.md` §8, §10):
//!
//! ```text
//! CV : τ_F = kc·tanh(ka·ṡ) + kv·ṡ
//! SCV: τ_F = kv·ṡ + kc·tanh(ka·ṡ) + (ks − kc)·exp(−|ṡ/vs|^alpha)·tanh(ka·ṡ)
//! ```
//! `ka = +∞` means a true sign(). The evaluation is the core's (`frictionless::friction`).

use fl_core::friction::{CvParams, ScvParams, StaticFriction};
use fl_core::lugre::LugreParams;

use crate::{Fail, arg, arg_mut, fl_status, guard};

/// Coulomb–viscous parameters (BLF `FRICTION_COULOMB_VISCOUS`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct fl_cv_params {
    /// Coulomb level kc [Nm], ≥ 0.
    pub kc: f64,
    /// Steepness of the smooth sign ka [s/rad], > 0 (+∞: sign()).
    pub ka: f64,
    /// Viscous coefficient kv [Nm·s/rad], ≥ 0.
    pub kv: f64,
}

/// Stribeck–Coulomb–viscous parameters, paper form (BLF `FRICTION_COULOMB_VISCOUS_STRIBECK`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct fl_scv_params {
    /// Coulomb level kc [Nm], ≥ 0.
    pub kc: f64,
    /// Steepness of the smooth sign ka [s/rad], > 0 (+∞: sign()).
    pub ka: f64,
    /// Viscous coefficient kv [Nm·s/rad], ≥ 0.
    pub kv: f64,
    /// Breakaway (static) level ks [Nm], ≥ 0.
    pub ks: f64,
    /// Stribeck velocity vs [rad/s], > 0.
    pub vs: f64,
    /// Stribeck shape exponent alpha, > 0.
    pub alpha: f64,
}

/// LuGre parameters (joint side): the SCV Stribeck curve (sign() Coulomb, no `ka`) plus the bristle
/// stiffness σ0 and damping σ1. The names are the fit file's and the daemon config's.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct fl_lugre_params {
    /// Coulomb level kc [Nm], > 0.
    pub kc: f64,
    /// Viscous coefficient kv = σ2 [Nm·s/rad], ≥ 0.
    pub kv: f64,
    /// Breakaway (static) level ks [Nm], ≥ 0.
    pub ks: f64,
    /// Stribeck velocity vs [rad/s], > 0.
    pub vs: f64,
    /// Stribeck shape exponent alpha, > 0.
    pub alpha: f64,
    /// Bristle stiffness σ0 [Nm/rad], > 0.
    pub sigma0: f64,
    /// Bristle damping σ1 [Nm·s/rad], ≥ 0.
    pub sigma1: f64,
}

impl From<&fl_lugre_params> for LugreParams {
    fn from(p: &fl_lugre_params) -> Self {
        LugreParams {
            kc: p.kc,
            kv: p.kv,
            ks: p.ks,
            vs: p.vs,
            alpha: p.alpha,
            sigma0: p.sigma0,
            sigma1: p.sigma1,
        }
    }
}

impl From<&fl_cv_params> for CvParams {
    fn from(p: &fl_cv_params) -> Self {
        CvParams {
            kc: p.kc,
            ka: p.ka,
            kv: p.kv,
        }
    }
}

impl From<&fl_scv_params> for ScvParams {
    fn from(p: &fl_scv_params) -> Self {
        ScvParams {
            kc: p.kc,
            ka: p.ka,
            kv: p.kv,
            ks: p.ks,
            vs: p.vs,
            alpha: p.alpha,
        }
    }
}

impl From<ScvParams> for fl_scv_params {
    fn from(p: ScvParams) -> Self {
        fl_scv_params {
            kc: p.kc,
            ka: p.ka,
            kv: p.kv,
            ks: p.ks,
            vs: p.vs,
            alpha: p.alpha,
        }
    }
}

/// Checks parameters with the core's validation; the message names the first bad one.
pub(crate) fn validated<M: StaticFriction>(m: M) -> Result<M, Fail> {
    m.validate()
        .map_err(|e| Fail::owned(fl_status::InvalidArgument, e.to_string()))?;
    Ok(m)
}

/// CV friction τ_F [Nm] at joint velocity `sdot_rad_s` [rad/s] into `*tau_f_nm`.
/// `FL_STATUS_INVALID_ARGUMENT` (naming the parameter) if `params` is out of its domain.
///
/// # Safety
/// `params` is NULL or points to a readable `fl_cv_params`; `tau_f_nm` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_cv_friction_nm(
    params: *const fl_cv_params,
    sdot_rad_s: f64,
    tau_f_nm: *mut f64,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let p = unsafe { arg(params, "fl_cv_friction_nm: `params` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(tau_f_nm, "fl_cv_friction_nm: `tau_f_nm` is NULL") }?;
        *out = validated(CvParams::from(p))?.torque_nm(sdot_rad_s);
        Ok(())
    })
}

/// SCV friction τ_F [Nm] at joint velocity `sdot_rad_s` [rad/s] into `*tau_f_nm`.
/// `FL_STATUS_INVALID_ARGUMENT` (naming the parameter) if `params` is out of its domain.
///
/// # Safety
/// `params` is NULL or points to a readable `fl_scv_params`; `tau_f_nm` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn fl_scv_friction_nm(
    params: *const fl_scv_params,
    sdot_rad_s: f64,
    tau_f_nm: *mut f64,
) -> fl_status {
    guard(|| {
        // SAFETY: caller contract.
        let p = unsafe { arg(params, "fl_scv_friction_nm: `params` is NULL") }?;
        // SAFETY: caller contract.
        let out = unsafe { arg_mut(tau_f_nm, "fl_scv_friction_nm: `tau_f_nm` is NULL") }?;
        *out = validated(ScvParams::from(p))?.torque_nm(sdot_rad_s);
        Ok(())
    })
}
