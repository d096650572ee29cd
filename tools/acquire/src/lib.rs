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
//! - [`arm_log`]: the log of a torque-sensed arm (joint torque sensor, no motor encoder, optional
//!   lower rate and jittered timestamps) for `frictl import csv`;
//! - [`leg`]: every joint of the coupled leg excited at once, each with its own protocol;
//! - [`offline`]: the protocol on a fresh simulated plant ([`offline::run_offline`]) and its rows as
//!   the label pipeline's input.
//!
//! What it is **not**: the plant (`frictionless-sim`) or a live shared-memory client (that is
//! `serve::shm::LiveJoint` in `frictl`, behind the same [`protocol::JointIo`] seam).
//!
//! ## Example: a two-step protocol on the simulated knee
//! ```
//! use frictionless_acquire::{BlockKind, LogRow, ProtocolConfig, run_offline, schedule};
//! use frictionless_sim::PlantParams;
//! use frictionless_sim::params::load_table;
//!
//! // The knee preset's [plant] and [protocol], cut down to one start and two current steps.
//! let sets = [
//!     "protocol.n_starts=1",
//!     "protocol.recentre_s=0.3",
//!     "protocol.sines.enabled=false",
//!     "protocol.ramps.enabled=false",
//!     "protocol.steps.levels_a=[2.0, -2.0]",
//!     "protocol.steps.hold_s=0.3",
//!     "protocol.steps.rest_s=0.2",
//!     "protocol.tracking.train.enabled=false",
//! ]
//! .map(String::from);
//! let table = load_table("knee", None, &sets)?;
//! let plant = PlantParams::from_table(&table)?;
//! let protocol = ProtocolConfig::from_table(&table)?;
//! let blocks = schedule(&protocol);
//! assert_eq!(blocks.len(), 2);
//! assert!(matches!(blocks[0].kind, BlockKind::Step { level_a, .. } if level_a > 0.0));
//!
//! // Play it on a fresh simulated plant; every 1 kHz row goes to the sink (a CSV writer in `frictl`).
//! let mut rows: Vec<LogRow> = Vec::new();
//! let run = run_offline(&plant, &protocol, &blocks, 7, &mut |row| {
//!     rows.push(*row);
//!     Ok(())
//! })?;
//! assert_eq!(run.summary.chunks, 2);
//! assert_eq!(run.summary.samples, rows.len() as u64);
//!
//! // During each step's hold the joint turns the way r·k_t·L says (r = −100: a positive step
//! // turns it negative).
//! let moved_rad = |chunk: u32| {
//!     let active: Vec<&LogRow> = rows.iter().filter(|r| r.chunk == chunk && r.active).collect();
//!     let hold = (0.3 / plant.sample_period_s()) as usize;
//!     active[hold - 1].meas.s_rad - active[0].meas.s_rad
//! };
//! assert!(plant.gear_ratio_signed < 0.0);
//! assert!(moved_rad(0) < -0.01, "{}", moved_rad(0));
//! assert!(moved_rad(1) > 0.01, "{}", moved_rad(1));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

pub mod arm_log;
pub mod config;
pub mod leg;
pub mod log;
pub mod offline;
pub mod protocol;

pub use config::ProtocolConfig;
pub use offline::{OfflineError, OfflineRun, log_meta, raw_log, run_offline};
pub use protocol::{
    Block, BlockKind, JointIo, JointRunner, LogRow, Mode, RunSummary, SimJoint, run, schedule,
};
