//! # `frictionless-ident`: the friction label pipeline and static-model fitting
//!
//! Crate table: `tools/ident`; depends on `frictionless` (CV/SCV models), `frictionless-dataset` and
//! `frictionless-sim` (link dynamics); used by `frictionless-acquire` (raw logs in memory) and `frictl`
//! (`preprocess`, `fit`, `experiment`).
//!
//! What this crate **is**:
//! - [`filter`]: Butterworth low-pass as second-order sections, causal and zero-phase, equal to scipy;
//! - [`kalman`]: constant-acceleration Kalman filter and RTS smoother for ṡ, s̈;
//! - [`preprocess`]: the label pipeline, acquisition log ([`preprocess::RawLog`], [`preprocess::LogMeta`])
//!   → labelled [`frictionless_dataset::Dataset`] (`frictl preprocess`);
//! - [`fit`]: least-squares fits of the static CV and SCV friction models to a dataset (`frictl fit`).
//!
//! What it is **not**: network training (`frictionless-train`), the dataset file format
//! (`frictionless-dataset`) or anything real-time.

#![warn(missing_docs)]

pub mod filter;
pub mod fit;
pub mod kalman;
pub mod preprocess;
