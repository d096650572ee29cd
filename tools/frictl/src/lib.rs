//! # `frictl` (library part): what only the `frictl` binary uses
//!
//! Crate table: `tools/frictl` (package `frictl`, lib + bin). The binary's command layer (`cmd/`,
//! untyped errors) runs the library crates of `tools/`: `frictionless-dynamics` (URDF, RNEA/CRBA),
//! `frictionless-sim` (virtual joint), `frictionless-acquire` (excitation protocol, logs),
//! `frictionless-dataset` (file formats), `frictionless-ident` (label pipeline, CV/SCV fit),
//! `frictionless-logs` (robot logs), `frictionless-train` (PINN trainer, random search, distillation),
//! `frictionless-eval` (offline evaluation, drift, figures), `frictionless-experiment` (closed-loop
//! experiments), `frictionless-plant` (the virtual robot as a process, `sim serve`),
//! `frictionless-interop` (ONNX, safetensors) and `frictionless-canlog` (candump logs).
//!
//! What this library **is**, on top of those:
//! - [`robot`]: the robot-level pipeline description (`frictl robot run ROBOT.toml`).
//!
//! What it is **not**: the real-time daemon; it never depends on it (experiments start `frictiond` as a
//! process).

#![warn(missing_docs)]

pub mod robot;
