//! Integration tests of `frictionless-sim` (physics of the virtual joint and the coupled leg, determinism).
//!
//! One test binary for the crate (one link step); each module tests one area.

mod sim_leg;
mod sim_physics;
