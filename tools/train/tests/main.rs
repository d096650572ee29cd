//! Integration tests of `frictionless-train` (gradients, determinism, learning, PINN vs SCV on simulated data).
//!
//! One test binary for the crate (one link step); each module tests one area.

mod train_beats_scv;
mod train_determinism;
mod train_gradcheck;
mod train_learning;
