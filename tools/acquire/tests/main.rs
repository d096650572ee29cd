//! Integration tests of `frictionless-acquire` (the offline protocol run through the label pipeline).
//!
//! One test binary for the crate: each module is one former integration-test file.

mod ident_label;
