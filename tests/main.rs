//! The core crate's integration tests in one binary: inference-kernel parity with the f64 reference
//! (`kernel_parity`), the `.fwt` reader/writer against the spec in `docs/` (`weights_bad_input`), and the
//! layout documents held against the workspace (`docs_in_step`: README's house map, ARCHITECTURE's crate
//! graph and table, CONTRIBUTING's paths).
//! Not here: the allocation-freedom proofs (`alloc_free.rs`, its own binary because it installs a
//! counting global allocator), the unit tests (in `src/`), anything about IPC, CAN or `frictiond`
//! (those live with `frictionless-shm-types` and the daemon).

mod docs_in_step;
mod kernel_parity;
mod weights_bad_input;
