//! The I/O seam of the RT loop: where joint states and torque requests come from and where current
//! commands and status go.
//!
//! What this module **is**: the [`Backend`] trait the tick in [`crate::rt`] is written against, and
//! [`AnyBackend`], the closed set of backends chosen by `[backend] kind` (static dispatch, no
//! `dyn` on the RT path). [`shm::ShmBackend`] speaks the iceoryx2 services of
//! `frictionless-shm-types`; [`can::CanBackend`] reads motor feedback from and sends commands to
//! SocketCAN drives, and still takes torque requests from (and mirrors commands and status to)
//! shared memory so controllers, `frictl monitor` and `frictl record` work the same on both.
//!
//! What it is **not**: no control law, no timing. Every method is called on the RT thread: no
//! allocation (beyond what the module docs measure and exempt), no locks, no blocking except
//! [`Backend::wait_input`], which exists for the lockstep trigger.

pub mod can;
pub mod shm;

use frictionless_shm_types::{
    BusCounters, DaemonStatus, IoError, JointStates, MotorCurrentCommand, ShmError, TorqueRequest,
};

use crate::config::{BackendKind, Config};

/// Why a backend could not be opened (set-up time). Messages name the interface or service and the
/// OS or iceoryx2 error.
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// An iceoryx2 node or port could not be opened.
    #[error("shared memory: {0}")]
    Shm(#[from] ShmError),
    /// `fd:` not followed by a descriptor number.
    #[error("CAN interface {interface:?}: `fd:` must be followed by a descriptor number")]
    FdSpec {
        /// The configured interface.
        interface: String,
    },
    /// An inherited descriptor (`fd:N`) is not open.
    #[error("CAN interface {interface:?}: descriptor {fd} is not open: {source}")]
    FdNotOpen {
        /// The configured interface.
        interface: String,
        /// The descriptor number.
        fd: i32,
        /// `fcntl(F_GETFD)`'s error.
        source: std::io::Error,
    },
    /// A kernel CAN interface could not be opened.
    #[error("opening CAN interface {interface:?}: {source}")]
    Open {
        /// The interface name.
        interface: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// A socket option could not be set.
    #[error("CAN interface {interface:?}: {what}: {source}")]
    SocketOption {
        /// The interface name.
        interface: String,
        /// Which option (e.g. "set_nonblocking").
        what: &'static str,
        /// The OS error.
        source: std::io::Error,
    },
    /// `CanBackend::with_sockets` got a socket count that differs from the configured buses.
    #[error("{sockets} sockets for {buses} configured CAN buses")]
    SocketCount {
        /// Sockets passed.
        sockets: usize,
        /// Buses configured.
        buses: usize,
    },
    /// A CiA 402 drive's start-up failed: an SDO abort (its code, meaning and the object), a time-out,
    /// or a value read back that differs from what was written.
    #[error("CAN interface {interface:?}, CiA 402 node {node}: {message}")]
    Cia402Startup {
        /// Interface name.
        interface: String,
        /// CANopen node id.
        node: u8,
        /// What failed.
        message: String,
    },
    /// The bus-counter logger thread could not be spawned.
    #[error("spawning the CAN logger thread: {0}")]
    LoggerThread(#[source] std::io::Error),
}

/// The I/O seam: the loop reads newest inputs and publishes outputs through this.
pub trait Backend {
    /// Newest joint states since the last call, if any.
    fn read_states(&mut self) -> Result<Option<JointStates>, IoError>;
    /// Newest torque request since the last call, if any.
    fn read_request(&mut self) -> Result<Option<TorqueRequest>, IoError>;
    /// Sends a current command.
    fn publish_command(&mut self, cmd: &MotorCurrentCommand) -> Result<(), IoError>;
    /// Sends a status snapshot.
    fn publish_status(&mut self, status: &DaemonStatus) -> Result<(), IoError>;
    /// Blocks until new input (a joint state) may be available or `timeout_ns` passed;
    /// `Ok(true)` if woken by input. Spurious wake-ups are allowed (the caller re-polls). Used
    /// only by the lockstep trigger (`[loop] trigger = "lockstep"`).
    fn wait_input(&mut self, timeout_ns: u64) -> Result<bool, IoError>;
    /// Like [`Backend::wait_input`], but for the torque request: the lockstep trigger calls it
    /// when it has the new state and misses only the request answering it. Default: `wait_input`.
    fn wait_request(&mut self, timeout_ns: u64) -> Result<bool, IoError> {
        self.wait_input(timeout_ns)
    }
    /// The backend's I/O-link counters since start, tagged with its [`frictionless_shm_types::BusKind`]
    /// (every backend also puts them into each status it publishes).
    fn bus_counters(&self) -> BusCounters;
}

/// The configured backend (static dispatch).
// Built once at start and owned by the RT thread for its lifetime: variant size does not matter.
#[allow(clippy::large_enum_variant)]
pub enum AnyBackend {
    /// iceoryx2 shared memory.
    Shm(shm::ShmBackend),
    /// SocketCAN drives (+ shared memory for requests, command mirror and status).
    Can(can::CanBackend),
}

impl AnyBackend {
    /// Opens the backend named by `[backend] kind`. Set-up time only (allocates, logs).
    pub fn open(cfg: &Config) -> Result<Self, BackendError> {
        match cfg.raw.backend.kind {
            BackendKind::Shm => Ok(Self::Shm(shm::ShmBackend::open(&shm::ipc_config(cfg))?)),
            BackendKind::Can => Ok(Self::Can(can::CanBackend::open(cfg)?)),
        }
    }

    /// What a reload from `running` to `new` would change that the running backend fixed when it
    /// opened (each entry names the bus or joint with the old and new value); empty when a reload
    /// may apply `new`. The shared-memory backend fixes nothing beyond `[backend]` itself (which a
    /// reload never applies); the CAN backend fixes its buses and drives
    /// ([`can::reload_conflicts`]). Reload time, not the RT thread.
    pub fn reload_conflicts(running: &Config, new: &Config) -> Vec<String> {
        match running.raw.backend.kind {
            BackendKind::Shm => Vec::new(),
            BackendKind::Can => can::reload_conflicts(running, new),
        }
    }
}

impl Backend for AnyBackend {
    #[inline]
    fn read_states(&mut self) -> Result<Option<JointStates>, IoError> {
        match self {
            Self::Shm(b) => b.read_states(),
            Self::Can(b) => b.read_states(),
        }
    }
    #[inline]
    fn read_request(&mut self) -> Result<Option<TorqueRequest>, IoError> {
        match self {
            Self::Shm(b) => b.read_request(),
            Self::Can(b) => b.read_request(),
        }
    }
    #[inline]
    fn publish_command(&mut self, cmd: &MotorCurrentCommand) -> Result<(), IoError> {
        match self {
            Self::Shm(b) => b.publish_command(cmd),
            Self::Can(b) => b.publish_command(cmd),
        }
    }
    #[inline]
    fn publish_status(&mut self, status: &DaemonStatus) -> Result<(), IoError> {
        match self {
            Self::Shm(b) => b.publish_status(status),
            Self::Can(b) => b.publish_status(status),
        }
    }
    #[inline]
    fn wait_input(&mut self, timeout_ns: u64) -> Result<bool, IoError> {
        match self {
            Self::Shm(b) => b.wait_input(timeout_ns),
            Self::Can(b) => b.wait_input(timeout_ns),
        }
    }
    #[inline]
    fn wait_request(&mut self, timeout_ns: u64) -> Result<bool, IoError> {
        match self {
            Self::Shm(b) => b.wait_request(timeout_ns),
            Self::Can(b) => b.wait_request(timeout_ns),
        }
    }
    #[inline]
    fn bus_counters(&self) -> BusCounters {
        match self {
            Self::Shm(b) => b.bus_counters(),
            Self::Can(b) => b.bus_counters(),
        }
    }
}
