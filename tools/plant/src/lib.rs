//! # `frictionless-plant`: the virtual robot as a process that speaks the robot's interfaces
//!
//! Crate table: `tools/plant`; depends on `frictionless-sim` (the physics), `frictionless-shm-types`
//! (payloads, CAN codecs) and `frictionless-acquire` (the `JointIo` seam of live acquisition); used by
//! `frictl` (`sim serve`, `acquire --live-shm`) and the daemon's end-to-end tests.
//!
//! What this crate **is**: the served robot ([`ServedRobot`], built by [`build_robot`] from
//! presets: N independent single-joint plants, or the coupled leg of `--preset leg` whose joints
//! are stepped together through one [`LegPlant`]) and two transports over it — [`shm`] (iceoryx2 `JointStates` out,
//! `MotorCurrentCommand` in, plus the simulator-only `SimTruth` / `SimDisturbance`; real time at
//! 1 kHz or `--lockstep`) and [`can`] (the joints answer as motor drives on a SocketCAN bus, MIT or
//! ODrive protocol).
//!
//! Also here: [`install_stop_flag`], the SIGINT/SIGTERM flag the serving (and live acquiring)
//! commands poll for a clean shutdown.
//!
//! What it is **not**: no physics (that is [`frictionless_sim`]), no control (the daemon and the
//! experiment controller are separate processes).

#![warn(missing_docs)]

pub mod can;
pub mod shm;

use frictionless_drives::can::CanCodecError;
use frictionless_shm_types::{IoError, ShmError};
use frictionless_sim::params::{ParamError, load_table};
use frictionless_sim::{LegError, LegParams, LegPlant, Measurement, Plant, PlantParams, Truth};

/// The `--preset` name of the coupled leg (`config/presets/leg.toml`).
pub const LEG_PRESET: &str = "leg";

