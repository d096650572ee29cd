//! # `frictionless-sim`: the virtual harmonic-drive joint
//!
//! Crate table: `tools/sim`; depends on `frictionless-dynamics` (link models from URDF); used by
//! `frictionless-acquire`, `frictionless-ident` (link dynamics of the label) and `frictl` (`sim`, `serve`,
//! `experiment`).
//!
//! What this crate **is**: a two-inertia joint simulator (the paper's plant, see `docs/`) used to
//! generate datasets and to test the whole method without a robot:
//! - [`params`]: every parameter as a serde struct, the `knee` / `ankle_roll` presets and the
//!   `--params FILE` / `--set key=value` override layering;
//! - [`leg`]: the coupled virtual leg ([`LegPlant`]): one drive per joint of a URDF leg (the ergoCub
//!   left leg by default, `config/presets/leg.toml`), coupled through the rigid-body dynamics (ABA);
//! - [`link`]: the [`LinkDynamics`](link::LinkDynamics) trait (I_L(s), g(s)) and an analytic pendulum;
//! - [`plant`]: the equations, 20 kHz semi-implicit Euler with the exact LuGre update, 1 kHz sensor
//!   emulation and the true friction as diagnostics;
//! - [`profile`]: open-loop current profiles for `frictl sim run`;
//! - [`stribeck`]: the tabulated Stribeck shape exp(−u^δ) of the fast path;
//! - [`torque_sensor`]: a joint torque sensor at the output flange (a torque-sensed arm's reading) and
//!   a logger's jittered timestamps.
//!
//! What it is **not**: the excitation protocol or any controller (`frictionless-acquire`), and not the
//! plant process over shared memory or CAN (`frictl sim serve`, `frictl`'s `serve`).
//!
//! ## Example: push the knee with a constant current
//! ```
//! use frictionless_sim::{ParamError, Plant, PlantParams};
//!
//! let params = PlantParams::preset("knee")?; // r = −100, k_t = 0.157 Nm/A, 1 kHz samples
//! let r = params.gear_ratio_signed;
//! let s0_rad = params.initial_s_rad;
//!
//! // 100 ms at a constant current reference (robot convention), no external torque.
//! let push = |i_a: f64| -> Result<f64, ParamError> {
//!     let mut plant = Plant::from_params(params.clone(), 1)?; // at rest, holding gravity
//!     let mut s_rad = s0_rad;
//!     for _ in 0..100 {
//!         let sample = plant.step(i_a, 0.0);
//!         s_rad = sample.meas.s_rad; // the joint encoder, quantised
//!     }
//!     Ok(s_rad)
//! };
//!
//! // Joint torque = r·k_t·i (signed r): with r < 0 a positive current turns the joint negative.
//! assert!(r < 0.0);
//! let (s_pos, s_neg) = (push(3.0)?, push(-3.0)?);
//! assert!(s_pos < s0_rad - 0.01, "s = {s_pos} from {s0_rad}");
//! assert!(s_neg > s0_rad + 0.01, "s = {s_neg} from {s0_rad}");
//! # Ok::<(), ParamError>(())
//! ```

#![warn(missing_docs)]

pub mod leg;
pub mod link;
pub mod params;
pub mod plant;
pub mod profile;
pub mod stribeck;
pub mod torque_sensor;

pub use leg::{JointSample, LegError, LegParams, LegPlant, Perturbation};
pub use link::{LinkDynamics, Pendulum};
pub use params::{LinkModel, MotorEncoderKind, ParamError, PlantParams, SensorParams};
pub use plant::{Measurement, Plant, PlantState, Sample, Truth};
