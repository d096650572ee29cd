//! # `frictl` (library part): what only the `frictl` binary uses
//!
//! Crate table: `tools/frictl` (package `frictl`, lib + bin). The binary's command layer (`cmd/`,
//! `anyhow` errors) runs the library crates of `tools/`: `frictionless-dynamics` (URDF, RNEA/CRBA),
//! `frictionless-sim` (virtual joint), `frictionless-acquire` (excitation protocol, logs),
//! `frictionless-dataset` (file formats), `frictionless-ident` (label pipeline, CV/SCV fit),
//! `frictionless-train` (PINN trainer, random search), `frictionless-interop` (ONNX, safetensors) and
//! `frictionless-canlog` (candump logs).
//!
//! What this library **is**, on top of those:
//! - [`serve`]: the virtual joints as a plant process (shared memory, SocketCAN);
//! - [`eval`]: model evaluation on datasets, with figures;
//! - [`experiment`]: closed-loop experiments against a running `frictiond`.
//!
//! What it is **not**: the real-time daemon; it never depends on it (experiments start `frictiond` as a
//! process).

#![warn(missing_docs)]

pub mod eval;
pub mod experiment;
pub mod serve;
