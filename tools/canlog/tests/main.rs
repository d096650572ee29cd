//! Integration tests of `frictionless-canlog` (the candump -L format; `vcan_*` tests need a vcan interface).
//!
//! One test binary for the crate: each module is one former integration-test file.

mod canlog_format;
mod canlog_vcan;
