//! Integration tests of `frictionless-canlog` (the candump -L format; `vcan_*` tests need a vcan interface).
//!
//! One test binary for the crate (one link step); each module tests one area.

mod canlog_format;
mod canlog_vcan;
