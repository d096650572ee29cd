//! What the robot-log importer targets share (`log_importers`, `mat_import`, through `#[path]`): a
//! scratch directory for the files the readers open, and what every accepted [`ImportedRun`] must
//! satisfy, whichever importer produced it.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use frictionless_logs::ImportedRun;

/// One scratch directory per fuzzing process (the readers take paths), in /dev/shm where it exists.
pub fn scratch_dir() -> &'static PathBuf {
    static D: OnceLock<PathBuf> = OnceLock::new();
    D.get_or_init(|| {
        let base = if Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        let d = base.join(format!("frictionless-fuzz-logs-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("scratch dir");
        d
    })
}

/// The invariants of an accepted run: at least two rows, one chunk id and one finite value per row in
/// every signal, strictly increasing finite time, and a report that counts the rows it used.
pub fn check(run: &ImportedRun) {
    let s = &run.signals;
    let n = s.time_s.len();
    assert!(n >= 2, "an accepted run has at least 2 rows");
    assert_eq!(s.chunk.len(), n, "one chunk id per row");
    assert_eq!(run.report.rows_used, n as u64, "rows_used counts the rows");
    assert!(run.report.rows_used <= run.report.rows_read);
    assert!(
        s.time_s.iter().all(|t| t.is_finite()) && s.time_s.windows(2).all(|w| w[0] < w[1]),
        "time is finite and strictly increasing"
    );
    for col in signals(s).into_iter().flatten() {
        assert_eq!(col.len(), n, "one value per row in every signal");
        assert!(col.iter().all(|v| v.is_finite()), "every value is finite");
    }
}

/// Every signal a run may hold.
pub fn signals(s: &frictionless_logs::RunSignals) -> [&Option<Vec<f64>>; 10] {
    [
        &s.s_rad,
        &s.sdot_rad_s,
        &s.sddot_rad_s2,
        &s.theta_motor_rad,
        &s.omega_motor_rad_s,
        &s.current_a,
        &s.tau_joint_nm,
        &s.tau_motor_nm,
        &s.tau_f_nm,
        &s.temperature_c,
    ]
}
