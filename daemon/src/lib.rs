//! `frictiond` as a library: the pieces of the 1 kHz friction-compensation daemon.
//!
//! What this crate **is**: the config schema ([`config`], re-exporting `frictiond-config`), the
//! runtime parameters built from it ([`params`], with the per-joint control law of
//! `frictionless::law`), the I/O backends ([`backend`]: iceoryx2 shared memory, SocketCAN), the RT
//! loop ([`rt`], the tick top to bottom in one module), systemd notification ([`sdnotify`]) and the
//! RT-thread allocation counter ([`alloc_count`]). The
//! binary `frictiond` (`main.rs`) is the supervisor that wires them together; the library exists so
//! benches and tests can drive the same code.
//!
//! What it is **not**: no friction models and no control law (the `frictionless` crate), no ABI (`frictionless-shm-types`),
//! no offline tooling (`frictl`).

#![warn(missing_docs)]

pub mod alloc_count;
pub mod backend;
pub mod config;
pub mod params;
pub mod rt;
pub mod sdnotify;
