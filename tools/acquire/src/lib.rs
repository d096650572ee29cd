//! # `frictionless-acquire`: data acquisition with the paper's excitation protocol
//!
//! Crate table: `tools/acquire`; depends on `frictionless-sim` (the plant), `frictionless-dataset`
//! (column docs) and `frictionless-ident` (the in-memory raw log handed to the label pipeline); used by
//! `frictl` (`acquire`, `serve`).
//!
//! What this crate **is**: the paper's excitation protocol (see `docs/`) — five starting poses,
//! position-controlled re-centring before every block, current sines (amplitude × frequency, 2 cycles
//! each, high → low f), ramps both ways, steps, a position-limit latch and a current guard, plus
//! closed-loop sine-tracking sets for sliding data — and its dataset output (CSV + JSON sidecar):
//! - [`config`]: every number as a serde struct (the `[protocol]` table of a preset);
//! - [`protocol`]: the schedule, the controllers and the run loop over the [`protocol::JointIo`] seam;
//! - [`log`]: CSV columns, units and the sidecar;
//! - [`offline`]: the protocol on a fresh simulated plant ([`offline::run_offline`]) and its rows as
//!   the label pipeline's input.
//!
//! What it is **not**: the plant (`frictionless-sim`) or a live shared-memory client (that is
//! `serve::shm::LiveJoint` in `frictl`, behind the same [`protocol::JointIo`] seam).

#![warn(missing_docs)]

pub mod config;
pub mod log;
pub mod offline;
pub mod protocol;

pub use config::ProtocolConfig;
pub use offline::{OfflineError, OfflineRun, log_meta, raw_log, run_offline};
pub use protocol::{Block, BlockKind, JointIo, LogRow, Mode, RunSummary, SimJoint, run, schedule};
