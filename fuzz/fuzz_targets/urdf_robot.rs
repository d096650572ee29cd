//! Fuzz target: arbitrary text as a URDF, through what `frictl dynamics`, `frictl import --urdf` and the
//! simulator's link model do with one: `Robot::from_urdf_str` (the geometry pre-pass, urdf-rs, the tree
//! build with fixed joints lumped), then, for an accepted model, RNEA and the gravity torques at a
//! non-trivial state.
//!
//! Each must return an error or a value, never panic.
#![no_main]

use frictionless_dynamics::{Robot, Workspace};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(robot) = Robot::from_urdf_str(text, "<fuzz>") else {
        return;
    };
    let n = robot.dof();
    let q: Vec<f64> = (0..n).map(|i| 0.3 * (i as f64 + 1.0)).collect();
    let qd = vec![0.5; n];
    let qdd = vec![-1.0; n];
    let mut ws = Workspace::new(&robot);
    let mut tau = vec![0.0; n];
    let _ = robot.rnea(&mut ws, &q, &qd, &qdd, &mut tau);
    let _ = robot.gravity_torques(&mut ws, &q, &mut tau);
    let _ = robot.total_mass_kg();
});
