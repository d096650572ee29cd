//! Integration tests of `frictionless-ident` (CV/SCV fit, filters against scipy).
//!
//! One test binary for the crate (one link step); each module tests one area.

mod ident_fit;
mod ident_scipy;
