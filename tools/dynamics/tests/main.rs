//! Integration tests of `frictionless-dynamics` (analytic cases, Pinocchio reference values, the virtual leg).
//!
//! One test binary for the crate (one link step); each module tests one area.

mod dynamics_analytic;
mod dynamics_pinocchio;
mod dynamics_virtual_leg;
