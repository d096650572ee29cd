//! LuGre friction: the Stribeck curve of SCV plus a bristle state z [rad] that gives pre-sliding
//! stiffness and damping (Canudas de Wit, Olsson, Åström, Lischinsky 1995).
//!
//! What this module **is**: the parameters ([`LugreParams`]) and the per-joint estimator
//! ([`LugreEstimator`]) the daemon runs at its tick:
//!
//! - g(v) = kc + (ks − kc)·exp(−|v/vs|^α) [Nm], the Stribeck curve (SCV's, with sign() for the
//!   smooth sign);
//! - dz/dt = v − σ0·|v|/g(v)·z;
//! - τ = σ0·z + σ1·dz/dt + kv·v.
//!
//! At constant velocity z settles at g(v)·sign(v)/σ0 and τ at the SCV curve
//! g(v)·sign(v) + kv·v ([`LugreParams::steady_state_nm`]). The estimator integrates z exactly for a
//! velocity held over the tick (z relaxes exponentially to its steady state, rate σ0·|v|/g), so a
//! stiff σ0 needs no small step; dz/dt is the tick's mean (Δz/Δt). The state is reset to 0 at every
//! enable.
//!
//! What it is **not**: no identification (that is `frictionless-ident`'s `lugre_fit`, `frictl fit
//! lugre`, which simulates this estimator over a dataset); no clamping or gain (the control law's).

/// LuGre parameters (joint side).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LugreParams {
    /// Coulomb level kc [Nm], > 0.
    pub kc: f64,
    /// Viscous coefficient kv = σ2 [Nm·s/rad], ≥ 0.
    pub kv: f64,
    /// Breakaway friction ks [Nm], ≥ 0.
    pub ks: f64,
    /// Stribeck velocity vs [rad/s], > 0.
    pub vs: f64,
    /// Stribeck exponent α [-], > 0.
    pub alpha: f64,
    /// Bristle stiffness σ0 [Nm/rad], > 0.
    pub sigma0: f64,
    /// Bristle damping σ1 [Nm·s/rad], ≥ 0.
    pub sigma1: f64,
}

/// A LuGre parameter out of its domain: names the parameter, its value and the requirement.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("LuGre: {name} = {value} {requirement}")]
pub struct LugreParamError {
    /// The parameter.
    pub name: &'static str,
    /// Its value.
    pub value: f64,
    /// What it must be.
    pub requirement: &'static str,
}

