//! # `frictl` (library part): where frictl's parts live
//!
//! Crate table: `tools/frictl` (package `frictl`, lib + bin) is the command layer: it parses a
//! command line and calls the crates that do the work. The arguments of every subcommand (their clap
//! `Args`) and the typed stage builder are in `frictl-cli` (`tools/cli`); the pipelines that chain the
//! stages as child processes (`frictl demo`, `frictl robot run`, the robot file description) are in
//! `frictionless-pipeline` (`tools/pipeline`). The work is done by the library crates of `tools/`:
//! `frictionless-dynamics` (URDF, RNEA/CRBA), `frictionless-sim` (virtual joint),
//! `frictionless-acquire` (excitation protocol, logs), `frictionless-dataset` (file formats),
//! `frictionless-ident` (label pipeline, CV/SCV fit), `frictionless-logs` (robot logs),
//! `frictionless-import` (robot logs into datasets, `frictl import csv|mat|mcap`),
//! `frictionless-train` (PINN trainer, random search, distillation), `frictionless-eval` (offline
//! evaluation, drift, figures), `frictionless-experiment` (closed-loop experiments),
//! `frictionless-plant` (the virtual robot as a process, `sim serve`), `frictionless-interop` (ONNX,
//! safetensors) and `frictionless-canlog` (candump logs).
//!
//! What it is **not**: the real-time daemon; it never depends on it (experiments start `frictiond` as a
//! process).

#![warn(missing_docs)]
