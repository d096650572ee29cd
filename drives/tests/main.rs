//! The integration tests of `frictionless-drives` in one binary: the CAN codecs (hand-computed
//! bytes, round trips, proptest), the socketcan I/O path over a socketpair, and real-kernel SocketCAN
//! on vcan (`can_vcan`: tests named `vcan_*`, `#[ignore]`d on the host and run inside the QEMU VM of
//! `tests/canvm/run.sh`, which selects this target by name, `drives_tests`). Not here: the unit
//! tests of the payloads and codecs (in `src/`), anything that starts `frictiond` (`daemon/tests/`).

mod can_cia402;
mod can_cia402_eds;
mod can_codecs;
mod can_socketpair;
mod can_vcan;
