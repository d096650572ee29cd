//! # `frictionless-test-support`: test helpers shared across crates
//!
//! Crate table: `tools/test-support`; a dev-dependency of `frictionless-interop`, `frictl` and
//! `frictiond`.
//!
//! What this crate **is**: the helpers more than one crate's tests use, so each exists once:
//! - [`onnx`]: the ergoCub anchor fixture (path, reference I/O), a small ONNX graph builder written
//!   against `onnx-protobuf` (independent of the exporter under test) and seeded random weights.
//! - [`python_canopen`]: the Python interpreter, scripts and EDS file of the CiA 402 tests against
//!   python-canopen on vcan, and a Python process whose output lines a test waits for.
//!
//! What it is **not**: a fake of anything the tests check (models, plants and processes in tests are
//! the real ones), and never a dependency of non-test code.

#![warn(missing_docs)]

pub mod onnx;
pub mod python_canopen;
