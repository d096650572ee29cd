//! # `frictionless-ident`: the friction label pipeline and static-model fitting
//!
//! Crate table: `tools/ident`; depends on `frictionless` (CV/SCV models), `frictionless-dataset`,
//! `frictionless-sim` (link dynamics) and `frictionless-dynamics` (the whole-body RNEA); used by `frictionless-acquire` (raw logs in memory) and `frictl`
//! (`preprocess`, `import`, `fit`, `experiment`) and `frictionless-logs` (its input type).
//!
//! What this crate **is**:
//! - [`kalman`]: constant-acceleration Kalman filter and RTS smoother for ṡ, s̈;
//! - [`preprocess`]: the label pipeline, acquisition log ([`preprocess::RawLog`], [`preprocess::LogMeta`])
//!   → labelled [`frictionless_dataset::Dataset`] (`frictl preprocess`), and the same pipeline for
//!   imported robot signals ([`preprocess::preprocess_signals`], `frictl import csv|mat|mcap`: optional
//!   signals, current / torque-sensor / given labels; several joints in one pass with
//!   [`preprocess::preprocess_joints`]);
//! - [`stream`]: the same pipeline on a log read in blocks (windows with margins derived from the
//!   smoother and filter settings; the rows equal the whole-log result);
//! - [`matched`]: the matched `current` label (every term at the sample rate, then one filter);
//! - [`ripple`]: the wave generator's friction ripple (twice the motor angle), identified from the
//!   log and added back to the matched label where its smoother removed it;
//! - [`whole_body`]: τ_ID = RNEA(q, q̇, q̈) on the whole URDF from every joint a log has, for the
//!   `current` label;
//! - [`fit`]: least-squares fits of the static CV and SCV friction models to a dataset (`frictl fit`);
//! - [`scv_fit`]: the SCV fit `frictl fit scv` runs (data bounds, low-speed rows, the CV fallback);
//! - [`lugre_fit`]: LuGre identification (Stribeck curve, bristle σ0 and σ1) from the time series
//!   (`frictl fit lugre`).
//!
//! The Butterworth filters it runs are the core's one implementation, [`frictionless::filter`].
//!
//! What it is **not**: network training (`frictionless-train`), the dataset file format
//! (`frictionless-dataset`) or anything real-time.
//!
//! ## Example: recover CV parameters from synthetic (ṡ, τ_F) samples
//! ```
//! use frictionless::friction::{CvParams, StaticFriction};
//! use frictionless_ident::fit::{FitOptions, fit, sliding_quadrant_mask, select};
//!
//! // Known parameters: τ_F = kc·tanh(ka·ṡ) + kv·ṡ.
//! let truth = CvParams { kc: 8.1, ka: 50.0, kv: 5.55 };
//! // 2 000 samples over ±2 rad/s with a deterministic ±0.05 Nm disturbance.
//! let v_rad_s: Vec<f64> = (0..2000).map(|k| -2.0 + 4.0 * k as f64 / 1999.0).collect();
//! let tau_nm: Vec<f64> = (v_rad_s.iter().enumerate())
//!     .map(|(k, &v)| truth.torque_nm(v) + if k % 2 == 0 { 0.05 } else { -0.05 })
//!     .collect();
//!
//! // The authors' selection (sliding, friction opposing motion), then projected Levenberg–Marquardt.
//! let mask = sliding_quadrant_mask(&v_rad_s, &tau_nm, 0.01);
//! let (v, tau) = (select(&v_rad_s, &mask), select(&tau_nm, &mask));
//! let res = fit::<CvParams>(&v, &tau, &FitOptions::default())?;
//!
//! let m = res.model;
//! assert!((m.kc - truth.kc).abs() < 0.02, "kc = {}", m.kc);
//! assert!((m.kv - truth.kv).abs() < 0.02, "kv = {}", m.kv);
//! assert!((m.ka - truth.ka).abs() < 0.05 * truth.ka, "ka = {}", m.ka);
//! assert!(res.rmse_nm < 0.06, "residual is the disturbance: {}", res.rmse_nm);
//! assert!(res.at_bounds.is_empty(), "interior optimum");
//! # Ok::<(), frictionless_ident::fit::FitError>(())
//! ```

#![warn(missing_docs)]

pub mod dataset_file;
pub mod fit;
pub mod kalman;
pub mod label_settings;
pub mod lugre_fit;
pub mod matched;
pub mod preprocess;
pub mod ripple;
pub mod scv_fit;
mod signals;
pub mod stream;
pub mod whole_body;
