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
//! - [`link`]: the [`LinkDynamics`](link::LinkDynamics) trait (I_L(s), g(s)) and an analytic pendulum;
//! - [`plant`]: the equations, 20 kHz semi-implicit Euler with the exact LuGre update, 1 kHz sensor
//!   emulation and the true friction as diagnostics;
//! - [`profile`]: open-loop current profiles for `frictl sim run`;
//! - [`stribeck`]: the tabulated Stribeck shape exp(−u^δ) of the fast path.
//!
//! What it is **not**: the excitation protocol or any controller (`frictionless-acquire`), and not the
//! plant process over shared memory or CAN (`frictl sim serve`, `frictl`'s `serve`).

#![warn(missing_docs)]

pub mod link;
pub mod params;
pub mod plant;
pub mod profile;
pub mod stribeck;

pub use link::{LinkDynamics, Pendulum};
pub use params::{LinkModel, ParamError, PlantParams, SensorParams};
pub use plant::{Measurement, Plant, PlantState, Sample, Truth};