impl LugreParams {
    /// Parameter names, as in the fit file and the daemon config.
    pub const PARAM_NAMES: [&'static str; 7] =
        ["kc", "kv", "ks", "vs", "alpha", "sigma0", "sigma1"];

    /// Checks every parameter (finite; kc, vs, α, σ0 > 0; kv, ks, σ1 ≥ 0).
    pub fn validate(&self) -> Result<(), LugreParamError> {
        let checks: [(&'static str, f64, bool); 7] = [
            ("kc", self.kc, true),
            ("kv", self.kv, false),
            ("ks", self.ks, false),
            ("vs", self.vs, true),
            ("alpha", self.alpha, true),
            ("sigma0", self.sigma0, true),
            ("sigma1", self.sigma1, false),
        ];
        for (name, value, positive) in checks {
            let ok = value.is_finite() && if positive { value > 0.0 } else { value >= 0.0 };
            if !ok {
                return Err(LugreParamError {
                    name,
                    value,
                    requirement: if positive {
                        "must be finite and > 0"
                    } else {
                        "must be finite and ≥ 0"
                    },
                });
            }
        }
        Ok(())
    }

    /// The Stribeck curve g(v) [Nm] (> 0 for valid parameters).
    #[inline]
    pub fn stribeck_nm(&self, v_rad_s: f64) -> f64 {
        self.kc + (self.ks - self.kc) * (-(v_rad_s.abs() / self.vs).powf(self.alpha)).exp()
    }

    /// The steady-state (constant-velocity) torque g(v)·sign(v) + kv·v [Nm].
    pub fn steady_state_nm(&self, v_rad_s: f64) -> f64 {
        let sign = if v_rad_s > 0.0 {
            1.0
        } else if v_rad_s < 0.0 {
            -1.0
        } else {
            0.0
        };
        self.stribeck_nm(v_rad_s) * sign + self.kv * v_rad_s
    }
}

/// The default integration step [s]: the daemon's 1 kHz tick, the datasets' sample period.
pub const DEFAULT_DT_S: f64 = 1e-3;

/// The LuGre estimator of one joint: parameters, the tick period and the bristle state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LugreEstimator {
    params: LugreParams,
    dt_s: f64,
    z_rad: f64,
}

impl LugreEstimator {
    /// An estimator integrating at `dt_s` [s] (the tick period), bristle state 0. `dt_s` must be
    /// finite and > 0, the parameters valid (see [`LugreParams::validate`]).
    pub fn new(params: LugreParams, dt_s: f64) -> Result<Self, LugreParamError> {
        params.validate()?;
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(LugreParamError {
                name: "dt_s",
                value: dt_s,
                requirement: "must be finite and > 0",
            });
        }
        Ok(Self {
            params,
            dt_s,
            z_rad: 0.0,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &LugreParams {
        &self.params
    }

    /// The integration step [s].
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// The bristle state z [rad].
    pub fn z_rad(&self) -> f64 {
        self.z_rad
    }

    /// Clears the bristle state (enable).
    #[inline]
    pub fn reset_state(&mut self) {
        self.z_rad = 0.0;
    }

    /// One tick at joint velocity `v_rad_s`: integrates z over the tick and returns τ̂_F [Nm].
    /// A non-finite velocity gives NaN and leaves the state as it was. Allocation-free.
    #[inline]
    pub fn step(&mut self, v_rad_s: f64) -> f64 {
        if !v_rad_s.is_finite() {
            return f64::NAN;
        }
        let p = &self.params;
        let g = p.stribeck_nm(v_rad_s);
        let rate_per_s = p.sigma0 * v_rad_s.abs() / g;
        let z0 = self.z_rad;
        let z1 = if rate_per_s > 0.0 {
            let z_ss = v_rad_s / rate_per_s;
            z_ss + (z0 - z_ss) * (-rate_per_s * self.dt_s).exp()
        } else {
            z0
        };
        self.z_rad = z1;
        let zdot = (z1 - z0) / self.dt_s;
        p.sigma0 * z1 + p.sigma1 * zdot + p.kv * v_rad_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: LugreParams = LugreParams {
        kc: 1.0,
        kv: 0.3,
        ks: 1.6,
        vs: 0.05,
        alpha: 1.5,
        sigma0: 2.0e3,
        sigma1: 5.0,
    };

    #[test]
    fn constant_velocity_settles_on_the_stribeck_curve() {
        for v in [-0.8, -0.04, 0.01, 0.2, 1.5] {
            let mut e = LugreEstimator::new(P, DEFAULT_DT_S).unwrap();
            let mut tau = 0.0;
            for _ in 0..5000 {
                tau = e.step(v);
            }
            let want = P.steady_state_nm(v);
            assert!((tau - want).abs() < 1e-9, "v {v}: {tau} vs {want}");
        }
    }

    #[test]
    fn presliding_is_a_spring_and_reset_clears_it() {
        let mut e = LugreEstimator::new(P, DEFAULT_DT_S).unwrap();
        // A small move: the bristles deflect, the torque stays below breakaway, then holds at rest.
        for _ in 0..10 {
            e.step(1e-4);
        }
        let z = e.z_rad();
        assert!(z > 0.0 && z < 1.0e-6 + 1e-9, "z = {z}");
        let held = e.step(0.0);
        assert_eq!(held, P.sigma0 * z, "at rest: the spring alone");
        assert!(held < P.ks);
        e.reset_state();
        assert_eq!(e.step(0.0), 0.0);
    }

    #[test]
    fn exact_step_stays_stable_with_a_stiff_sigma0() {
        let stiff = LugreParams { sigma0: 1.0e8, ..P };
        let mut e = LugreEstimator::new(stiff, DEFAULT_DT_S).unwrap();
        for k in 0..2000 {
            let v = (k as f64 * 0.01).sin();
            let tau = e.step(v);
            assert!(
                tau.is_finite() && tau.abs() < 10.0 + stiff.sigma1 * 1e3,
                "tick {k}: {tau}"
            );
        }
        assert!(e.step(f64::NAN).is_nan());
    }

    #[test]
    fn invalid_parameters_are_named() {
        let e = LugreEstimator::new(LugreParams { sigma0: 0.0, ..P }, 1e-3).unwrap_err();
        assert_eq!(e.name, "sigma0");
        let e = LugreEstimator::new(P, f64::NAN).unwrap_err();
        assert_eq!(e.name, "dt_s");
        assert!(
            LugreParams { vs: -1.0, ..P }
                .validate()
                .unwrap_err()
                .to_string()
                .contains("vs")
        );
    }
}
