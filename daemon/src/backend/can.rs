//! SocketCAN backend: motor drives on CAN buses (MIT mini-cheetah / CubeMars, ODrive CAN Simple).
//!
//! What this module **is**: [`CanBackend`] — to be built in the SocketCAN issue (#6): raw
//! non-blocking sockets per `[[bus]]`, feedback frames → [`JointStates`], current commands → drive
//! frames, torque requests / command mirror / status over shared memory.
//!
//! What it is **not** (yet): working. `open` refuses with a clear error until the backend lands.

use frictionless_shm_types::{
    DaemonStatus, IoError, JointStates, MotorCurrentCommand, TorqueRequest,
};

use super::Backend;
use crate::config::Config;

/// SocketCAN drives (+ shared memory for requests, command mirror and status).
pub struct CanBackend {
    _private: (),
}

impl CanBackend {
    /// Opens every configured bus. Set-up time only.
    pub fn open(_cfg: &Config) -> Result<Self, String> {
        Err("the SocketCAN backend is not built yet".to_owned())
    }
}

impl Backend for CanBackend {
    fn read_states(&mut self) -> Result<Option<JointStates>, IoError> {
        Ok(None)
    }
    fn read_request(&mut self) -> Result<Option<TorqueRequest>, IoError> {
        Ok(None)
    }
    fn publish_command(&mut self, _cmd: &MotorCurrentCommand) -> Result<(), IoError> {
        Ok(())
    }
    fn publish_status(&mut self, _status: &DaemonStatus) -> Result<(), IoError> {
        Ok(())
    }
    fn wait_input(&mut self, _timeout_ns: u64) -> Result<bool, IoError> {
        Ok(false)
    }
}
