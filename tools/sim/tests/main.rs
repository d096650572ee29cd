//! Integration tests of `frictionless-sim` (physics of the virtual joint, determinism).
//!
//! One test binary for the crate: each module is one former integration-test file.

mod sim_physics;
