//! Integration tests of `frictionless-ident` (CV/SCV fit, filters against scipy).
//!
//! One test binary for the crate: each module is one former integration-test file.

mod ident_fit;
mod ident_scipy;
