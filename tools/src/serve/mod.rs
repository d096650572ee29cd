//! `frictl sim serve`: the virtual joints as a plant process that speaks the robot's interfaces.
//!
//! What this module **is**: the set of served joints ([`ServedJoint`], built by [`build_joints`]
//! from presets) and two transports over it — [`shm`] (iceoryx2 `JointStates` out,
//! `MotorCurrentCommand` in, plus the simulator-only `SimTruth` / `SimDisturbance`; real time at
//! 1 kHz or `--lockstep`) and [`can`] (the joints answer as motor drives on a SocketCAN bus, MIT or
//! ODrive protocol).
//!
//! What it is **not**: no physics (that is [`crate::sim`]), no control (the daemon and the
//! experiment controller are separate processes).

pub mod can;
pub mod shm;

use crate::sim::params::load_table;
use crate::sim::{Plant, PlantParams};

/// One virtual joint on a payload index / bus node.
pub struct ServedJoint {
    /// Preset name or file it was built from (`knee`, `ankle_roll`, …).
    pub name: String,
    /// Index into the shared-memory payload arrays (0-based, in `--preset` order).
    pub index: usize,
    /// The simulated joint.
    pub plant: Plant,
}

/// Builds one plant per comma-separated preset (`knee,ankle_roll`), indices 0, 1, … in that order.
/// `params_file` and `sets` apply to every preset; each plant gets seed `seed + index`.
pub fn build_joints(
    presets: &str,
    params_file: Option<&std::path::Path>,
    sets: &[String],
    seed: u64,
) -> anyhow::Result<Vec<ServedJoint>> {
    let mut out = Vec::new();
    for (index, name) in presets.split(',').map(str::trim).enumerate() {
        anyhow::ensure!(!name.is_empty(), "--preset `{presets}`: empty preset name");
        anyhow::ensure!(
            index < frictionless_shm_types::MAX_JOINTS,
            "--preset `{presets}`: more than {} joints",
            frictionless_shm_types::MAX_JOINTS
        );
        let table = load_table(name, params_file, sets)?;
        let p = PlantParams::from_table(&table)?;
        let plant = Plant::from_params(p, seed.wrapping_add(index as u64))?;
        out.push(ServedJoint {
            name: name.to_owned(),
            index,
            plant,
        });
    }
    Ok(out)
}
