//! # frictl (library part)
//!
//! The offline machinery behind the `frictl` binary, as a library so benches and tests can use it:
//! - [`dynamics`]: URDF parsing and rigid-body dynamics (RNEA fixed/floating base, CRBA).
//! - [`sim`]: the virtual two-inertia harmonic-drive joint with LuGre friction.
//! - [`acquire`]: the excitation protocol and dataset logs.
//! - [`serve`]: the virtual joints as a plant process (shared memory, SocketCAN).
//! - [`interop`]: ONNX and safetensors import/export of `.fwt` models.
//!
//! It is **not** the real-time daemon and never depends on it.

#![warn(missing_docs)]

pub mod acquire;
pub mod canlog;
pub mod dynamics;
pub mod eval;
pub mod experiment;
pub mod ident;
pub mod interop;
pub mod serve;
pub mod sim;
pub mod train;
