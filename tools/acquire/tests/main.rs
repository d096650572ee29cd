//! Integration tests of `frictionless-acquire` (the offline protocol run through the label pipeline).
//!
//! One test binary for the crate (one link step); each module tests one area.

mod ident_label;
mod leg_label;
