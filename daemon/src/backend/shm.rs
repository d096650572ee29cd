//! iceoryx2 shared-memory backend: the `frictionless-shm-types` services.
//!
//! What this module **is**: [`ShmBackend`], the four services of a `frictiond` deployment
//! (states and requests in; commands and status out) with latest-value semantics. Its
//! [`BusCounters`] (kind [`BusKind::Shm`], one link) count samples: new states and requests
//! received, commands and status snapshots sent, failed loans as dropped, other failures as I/O
//! errors; every published status carries them.
//!
//! What it is **not**: no CAN (see [`super::can`]), no timing.

use std::time::Duration;

use frictionless_shm_types::{
    BusCounters, BusKind, DaemonStatus, Inbox, IoError, Ipc, IpcConfig, JointStates,
    MotorCurrentCommand, Outbox, TorqueRequest,
};

use super::{Backend, BackendError};
use crate::alloc_count;
use crate::config::Config;

/// The iceoryx2 root path and service prefix of `cfg`.
pub fn ipc_config(cfg: &Config) -> IpcConfig {
    IpcConfig {
        root_path: cfg.root_path.clone(),
        service_prefix: cfg.raw.backend.service_prefix.clone(),
    }
}

/// iceoryx2 shared-memory backend (the `frictionless-shm-types` services).
pub struct ShmBackend {
    _ipc: Ipc,
    states: Inbox<JointStates>,
    request: Inbox<TorqueRequest>,
    command: Outbox<MotorCurrentCommand>,
    status: Outbox<DaemonStatus>,
    counters: BusCounters,
    /// The status as published: the caller's with this backend's counters.
    status_out: DaemonStatus,
}

impl ShmBackend {
    /// Counts one receive's outcome.
    #[inline]
    fn count_rx<T>(&mut self, r: Result<Option<T>, IoError>) -> Result<Option<T>, IoError> {
        match &r {
            Ok(Some(_)) => self.counters.rx_messages += 1,
            Ok(None) => {}
            Err(_) => self.counters.io_errors += 1,
        }
        r
    }

    /// Counts one send's outcome.
    #[inline]
    fn count_tx(&mut self, r: Result<(), IoError>) -> Result<(), IoError> {
        match r {
            Ok(()) => self.counters.tx_messages += 1,
            Err(IoError::Loan) => self.counters.tx_dropped += 1,
            Err(_) => self.counters.io_errors += 1,
        }
        r
    }
}

impl ShmBackend {
    /// Opens the node (cleaning up dead nodes first) and all ports. Set-up time only.
    pub fn open(ipc_cfg: &IpcConfig) -> Result<Self, BackendError> {
        match Ipc::cleanup_dead_nodes_for(ipc_cfg) {
            Ok(n) if n > 0 => tracing::info!("removed resources of {n} dead iceoryx2 node(s)"),
            Ok(_) => {}
            Err(e) => tracing::warn!("dead-node clean-up failed: {e}"),
        }
        let ipc = Ipc::open(ipc_cfg, "frictiond")?;
        let states = ipc.joint_states()?;
        let request = ipc.torque_request()?;
        let command = ipc.motor_current_command()?;
        let status = ipc.daemon_status()?;
        Ok(Self {
            states: states.inbox()?,
            request: request.inbox()?,
            command: command.outbox()?,
            status: status.outbox()?,
            counters: BusCounters::new(BusKind::Shm, 1),
            status_out: DaemonStatus::zeroed(),
            _ipc: ipc,
        })
    }
}

impl Backend for ShmBackend {
    fn read_states(&mut self) -> Result<Option<JointStates>, IoError> {
        let r = self.states.latest();
        self.count_rx(r)
    }
    fn read_request(&mut self) -> Result<Option<TorqueRequest>, IoError> {
        let r = self.request.latest();
        self.count_rx(r)
    }
    fn publish_command(&mut self, cmd: &MotorCurrentCommand) -> Result<(), IoError> {
        // iceoryx2 0.10 allocates one 48-byte Box per loaned sample (measured; see module doc).
        let r = alloc_count::exempt(|| self.command.publish(cmd));
        self.count_tx(r)
    }
    fn publish_status(&mut self, status: &DaemonStatus) -> Result<(), IoError> {
        self.status_out = *status;
        self.status_out.bus = self.counters;
        let (out, s) = (&self.status, &self.status_out);
        let r = alloc_count::exempt(|| out.publish(s));
        self.count_tx(r)
    }
    fn wait_input(&mut self, timeout_ns: u64) -> Result<bool, IoError> {
        // One blocking `Listener::timed_wait` on the states' event service (0 allocations). An
        // iceoryx2 WaitSet over both listeners would be the textbook choice, but it allocates
        // twice per wake-up (measured, `docs/realtime.md` §2.6) and `Inbox` does not expose its
        // listener; the lockstep trigger instead waits on the listener of the input it misses
        // (`wait_request` for the request), re-polling both after every wake.
        self.states.wait(Duration::from_nanos(timeout_ns))
    }
    fn wait_request(&mut self, timeout_ns: u64) -> Result<bool, IoError> {
        self.request.wait(Duration::from_nanos(timeout_ns))
    }
    fn bus_counters(&self) -> BusCounters {
        self.counters
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use frictionless_shm_types::monotonic_ns;

    /// The published status carries this backend's counters: kind shm, one link, the samples
    /// received and sent so far.
    #[test]
    fn status_carries_the_shared_memory_counters() {
        let id = format!(
            "fl_shmbk_{}_{}",
            std::process::id(),
            monotonic_ns() % 1_000_000_000
        );
        let root = std::env::temp_dir().join(&id);
        std::fs::create_dir_all(&root).unwrap();
        let cfg = IpcConfig::new(Some(&root), &id);
        let mut b = ShmBackend::open(&cfg).unwrap();
        let peer = Ipc::open(&cfg, "peer").unwrap();
        let states = peer.joint_states().unwrap().outbox().unwrap();
        let status = peer.daemon_status().unwrap().inbox().unwrap();
        assert!(b.read_states().unwrap().is_none());
        states.publish(&JointStates::zeroed()).unwrap();
        assert!(b.read_states().unwrap().is_some());
        b.publish_command(&MotorCurrentCommand::zeroed()).unwrap();
        b.publish_status(&DaemonStatus::zeroed()).unwrap();
        let got = status.latest().unwrap().expect("status arrives").bus;
        assert_eq!((got.bus_kind(), got.links), (Some(BusKind::Shm), 1));
        assert_eq!((got.rx_messages, got.tx_messages), (1, 1), "{got:?}");
        assert_eq!((got.tx_dropped, got.io_errors), (0, 0));
        assert_eq!(b.bus_counters().tx_messages, 2);
        drop((states, status, peer, b));
        let _ = std::fs::remove_dir_all(root);
    }
}
