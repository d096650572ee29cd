//! `frictiond` end to end: the one integration-test binary of the daemon package. Every test starts
//! the real `frictiond` binary as a process (Cargo builds it for this target:
//! `CARGO_BIN_EXE_frictiond`) and is the plant or controller itself over iceoryx2 shared memory, a
//! socketpair or a vcan. `daemon_watch` and `daemon_features` also run `frictl` (another package; see
//! [`daemon_support::frictl_path`]).
//!
//! Tests named `vcan_*` need a kernel with CAN: `#[ignore]`d on the host, run inside the QEMU VM of
//! `tests/canvm/run.sh` (which selects this target by name, `frictiond_e2e`, and the tests with the
//! libtest filter `vcan`). Not here: the daemon's unit tests (in `src/`).

mod can_support;
mod daemon_support;

mod can_backend;
mod daemon_alloc;
mod daemon_control;
mod daemon_e2e;
mod daemon_features;
mod daemon_lockstep;
mod daemon_ood;
mod daemon_pinn;
mod daemon_reliability;
mod daemon_watch;
mod vcan_cia402_candump;
mod vcan_cia402_canopen;
mod vcan_daemon;
