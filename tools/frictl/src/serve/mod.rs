//! `frictl sim serve`: the virtual joints as a plant process that speaks the robot's interfaces.
//!
//! What this module **is**: the set of served joints ([`ServedJoint`], built by [`build_joints`]
//! from presets) and two transports over it — [`shm`] (iceoryx2 `JointStates` out,
//! `MotorCurrentCommand` in, plus the simulator-only `SimTruth` / `SimDisturbance`; real time at
//! 1 kHz or `--lockstep`) and [`can`] (the joints answer as motor drives on a SocketCAN bus, MIT or
//! ODrive protocol).
//!
//! Also here: [`install_stop_flag`], the SIGINT/SIGTERM flag the serving (and live acquiring)
//! commands poll for a clean shutdown.
//!
//! What it is **not**: no physics (that is [`frictionless_sim`]), no control (the daemon and the
//! experiment controller are separate processes).

pub mod can;
pub mod shm;

use frictionless_sim::params::load_table;
use frictionless_sim::{Plant, PlantParams};

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
    let names: Vec<&str> = presets.split(',').map(str::trim).collect();
    frictionless_sim::params::check_set_joints(sets, &names)?;
    let mut out = Vec::new();
    for (index, name) in names.iter().copied().enumerate() {
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

static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

extern "C" fn on_stop_signal(_sig: libc::c_int) {
    // Async-signal-safe: one atomic store.
    STOP.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// Installs SIGINT and SIGTERM handlers that set a process-wide flag and returns it. Plain
/// `sigaction` with an atomic store (async-signal-safe): the tools crate has no signal-hook
/// dependency. Calling it again is harmless.
pub fn install_stop_flag() -> anyhow::Result<&'static std::sync::atomic::AtomicBool> {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: a zeroed sigaction with a valid handler address and an empty mask; the handler
        // only stores to an atomic.
        let rc = unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_stop_signal as extern "C" fn(libc::c_int) as usize;
            libc::sigemptyset(&mut sa.sa_mask);
            libc::sigaction(sig, &sa, std::ptr::null_mut())
        };
        anyhow::ensure!(
            rc == 0,
            "installing the handler for signal {sig}: {}",
            std::io::Error::last_os_error()
        );
    }
    Ok(&STOP)
}
