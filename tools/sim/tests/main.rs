//! Integration tests of `frictionless-sim` (physics of the virtual joint, determinism).
//!
//! One test binary for the crate (one link step); each module tests one area.

mod sim_physics;
