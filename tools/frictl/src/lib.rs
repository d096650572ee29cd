//! # `frictl` (library part): what only the `frictl` binary uses
//!
//! Crate table: `tools/frictl` (package `frictl`, lib + bin). The binary's command layer (`cmd/`,
//! untyped errors) runs the library crates of `tools/`: `frictionless-dynamics` (URDF, RNEA/CRBA),
//! `frictionless-sim` (virtual joint), `frictionless-acquire` (excitation protocol, logs),
//! `frictionless-dataset` (file formats), `frictionless-ident` (label pipeline, CV/SCV fit),
//! `frictionless-train` (PINN trainer, random search), `frictionless-interop` (ONNX, safetensors) and
//! `frictionless-canlog` (candump logs).
//!
//! What this library **is**, on top of those:
//! - [`serve`]: the virtual joints as a plant process (shared memory, SocketCAN);
//! - [`eval`]: model evaluation on datasets, with figures;
//! - [`experiment`]: closed-loop experiments against a running `frictiond`;
//! - [`robot`]: the robot-level pipeline description (`frictl robot run ROBOT.toml`).
//!
//! What it is **not**: the real-time daemon; it never depends on it (experiments start `frictiond` as a
//! process).
//!
//! ## Example: the frictiond config of one experiment run, through the daemon's schema
//! ```
//! use std::path::Path;
//! use frictionless::friction::CvParams;
//! use frictionless_shm_types::IpcConfig;
//! use frictl::experiment::session::{DaemonJoint, FrictionModel, Mode, daemon_config, shipped_kfc};
//!
//! // The virtual knee (gear ratio and k_t from its plant preset) compensated by a fitted CV model.
//! let knee = DaemonJoint {
//!     name: "l_knee".into(),
//!     index: 0,
//!     gear_ratio: -100.0,
//!     kt_nm_per_a: 0.157,
//!     model: FrictionModel::Cv(CvParams { kc: 8.1, ka: 50.84, kv: 5.55 }),
//!     delta_theta_offset_motor_rad: None,
//!     kfc: None, // the shipped config/ankle_knee.toml value
//!     lpf: None,
//! };
//! let ipc = IpcConfig::new(Some(Path::new("/tmp/frictl-run")), "run0");
//! // Pure: builds frictiond-config's typed `RawConfig`, starts nothing.
//! let raw = daemon_config(&ipc, Mode::Lockstep, &[knee], false)?;
//!
//! // What `frictl experiment` writes for frictiond is `toml::to_string` of it, and frictiond's
//! // own validation accepts it.
//! let text = toml::to_string(&raw)?;
//! let cfg = frictiond_config::parse(Path::new("/tmp/frictl-run/frictiond.toml"), &text)?;
//! let j = &cfg.raw.joint[0];
//! assert_eq!(j.kfc, shipped_kfc("l_knee"));
//! assert_eq!(j.kfc, 0.85);
//! assert_eq!(j.friction_model, frictiond_config::ModelKind::Cv);
//! assert_eq!(cfg.raw.loop_.trigger, frictiond_config::Trigger::Lockstep);
//! assert!(matches!(cfg.models[0], frictiond_config::ModelSpec::Cv(p) if p.kc == 8.1));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod eval;
pub mod experiment;
pub mod robot;
pub mod serve;
