//! # frictionless-drives — what the motor drives speak on the wire
//!
//! What this crate **is**: pure, allocation-free encoders and decoders of the frames exchanged with
//! motor drives, shared by `frictiond` (sends commands, decodes feedback), the emulated drives of the
//! virtual plant (`frictionless-plant`), the candump tools (`frictionless-canlog`) and the fuzz
//! targets:
//! - [`can`]: classic CAN 2.0 — [`can::WireFrame`] (a frame as plain data), the per-joint unit
//!   mapping ([`can::units`]), the bus-load budget ([`can::busload`]), and one module per drive
//!   protocol: [`can::mit`] (MIT mini-cheetah / CubeMars AK "MIT mode"), [`can::odrive`] (ODrive
//!   "CAN Simple") and [`can::cia402`] (CANopen with the CiA 402 drive profile). [`can::CanProtocol`] is the closed list of them, as `[[bus]] protocol` names it.
//!
//! What it is **not**: no sockets, no threads, no timing, no friction or control law; errors are `Copy`
//! values without heap data so the RT loop can construct and match them. The `#[repr(C)]` payloads
//! between processes live in `frictionless-shm-types`; the bus back end that owns the sockets is
//! `frictiond`'s `backend::can`.
//!
//! ## Where another drive protocol goes
//! - **On CAN** (e.g. a vendor protocol): one new file `src/can/<name>.rs` with
//!   `encode_*` / `decode_*` functions over [`can::WireFrame`] (copy the shape of [`can::odrive`]),
//!   and one [`can::CanProtocol`] variant. Its methods (feedback angle unit, bits and frames per joint
//!   per tick) then fail to compile until the new protocol answers them, and so do the `match`es in
//!   frictiond's CAN backend and the plant's drive emulator.
//! - **On another bus** (e.g. CiA 402 over EtherCAT): a sibling module `src/ethercat/` with its own
//!   frame type and codec error, following the layout of [`can`]; the back end that owns the link is a
//!   new `AnyBackend` variant in frictiond (`ARCHITECTURE.md`, "Extending").
//!
//! ## Example: an MIT-mode torque command
//! ```
//! use frictionless_drives::can::mit::{self, MitCommand, MitRanges, MitRx, MitSaturation};
//!
//! // frictiond's command: pure feed-forward torque (kp = kd = 0) to the drive with motor id 3.
//! let ranges = MitRanges::MINI_CHEETAH; // T ±18 Nm in 12 bits
//! let (frame, sat) = mit::encode_command(3, &MitCommand::torque(1.25), &ranges)?;
//! assert_eq!((frame.id, frame.len, frame.extended), (3, 8, false));
//! assert!(!sat.any());
//!
//! // What the drive decodes: the same torque within one quantisation step.
//! let MitRx::Command(rx) = mit::decode_command(&frame, &ranges)? else {
//!     panic!("a torque command is not a special frame");
//! };
//! let t_step_nm = ranges.steps()[4];
//! assert!((rx.t_ff_nm - 1.25).abs() <= 0.5 * t_step_nm);
//!
//! // Out of range is clamped to the range end and reported, never wrapped.
//! let (frame, sat) = mit::encode_command(3, &MitCommand::torque(-30.0), &ranges)?;
//! assert!(sat.has(MitSaturation::T));
//! let MitRx::Command(rx) = mit::decode_command(&frame, &ranges)? else {
//!     panic!("not a special frame");
//! };
//! assert_eq!(rx.t_ff_nm, ranges.t_min_nm);
//! # Ok::<(), frictionless_drives::can::CanCodecError>(())
//! ```

#![warn(missing_docs)]

pub mod can;