/// Why building, opening or serving the virtual joints failed. Messages name the option, joint,
/// interface or service and the cause.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// A preset, parameter file or `--set` override is not acceptable.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// An empty name in the comma-separated preset list.
    #[error("--preset `{presets}`: empty preset name")]
    EmptyPreset {
        /// The `--preset` value.
        presets: String,
    },
    /// More presets than the payloads have joint slots.
    #[error("--preset `{presets}`: more than {max} joints")]
    TooManyPresets {
        /// The `--preset` value.
        presets: String,
        /// [`frictionless_shm_types::MAX_JOINTS`].
        max: usize,
    },
    /// `sigaction` failed.
    #[error("installing the handler for signal {sig}")]
    Signal {
        /// The signal number.
        sig: i32,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Nothing to serve.
    #[error("no joints to serve")]
    NoJoints,
    /// More joints than the shared-memory payloads hold.
    #[error("{n} joints: at most {max}")]
    TooManyJoints {
        /// Joints requested.
        n: usize,
        /// [`frictionless_shm_types::MAX_JOINTS`].
        max: usize,
    },
    /// `--initial-pose-rad` does not give one value per joint.
    #[error("--initial-pose-rad has {values} values for {joints} joints")]
    InitialPoseCount {
        /// Values given.
        values: usize,
        /// Joints served.
        joints: usize,
    },
    /// A non-finite initial pose.
    #[error(
        "--initial-pose-rad entry {} (joint index {k}) is {value}: not a finite angle [rad]",
        .k + 1
    )]
    InitialPoseValue {
        /// Position in the list (0-based: the served joint's index).
        k: usize,
        /// The value.
        value: f64,
    },
    /// The shared-memory plant's `--duration-s` is negative or not finite.
    #[error("--duration-s must be ≥ 0, got {0}")]
    ShmDuration(f64),
    /// The CAN plant's `--duration-s` is negative or not finite.
    #[error("--duration-s {0}: must be finite and ≥ 0")]
    CanDuration(f64),
    /// A joint whose plant does not run at the served 1 kHz.
    #[error(
        "joint {index} (`{joint}`): sample period {period_s} s, the served plant runs at 1 kHz (1e-3 s)"
    )]
    SamplePeriod {
        /// Payload index.
        index: usize,
        /// Preset name.
        joint: String,
        /// The plant's sample period [s].
        period_s: f64,
    },
    /// The live client's joint index does not fit the payloads.
    #[error("--joint-index {index}: at most {max}")]
    JointIndexRange {
        /// The requested index.
        index: usize,
        /// The largest index.
        max: usize,
    },
    /// Opening the iceoryx2 node failed.
    #[error("opening iceoryx2 node")]
    OpenNode(#[source] ShmError),
    /// Opening an iceoryx2 service or port failed.
    #[error(transparent)]
    Shm(#[from] ShmError),
    /// A send or receive on an iceoryx2 port failed.
    #[error("{what}")]
    Io {
        /// What was being done, e.g. "receiving commands".
        what: &'static str,
        /// The port's error.
        #[source]
        source: IoError,
    },
    /// The live client failed.
    #[error(transparent)]
    Live(#[from] shm::LiveError),
    /// An MIT drive on the host's reply id.
    #[error("MIT node id {node} is the host (reply) id {host}")]
    MitNodeIsHost {
        /// The node id.
        node: u8,
        /// [`can::MIT_HOST_ID`].
        host: u32,
    },
    /// An ODrive node id beyond the protocol's range.
    #[error("ODrive node id {node} out of range 0..={max}")]
    OdriveNodeRange {
        /// The node id.
        node: u8,
        /// The largest ODrive node id.
        max: u8,
    },
    /// A CiA 402 node id outside 1..=127.
    #[error("CiA 402 node id {node} out of range 1..=127")]
    Cia402NodeRange {
        /// The node id.
        node: u8,
    },
    /// The MIT ranges derived from a joint's parameters are not encodable.
    #[error("MIT ranges of joint `{joint}`")]
    MitRanges {
        /// The joint named in its parameters.
        joint: String,
        /// The codec's reason.
        #[source]
        source: CanCodecError,
    },
    /// Default node ids only go to 255.
    #[error("more than 255 joints")]
    TooManyCanJoints(#[source] std::num::TryFromIntError),
    /// `--node-ids` does not give one id per joint.
    #[error("--node-ids has {ids} ids for {joints} joints")]
    NodeIdCount {
        /// Ids given.
        ids: usize,
        /// Joints served.
        joints: usize,
    },
    /// A node id given twice.
    #[error("--node-ids: node id {0} appears twice")]
    DuplicateNodeId(u8),
    /// The leg preset listed together with other presets.
    #[error(
        "--preset `{presets}`: `leg` is a whole coupled robot and cannot be combined with other presets"
    )]
    LegMixed {
        /// The `--preset` value.
        presets: String,
    },
    /// `--params` given with the leg preset.
    #[error(
        "--params {path}: a parameter file applies to single-joint presets; change the leg's joints \
         with --set JOINT:key=value (e.g. --set l_knee:plant.f_c0_nm=3)"
    )]
    LegParamsFile {
        /// The `--params` file.
        path: String,
    },
    /// Building or stepping the coupled leg failed.
    #[error(transparent)]
    Leg(#[from] LegError),
    /// Building one joint's drive failed.
    #[error("joint `{joint}`")]
    Joint {
        /// The served joint's name.
        joint: String,
        /// Why.
        #[source]
        source: Box<ServeError>,
    },
    /// Opening the CAN interface failed.
    #[error("opening CAN interface `{bus}` (--bus)")]
    OpenBus {
        /// The interface.
        bus: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Setting the receive filters failed.
    #[error("setting receive filters on `{bus}`")]
    SetFilters {
        /// The interface.
        bus: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// An operation on the open CAN socket failed.
    #[error("{what}")]
    CanSocket {
        /// What was being done, e.g. "reading from the CAN socket".
        what: &'static str,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
}

/// The served plants behind the payload indices.
enum Body {
    /// One independent single-joint plant per index.
    Joints(Vec<Plant>),
    /// One coupled leg; index k is the leg's joint k.
    Leg(Box<LegPlant>),
}

/// The simulated robot a transport serves: joints on payload indices / bus nodes 0, 1, …, stepped
/// together once per 1 ms tick with every joint's current reference. Independent single-joint
/// plants and the coupled leg look the same from here (and from the wire): per joint its
/// parameters, its emulated sensors and its truth.
pub struct ServedRobot {
    names: Vec<String>,
    params: Vec<PlantParams>,
    body: Body,
}

impl ServedRobot {
    /// Independent single-joint plants, named by their presets, on indices 0, 1, … in order.
    pub fn independent(plants: Vec<(String, Plant)>) -> Self {
        let (names, plants): (Vec<String>, Vec<Plant>) = plants.into_iter().unzip();
        let params = plants.iter().map(|p| p.params().clone()).collect();
        Self {
            names,
            params,
            body: Body::Joints(plants),
        }
    }

    /// The coupled leg; the served joints are the leg's joints in its parameters' order, named by
    /// their URDF joints.
    pub fn leg(leg: LegPlant) -> Self {
        let params = leg.params().joints.clone();
        Self {
            names: params.iter().map(|p| p.joint.clone()).collect(),
            params,
            body: Body::Leg(Box::new(leg)),
        }
    }

    /// Number of served joints.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Whether nothing is served.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Whether the joints are coupled through one leg.
    pub fn is_leg(&self) -> bool {
        matches!(self.body, Body::Leg(_))
    }

    /// Name of joint `k` (preset name, or the leg's URDF joint).
    pub fn name(&self, k: usize) -> &str {
        &self.names[k]
    }

    /// Drive parameters of joint `k`.
    pub fn params(&self, k: usize) -> &PlantParams {
        &self.params[k]
    }

    /// The newest emulated sensors of joint `k` (the initial ones before the first step).
    pub fn measurement(&self, k: usize) -> Measurement {
        match &self.body {
            Body::Joints(p) => p[k].measurement(),
            Body::Leg(leg) => leg.samples()[k].meas,
        }
    }

    /// The newest truth of joint `k`.
    pub fn truth(&self, k: usize) -> Truth {
        match &self.body {
            Body::Joints(p) => p[k].truth(),
            Body::Leg(leg) => leg.samples()[k].truth,
        }
    }

    /// Puts every joint at rest at `q0_rad` (one finite value per joint, gravity held by the
    /// flexsplines).
    pub fn reset_at_rest(&mut self, q0_rad: &[f64]) -> Result<(), ServeError> {
        if q0_rad.len() != self.len() {
            return Err(ServeError::InitialPoseCount {
                values: q0_rad.len(),
                joints: self.len(),
            });
        }
        if let Some((k, &value)) = q0_rad.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(ServeError::InitialPoseValue { k, value });
        }
        match &mut self.body {
            Body::Joints(p) => {
                for (plant, &q) in p.iter_mut().zip(q0_rad) {
                    plant.reset_at_rest(q);
                }
            }
            Body::Leg(leg) => leg.reset_at_rest(q0_rad)?,
        }
        Ok(())
    }

    /// Advances every joint one control sample with its current reference `i_ref_a[k]` [A]
    /// (saturated at the joint's ±i_max, NaN → 0) and external joint torque `tau_ext_nm[k]` [Nm];
    /// one value per joint. Allocation-free.
    pub fn step(&mut self, i_ref_a: &[f64], tau_ext_nm: &[f64]) -> Result<(), ServeError> {
        match &mut self.body {
            Body::Joints(p) => {
                for ((plant, &i), &t) in p.iter_mut().zip(i_ref_a).zip(tau_ext_nm) {
                    plant.step(i, t);
                }
            }
            Body::Leg(leg) => {
                leg.step(i_ref_a, tau_ext_nm)?;
            }
        }
        Ok(())
    }
}

/// Builds the served robot from a comma-separated preset list: one independent plant per preset
/// (`knee,ankle_roll`: indices 0, 1 in that order; `params_file` and `sets` apply to every preset;
/// each plant gets seed `seed + index`), or `leg` alone: the coupled ergoCub left leg
/// (`config/presets/leg.toml`, six joints; `sets` as `JOINT:key=value` on the leg's joints, seed
/// `seed`).
pub fn build_robot(
    presets: &str,
    params_file: Option<&std::path::Path>,
    sets: &[String],
    seed: u64,
) -> Result<ServedRobot, ServeError> {
    let names: Vec<&str> = presets.split(',').map(str::trim).collect();
    if names.contains(&LEG_PRESET) {
        if names.len() > 1 {
            return Err(ServeError::LegMixed {
                presets: presets.to_owned(),
            });
        }
        if let Some(path) = params_file {
            return Err(ServeError::LegParamsFile {
                path: path.display().to_string(),
            });
        }
        let params =
            LegParams::from_toml_str(frictionless_sim::leg::LEG_PRESET_TOML, "<preset leg>", sets)?;
        if params.joints.len() > frictionless_shm_types::MAX_JOINTS {
            return Err(ServeError::TooManyPresets {
                presets: presets.to_owned(),
                max: frictionless_shm_types::MAX_JOINTS,
            });
        }
        return Ok(ServedRobot::leg(LegPlant::new(params, seed)?));
    }
    frictionless_sim::params::check_set_joints(sets, &names)?;
    let mut out = Vec::new();
    for (index, name) in names.iter().copied().enumerate() {
        if name.is_empty() {
            return Err(ServeError::EmptyPreset {
                presets: presets.to_owned(),
            });
        }
        if index >= frictionless_shm_types::MAX_JOINTS {
            return Err(ServeError::TooManyPresets {
                presets: presets.to_owned(),
                max: frictionless_shm_types::MAX_JOINTS,
            });
        }
        let table = load_table(name, params_file, sets)?;
        let p = PlantParams::from_table(&table)?;
        let plant = Plant::from_params(p, seed.wrapping_add(index as u64))?;
        out.push((name.to_owned(), plant));
    }
    Ok(ServedRobot::independent(out))
}

static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

extern "C" fn on_stop_signal(_sig: libc::c_int) {
    // Async-signal-safe: one atomic store.
    STOP.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// Installs SIGINT and SIGTERM handlers that set a process-wide flag and returns it. Plain
/// `sigaction` with an atomic store (async-signal-safe): the tools crate has no signal-hook
/// dependency. Calling it again is harmless.
pub fn install_stop_flag() -> Result<&'static std::sync::atomic::AtomicBool, ServeError> {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: a zeroed sigaction with a valid handler address and an empty mask; the handler
        // only stores to an atomic.
        let rc = unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_stop_signal as extern "C" fn(libc::c_int) as usize;
            libc::sigemptyset(&mut sa.sa_mask);
            libc::sigaction(sig, &sa, std::ptr::null_mut())
        };
        if rc != 0 {
            return Err(ServeError::Signal {
                sig,
                source: std::io::Error::last_os_error(),
            });
        }
    }
    Ok(&STOP)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A non-finite pose names its entry as the option counts them (from 1) and the joint's
    /// index (before: "value 0 is NaN", the 0 an index read as a value).
    #[test]
    fn a_non_finite_initial_pose_names_its_entry_and_joint_index() {
        let mut robot = build_robot("knee,knee", None, &[], 0).unwrap();
        let e = robot
            .reset_at_rest(&[0.1, f64::NAN])
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "--initial-pose-rad entry 2 (joint index 1) is NaN: not a finite angle [rad]"
        );
    }
}
