//! Integration tests of `frictionless-sim` (physics of the virtual joint and the coupled leg, determinism).
//!
//! One test binary for the crate: each module is one former integration-test file.

mod sim_leg;
mod sim_physics;
