//! `frictiond` as a library: the pieces of the 1 kHz friction-compensation daemon.
//!
//! What this crate **is**: the config schema ([`config`], re-exporting `frictiond-config`), the
//! runtime parameters built from it ([`params`], with the per-joint control law of
//! `frictionless::law`), the I/O backends ([`backend`]: iceoryx2 shared memory, SocketCAN), the RT
//! loop ([`rt`], the tick top to bottom in one module), systemd notification ([`sdnotify`]) and the
//! RT-thread allocation counter ([`alloc_count`]), the one-daemon-per-prefix lock ([`instance`]),
//! the answers to runtime control requests ([`control`], with the checks of [`runtime`]). The
//! binary `frictiond` (`main.rs`) is the supervisor that wires them together; the library exists so
//! benches and tests can drive the same code.
//!
//! What it is **not**: no friction models and no control law (the `frictionless` crate), no ABI (`frictionless-shm-types`),
//! no offline tooling (`frictl`).
//!
//! ## Example: config → runtime parameters → one RT tick, without IPC
//! ```
//! use std::path::Path;
//! use frictionless::friction::StaticFriction;
//! use frictiond::config::ModelSpec;
//! use frictiond::rt::{Freshness, Inputs, Latest};
//! use frictionless_shm_types::{JointStates, MAX_JOINTS, MotorCurrentCommand, TorqueRequest};
//!
//! let text = r#"
//! [backend]
//! kind = "shm"
//!
//! [[joint]]
//! name = "knee"
//! index = 2
//! gear_ratio = -100.0
//! kt = 0.157
//! max_curr = 5.0
//! kfc = 0.85
//! friction_model = "cv"
//! kc = 8.1
//! ka = 50.84
//! kv = 5.55
//! "#;
//! let cfg = frictiond::config::parse(Path::new("/etc/frictiond/knee.toml"), text)?;
//! // Off the RT thread: estimators, filters and laws, handed to the loop as one Box.
//! let mut params = frictiond::params::build(&cfg, 0)?;
//! assert_eq!(params.configured_mask, 1 << 2);
//!
//! // The inputs a backend would deliver: joint 2 moving at 0.3 rad/s, enabled, τ_des = 4 Nm.
//! let (k, sdot_rad_s, tau_des_nm) = (2, 0.3, 4.0);
//! let mut st = JointStates::zeroed();
//! st.n_joints = 3;
//! st.sdot_rad_s[k] = sdot_rad_s;
//! st.omega_motor_rad_s[k] = -100.0 * sdot_rad_s;
//! let mut rq = TorqueRequest::zeroed();
//! rq.n_joints = 3;
//! rq.enable_mask = 1 << k;
//! rq.tau_des_nm[k] = tau_des_nm;
//! let inputs = Inputs {
//!     states: Latest { value: st, have: true, new_at_tick: 0 },
//!     request: Latest { value: rq, have: true, new_at_tick: 0 },
//! };
//! let fresh = Freshness { state_stale: false, request_stale: false };
//! let mut cmd = MotorCurrentCommand::zeroed();
//! let (mut prev_active, mut tau_f_nm) = (0u64, [0.0; MAX_JOINTS]);
//!
//! // The tick's compute step (allocation-free): model estimate + control law per joint.
//! frictiond::rt::compute(&mut params, &inputs, fresh, &mut prev_active, &mut cmd, &mut tau_f_nm);
//!
//! // i = (τ_des + kfc·f(ṡ)) / (k_t·r), with the signed r.
//! let ModelSpec::Cv(cv) = &cfg.models[0] else { panic!("cv resolves to CV") };
//! let expected_a = (tau_des_nm + 0.85 * cv.torque_nm(sdot_rad_s)) / (0.157 * -100.0);
//! assert!(cmd.is_valid(k) && !cmd.is_valid(0), "only the enabled joint is commanded");
//! assert!((cmd.i_ref_a[k] - expected_a).abs() < 1e-12, "{} vs {expected_a}", cmd.i_ref_a[k]);
//! assert!(cmd.i_ref_a[k] < 0.0, "negative r: a positive joint torque needs a negative current");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod alloc_count;
pub mod backend;
pub mod config;
pub mod control;
pub mod instance;
/// The runtime parameters built from a validated config (they live with the schema, in
/// `frictiond-config`, so the config fuzzer and other tools build them without the daemon).
pub use frictiond_config::params;
/// Runtime changes of joint values: checked by the file's rules, applied at a tick boundary.
pub use frictiond_config::runtime;
pub mod rt;
pub mod sdnotify;
