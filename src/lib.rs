//! # frictionless — the friction-model core
//!
//! What this crate **is**: the pure, I/O-free heart of the project.
//! - [`friction`]: static joint-side friction models, Coulomb–viscous (CV) and Stribeck–Coulomb–viscous
//!   (SCV, paper form and the authors' code form), with parameter Jacobians for fitting.
//! - [`features`]: the seven feature sets (`[Δθ, ṡ]`, `[ω_m, ṡ]`, `[s, θ]`, `[s, ṡ]`, `[ṡ]` and the
//!   authors' types 3 `[Δθ, ω_m, ṡ]` and 4 `[Δθ, s, ṡ]`, each optionally with the motor temperature),
//!   their block-major oldest→newest layout, fixed-capacity per-joint history buffers, warm-up policies
//!   and the explicit Δθ offset latch.
//! - [`mlp`]: the plain description of a trained multilayer perceptron (PyTorch order), shape limits and
//!   the storage dtypes (f32, f16, bf16, int16, int8).
//! - [`weights`]: the `.fwt` fixed-size, versioned, CRC-checked weight file (spec in `docs/weights-format.md`).
//! - [`kernel`]: the allocation-free single-sample MLP inference kernel with runtime CPU dispatch
//!   (AVX-512 VNNI / AVX-512 / AVX2+FMA / portable) for every storage dtype, and cache prefetch of a
//!   network's weights.
//! - [`model`]: none / CV / SCV / PINN behind one trait, so the daemon treats them alike.
//! - [`units`]: the signed gear ratio and unit conventions.
//! - [`law`]: the per-joint torque-to-current control law (friction compensation gain, velocity-gated
//!   clip, τ̂_F low-pass, PI on the torque error, current clamp, NaN handling, bumpless reset) that
//!   frictiond runs every tick and the tools' experiment oracle runs on the true friction.
//! - [`filter`]: the one Butterworth low-pass (scipy-equal design, allocation-free per-sample step,
//!   offline `sosfilt`/`sosfiltfilt`).
//! - [`fastmath`]: inlinable exp/ln/powf/tanh kernels with stated error bounds (scalar and lane-wise).
//! - [`regular_file`]: opening the files a user names (regular files only, never blocking, size-bounded),
//!   used by every crate that reads a path from a command line or a config.
//! - [`error_line`]: an error and its causes on one line, as `frictiond` and `frictl` print it.
//! - `random` (cargo feature `random`, off by default): seeded random ReLU networks for tests, benches
//!   and tools.
//!
//! What it is **not**: no threads, no IPC, no logging. It touches the file system only where a caller
//! asks it to: [`regular_file`]'s checked reads and [`weights`]' `read_file`/`write_file`. The daemon
//! (`frictiond`) and the tools (`frictl`) build on it.
//!
//! ## Conventions
//! Joint side is SI: `s` [rad], `ṡ` [rad/s], torques [Nm]. Motor side: `θ` [motor rad], `ω_m`
//! [motor rad/s]. The gear ratio `r` is **signed** (motor angle = r · joint angle, e.g. −160 for
//! ergoCub's left ankle roll). Friction `τ_F` is joint side and opposes motion, so that
//! `τ = r·k_t·i − τ_F`.
//!
//! ## Example: load a `.fwt`, estimate friction, command a current
//! ```
//! use frictionless::features::{JointSample, WarmupPolicy};
//! use frictionless::law::{Gains, JointLaw, LawInput};
//! use frictionless::model::{FrictionModel, PinnEstimator};
//!
//! // A shipped paper-size network (40 → 268 → 215 → 1, inputs [Δθ ×20, ṡ ×20], r = −160).
//! let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/models/stress32_paper_f16_r-160.fwt");
//! let file = frictionless::weights::read_file(std::path::Path::new(path))?;
//! let r = file.meta.gear_ratio.get();
//! let mut pinn = PinnEstimator::from_model_file(&file, WarmupPolicy::ZeroPad)?;
//!
//! let sample = JointSample {
//!     s_rad: 0.1,
//!     sdot_rad_s: 0.5,
//!     theta_motor_rad: r * 0.1,
//!     omega_motor_rad_s: r * 0.5,
//!     temperature_c: f64::NAN,
//! };
//! pinn.reset(&sample); // enable: history cleared, Δθ latched at this sample
//! let tau_f_nm = pinn.estimate(&sample); // allocation-free, one sample per tick
//! assert!(tau_f_nm.is_finite());
//!
//! // i = (τ_des + kfc·τ̂_F)/(k_t·r), clamped; the law frictiond runs every tick.
//! let gains = Gains {
//!     kt_nm_per_a: 0.0665,
//!     gear_ratio: r,
//!     kfc: 0.85,
//!     kp: 0.0,
//!     ki: 0.0,
//!     max_curr_a: 10.0,
//!     max_output_friction_nm: f64::INFINITY,
//!     joint_velocity_threshold_rad_s: 0.0,
//!     dt_s: 1e-3,
//!     speed_limit: None, // Some(SpeedCurrentLimit::new(rated, no_load, sf)?): a torque–speed curve
//! };
//! let mut law = JointLaw::new(gains, None);
//! let out = law.step(&LawInput {
//!     tau_des_nm: 1.0,
//!     friction_nm: tau_f_nm,
//!     sdot_rad_s: sample.sdot_rad_s,
//!     tau_meas_nm: 0.0,
//! });
//! let expected_a = (1.0 + 0.85 * tau_f_nm) / (0.0665 * r);
//! assert!((out.i_a - expected_a.clamp(-10.0, 10.0)).abs() < 1e-9);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod fastmath;
pub mod features;
pub mod filter;
pub mod friction;
pub mod kernel;
pub mod law;
pub mod lugre;
pub mod mlp;
pub mod model;
pub mod named;
pub mod output_file;
#[cfg(feature = "random")]
pub mod random;
pub mod regular_file;
pub mod units;
pub mod weights;

/// An error and its causes on one line, `a: b: c`, leaving out a cause whose text the line already
/// holds (many errors quote their source in their own message, e.g. `FILE: No such file or
/// directory`). What `frictiond` and `frictl` print for a fatal error.
pub fn error_line(e: &(dyn std::error::Error + 'static)) -> String {
    let mut line = String::new();
    let mut cause = Some(e);
    while let Some(c) = cause {
        let text = c.to_string();
        if !line.contains(&text) {
            if !line.is_empty() {
                line.push_str(": ");
            }
            line.push_str(&text);
        }
        cause = c.source();
    }
    line
}

#[cfg(test)]
mod tests {
    #[derive(Debug)]
    struct Quoting(std::io::Error);
    impl std::fmt::Display for Quoting {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(f, "cfg.toml: {}", self.0)
        }
    }
    impl std::error::Error for Quoting {
        fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
            Some(&self.0)
        }
    }

    #[test]
    fn error_line_keeps_each_cause_once() {
        let os = || std::io::Error::new(std::io::ErrorKind::NotFound, "not found");
        // The message quotes its source: printed once.
        assert_eq!(super::error_line(&Quoting(os())), "cfg.toml: not found");
        // A source the message does not quote is appended.
        #[derive(Debug)]
        struct Wrap(std::io::Error);
        impl std::fmt::Display for Wrap {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("loading the model")
            }
        }
        impl std::error::Error for Wrap {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                Some(&self.0)
            }
        }
        assert_eq!(
            super::error_line(&Wrap(os())),
            "loading the model: not found"
        );
    }
}
