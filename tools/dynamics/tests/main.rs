//! Integration tests of `frictionless-dynamics` (analytic cases, Pinocchio reference values, the virtual leg).
//!
//! One test binary for the crate: each module is one former integration-test file.

mod dynamics_analytic;
mod dynamics_pinocchio;
mod dynamics_virtual_leg;
