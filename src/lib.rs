//! # frictionless — the friction-model core
//!
//! What this crate **is**: the pure, I/O-free heart of the project.
//! - [`friction`]: static joint-side friction models, Coulomb–viscous (CV) and Stribeck–Coulomb–viscous
//!   (SCV, paper form and the authors' code form), with parameter Jacobians for fitting.
//! - [`features`]: feature sets (`[Δθ, ṡ]`, `[ω_m, ṡ]`, `[s, θ]`, optional motor temperature), their
//!   block-major oldest→newest layout, fixed-capacity per-joint history buffers, warm-up policies and the
//!   explicit Δθ offset latch.
//! - [`mlp`]: the plain description of a trained multilayer perceptron (PyTorch order), shape limits.
//! - [`weights`]: the `.fwt` fixed-size, versioned, CRC-checked weight file (spec in `docs/weights-format.md`).
//! - [`kernel`]: the allocation-free single-sample MLP inference kernel with runtime CPU dispatch
//!   (AVX-512 / AVX2+FMA / portable) and f16/bf16 weight storage.
//! - [`model`]: none / CV / SCV / PINN behind one trait, so the daemon treats them alike.
//! - [`units`]: the signed gear ratio and unit conventions.
//! - [`law`]: the per-joint torque-to-current control law (friction compensation gain, velocity-gated
//!   clip, τ̂_F low-pass, PI on the torque error, current clamp, NaN handling, bumpless reset) that
//!   frictiond runs every tick and the tools' experiment oracle runs on the true friction.
//! - [`filter`]: the one Butterworth low-pass (scipy-equal design, allocation-free per-sample step,
//!   offline `sosfilt`/`sosfiltfilt`).
//! - [`fastmath`]: inlinable exp/ln/powf/tanh kernels with stated error bounds (scalar and lane-wise).
//! - `random` (cargo feature `random`, off by default): seeded random ReLU networks for tests, benches
//!   and tools.
//!
//! What it is **not**: no threads, no IPC, no logging, no file-system access beyond the explicit
//! `read`/`write` helpers of [`weights`]. The daemon (`frictiond`) and the tools (`frictl`) build on it.
//!
//! ## Conventions
//! Joint side is SI: `s` [rad], `ṡ` [rad/s], torques [Nm]. Motor side: `θ` [motor rad], `ω_m`
//! [motor rad/s]. The gear ratio `r` is **signed** (motor angle = r · joint angle, e.g. −160 for
//! ergoCub's left ankle roll). Friction `τ_F` is joint side and opposes motion, so that
//! `τ = r·k_t·i − τ_F`.

#![warn(missing_docs)]

pub mod fastmath;
pub mod features;
pub mod filter;
pub mod friction;
pub mod kernel;
pub mod law;
pub mod mlp;
pub mod model;
#[cfg(feature = "random")]
pub mod random;
pub mod units;
pub mod weights;
