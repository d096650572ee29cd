//! iceoryx2 shared-memory backend: the `frictionless-shm-types` services.
//!
//! What this module **is**: [`ShmBackend`], the four services of a `frictiond` deployment
//! (states and requests in; commands and status out) with latest-value semantics.
//!
//! What it is **not**: no CAN (see [`super::can`]), no timing.

use std::time::Duration;

use frictionless_shm_types::{
    DaemonStatus, Inbox, IoError, Ipc, IpcConfig, JointStates, MotorCurrentCommand, Outbox,
    TorqueRequest,
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
            _ipc: ipc,
        })
    }
}

impl Backend for ShmBackend {
    fn read_states(&mut self) -> Result<Option<JointStates>, IoError> {
        self.states.latest()
    }
    fn read_request(&mut self) -> Result<Option<TorqueRequest>, IoError> {
        self.request.latest()
    }
    fn publish_command(&mut self, cmd: &MotorCurrentCommand) -> Result<(), IoError> {
        // iceoryx2 0.10 allocates one 48-byte Box per loaned sample (measured; see module doc).
        alloc_count::exempt(|| self.command.publish(cmd))
    }
    fn publish_status(&mut self, status: &DaemonStatus) -> Result<(), IoError> {
        alloc_count::exempt(|| self.status.publish(status))
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
}
