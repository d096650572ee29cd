//! Integration tests of `frictionless-train` (gradients, determinism, learning, PINN vs SCV on simulated data).
//!
//! One test binary for the crate: each module is one former integration-test file.

mod train_beats_scv;
mod train_determinism;
mod train_gradcheck;
mod train_learning;
