//! # Data acquisition with the paper's excitation protocol
//!
//! What it is: the protocol of reference `simulator-and-protocol.md` §6.1/§6.2 — five starting poses,
//! position-controlled re-centring before every block, current sines (amplitude × frequency, 2 cycles
//! each, high → low f), ramps both ways, steps, a position-limit latch and a current guard, plus
//! closed-loop sine-tracking sets for sliding data — and its dataset output (CSV + JSON sidecar):
//! - [`config`]: every number as a serde struct (the `[protocol]` table of a preset);
//! - [`protocol`]: the schedule, the controllers and the run loop over the [`protocol::JointIo`] seam;
//! - [`log`]: CSV columns, units and the sidecar;
//! - [`offline`]: the protocol on a fresh simulated plant ([`offline::run_offline`]) and its rows as
//!   the label pipeline's input.
//!
//! What it is not: the plant (see [`crate::sim`]) or a live shared-memory client (that is
//! [`crate::serve::shm::LiveJoint`], behind the same [`protocol::JointIo`] seam).

pub mod config;
pub mod log;
pub mod offline;
pub mod protocol;

pub use config::ProtocolConfig;
pub use offline::{OfflineError, OfflineRun, log_meta, raw_log, run_offline};
pub use protocol::{Block, BlockKind, JointIo, LogRow, Mode, RunSummary, SimJoint, run, schedule};
