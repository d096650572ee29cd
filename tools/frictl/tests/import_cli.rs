//! `frictl import csv|mcap|mat` as a user runs it: two CSV logs of a virtual joint (jittered 2–3 ms
//! time, position in degrees, a given friction column, pauses) → `frictl import csv` → `frictl fit
//! scv` → `frictl train --features delta-theta-joint-vel`; the sidecar's runs, label, absent columns
//! and conversions; errors naming the column and header; `import mcap` on a bag written by the Python
//! `mcap` packages (`#[ignore]`d: needs `FRICTIONLESS_PY`, set by `tests/run.sh`); `import mat` without the `mat` feature.

use crate::util::{err_text, frictl, ok, s};
use std::path::{Path, PathBuf};
use std::process::Command;

fn dir() -> PathBuf {
    let d = crate::util::scratch("frictl-import-cli");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A virtual joint (r = −100) moving as A·sin(w·t) with CV friction 2·tanh(50ṡ) + 1.5ṡ and a
/// deflection Δθ = 0.002·τ_F; four 6 s segments separated by 0.3 s pauses; time jittered 2–3 ms.
fn write_log(path: &Path, w: f64, seed: u64) {
    let mut text = String::from("time,q_deg,theta_motor,friction_nm\n");
    let (mut t, mut k) = (0.0f64, seed);
    let mut seg_end = 6.0;
    while t < 25.0 {
        if t > seg_end {
            t += 0.3;
            seg_end += 6.3;
        }
        let q = 0.5 * (w * t).sin();
        let v = 0.5 * w * (w * t).cos();
        let f = 2.0 * (50.0 * v).tanh() + 1.5 * v;
        let theta = -100.0 * q - 0.002 * f;
        text += &format!("{t:.6},{},{theta},{f}\n", q.to_degrees());
        k += 1;
        t += 0.002 + 0.001 * ((k * 7919) % 11) as f64 / 10.0;
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn csv_logs_import_fit_and_train() {
    let d = dir();
    let (slow, fast) = (d.join("slow.csv"), d.join("fast.csv"));
    write_log(&slow, 1.0, 1);
    write_log(&fast, 3.0, 2);
    let ds = d.join("ds.csv");
    let out = ok(
        frictl(&[
            "import",
            "csv",
            s(&slow),
            s(&fast),
            "--joint",
            "wrist",
            "--column",
            "time=time",
            "--column",
            "s=q_deg",
            "--column",
            "theta=theta_motor",
            "--column",
            "tau_f=friction_nm",
            "--unit",
            "s=deg",
            "--gear-ratio",
            "-100",
            "--kt",
            "0.1",
            "-o",
            s(&ds),
        ]),
        "import csv",
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("2 runs"), "{err}");
    assert!(!err.contains("anti-correlated"), "{err}");
    let side: frictionless_dataset::DatasetSidecar =
        serde_json::from_str(&std::fs::read_to_string(d.join("ds.json")).unwrap()).unwrap();
    assert_eq!(side.label, frictionless_dataset::LabelSource::Given);
    let names: Vec<&str> = side.runs.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["slow", "fast"]);
    assert_eq!(side.runs[0].chunks, [0, 1, 2, 3]);
    assert_eq!(side.runs[1].chunks, [4, 5, 6, 7]);
    assert_eq!(side.chunks, 8);
    for c in [
        "temperature_c",
        "i_meas_a",
        "omega_motor_rad_s",
        "tau_id_nm",
    ] {
        assert!(
            side.absent_columns.iter().any(|a| a == c),
            "{c}: {:?}",
            side.absent_columns
        );
    }
    assert!(
        !side
            .absent_columns
            .iter()
            .any(|a| a == "delta_theta_motor_rad")
    );
    assert_eq!(side.gear_ratio_signed, -100.0);
    let conv = side.settings["import"]["runs"][0]["report"]["conversions"].to_string();
    assert!(conv.contains("s: deg x"), "{conv}");
    let data = frictionless_dataset::Dataset::read_csv(&ds).unwrap();
    // Δθ = r·s − θ − offset = 0.002·τ_F − offset: the deflection survives resampling.
    let (mut e, mut n) = (0.0f64, 0);
    for k in 0..data.len() {
        if data.valid[k] && data.chunk[k] < 4 {
            let want = 0.002 * data.tau_f_label_nm[k];
            e = e
                .max((data.delta_theta_motor_rad[k] - want + 0.002 * data.tau_f_label_nm[0]).abs());
            n += 1;
        }
    }
    assert!(n > 20_000 && e < 2e-3, "max Δθ error {e} on {n} samples");

    let scv = d.join("scv.json");
    ok(
        frictl(&["fit", "scv", s(&ds), "--json", s(&scv)]),
        "fit scv",
    );
    let fwt = d.join("m.fwt");
    ok(
        frictl(&[
            "train",
            "--quiet",
            "--dataset",
            s(&ds),
            "--scv",
            s(&scv),
            "--out",
            s(&fwt),
            "--features",
            "delta-theta-joint-vel",
            "--history",
            "5",
            "--hidden",
            "16,12",
            "--epochs",
            "2",
            "--batch",
            "1024",
            "--threads",
            "2",
        ]),
        "train",
    );
    let m = frictionless::weights::read_file(&fwt).unwrap();
    assert_eq!(m.meta.joint_name, "wrist");
    assert_eq!(m.meta.gear_ratio.get(), -100.0);
}

#[test]
fn import_errors_name_the_column_header_and_unit() {
    let d = dir();
    let log = d.join("e.csv");
    std::fs::write(&log, "t,q\n0,1\n0.002,2\n").unwrap();
    let out = d.join("e_out.csv");
    let base = ["import", "csv", s(&log), "--joint", "j", "-o", s(&out)];
    let mut a = base.to_vec();
    a.extend(["--column", "time=t", "--column", "s=pos"]);
    let e = err_text(frictl(&a), "missing column");
    assert!(e.contains("`pos`") && e.contains("t, q"), "{e}");
    let mut a = base.to_vec();
    a.extend(["--column", "time=t", "--column", "s=q", "--unit", "s=grad"]);
    let e = err_text(frictl(&a), "bad unit");
    assert!(e.contains("grad") && e.contains("rad, deg"), "{e}");
    let mut a = base.to_vec();
    a.extend(["--column", "time=t", "--column", "s=q"]);
    let e = err_text(frictl(&a), "current label without current");
    assert!(e.contains("current"), "{e}");
    assert!(!out.exists(), "nothing written on error");
}

#[test]
fn a_friction_column_of_the_opposite_sign_is_warned_about() {
    let d = dir();
    let log = d.join("neg.csv");
    write_log(&log, 2.0, 3);
    let ds = d.join("neg_ds.csv");
    let out = ok(
        frictl(&[
            "import",
            "csv",
            s(&log),
            "--joint",
            "wrist",
            "--column",
            "time=time",
            "--column",
            "s=q_deg",
            "--column",
            "tau_f=friction_nm",
            "--unit",
            "s=deg",
            "--negate",
            "tau_f",
            "-o",
            s(&ds),
        ]),
        "import csv --negate tau_f",
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("anti-correlated"), "{err}");
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("neg_ds.json")).unwrap()).unwrap();
    let w = side["settings"]["import"]["warnings"].to_string();
    assert!(w.contains("anti-correlated"), "{w}");
    let conv = side["settings"]["import"]["runs"][0]["report"]["conversions"].to_string();
    assert!(
        conv.contains("tau_f: Nm (no conversion), negated"),
        "{conv}"
    );
}

#[cfg(not(feature = "mat"))]
#[test]
fn import_mat_without_the_feature_says_how_to_build_it() {
    let d = dir();
    let f = d.join("x.mat");
    std::fs::write(&f, b"MATLAB 7.3 MAT-file").unwrap();
    let e = err_text(
        frictl(&["import", "mat", s(&f), "-o", s(&d.join("x.csv"))]),
        "import mat",
    );
    assert!(
        e.contains("libhdf5-dev") && e.contains("--features mat"),
        "{e}"
    );
}

#[test]
#[ignore = "needs FRICTIONLESS_PY: bash tests/run.sh"]
fn mcap_bag_imports_with_the_effort_as_given_friction() {
    let py = std::env::var_os("FRICTIONLESS_PY").expect(
        "FRICTIONLESS_PY is unset: run bash tests/run.sh (python with mcap, mcap-ros2-support)",
    );
    let d = dir();
    let bag = d.join("bag.mcap");
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../logs/tests/fixtures/make_fixtures.py");
    let st = Command::new(py)
        .arg(script)
        .arg("mcap")
        .arg(&bag)
        .status()
        .unwrap();
    assert!(st.success());
    let ds = d.join("bag_ds.csv");
    ok(
        frictl(&[
            "import",
            "mcap",
            s(&bag),
            "--joint",
            "wrist",
            "--effort",
            "tau_f",
            "-o",
            s(&ds),
        ]),
        "import mcap",
    );
    let side: frictionless_dataset::DatasetSidecar =
        serde_json::from_str(&std::fs::read_to_string(d.join("bag_ds.json")).unwrap()).unwrap();
    assert_eq!(side.label, frictionless_dataset::LabelSource::Given);
    assert_eq!(side.runs.len(), 1);
    assert_eq!(side.runs[0].chunks, [0, 1]);
    assert!(side.absent_columns.iter().any(|c| c == "theta_motor_rad"));
}

#[cfg(feature = "mat")]
#[test]
#[ignore = "needs FRICTIONLESS_PY: bash tests/run.sh"]
fn mat_file_imports_with_the_current_label_and_two_chunks() {
    let py = std::env::var_os("FRICTIONLESS_PY")
        .expect("FRICTIONLESS_PY is unset: run bash tests/run.sh (python with numpy, h5py)");
    let d = dir();
    let mat = d.join("robot_logger_device_2024_01_01_00_00_00.mat");
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../logs/tests/fixtures/make_fixtures.py");
    let st = Command::new(py)
        .arg(script)
        .arg("mat")
        .arg(&mat)
        .status()
        .unwrap();
    assert!(st.success());
    let ds = d.join("mat_ds.csv");
    ok(
        frictl(&[
            "import",
            "mat",
            s(&mat),
            "--gear-ratio",
            "-100",
            "--kt",
            "0.11",
            "--urdf",
            "virtual_leg",
            "-o",
            s(&ds),
        ]),
        "import mat",
    );
    let side: frictionless_dataset::DatasetSidecar =
        serde_json::from_str(&std::fs::read_to_string(d.join("mat_ds.json")).unwrap()).unwrap();
    assert_eq!(
        side.joint, "l_knee",
        "picked from the desired-current channel"
    );
    assert_eq!(side.label, frictionless_dataset::LabelSource::Current);
    assert_eq!(side.runs.len(), 1);
    assert_eq!(
        side.runs[0].chunks,
        [0, 1],
        "the 1.6 s gap of the desired current"
    );
    assert!(side.absent_columns.iter().any(|c| c == "temperature_c"));
    let data = frictionless_dataset::Dataset::read_csv(&ds).unwrap();
    // 2 s and 2.4 s of 500 Hz ticks on the 1 kHz grid (epoch stamps: the last grid point may fall a
    // rounding error beyond the last tick).
    let n0 = data.chunk.iter().filter(|c| **c == 0).count();
    let n1 = data.chunk.iter().filter(|c| **c == 1).count();
    assert!((1998..=1999).contains(&n0), "{n0}");
    assert!((2398..=2399).contains(&n1), "{n1}");
    let k = 500;
    assert!((data.i_meas_a[k] - (0.2 + 0.1 * (3.0 * data.time_s[k]).sin())).abs() < 1e-6);
    let e = err_text(
        frictl(&[
            "import",
            "mat",
            s(&mat),
            "--joint",
            "r_elbow",
            "--gear-ratio",
            "-100",
            "--kt",
            "0.11",
            "-o",
            s(&ds),
        ]),
        "unknown joint",
    );
    assert!(e.contains("r_elbow") && e.contains("l_knee"), "{e}");
}

/// The whole-body log of `make_fixtures.py leg` (Pinocchio on the ergoCub URDF: the six left-leg
/// joints move, the other leg and torso joints are held; knee current = (whole-body τ_ID + SCV
/// friction)/(r·k_t)), written once per test process.
pub(crate) fn leg_fixture() -> PathBuf {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let py = std::env::var_os("FRICTIONLESS_PY")
            .expect("FRICTIONLESS_PY must name a python with pinocchio, h5py, mcap (tests/run.sh)");
        let d = dir().join("leg");
        let script =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../logs/tests/fixtures/make_fixtures.py");
        let st = Command::new(py)
            .arg(script)
            .arg("leg")
            .arg(ergocub_urdf())
            .arg(&d)
            .status()
            .unwrap();
        assert!(st.success(), "make_fixtures.py leg failed");
        d
    })
    .clone()
}

pub(crate) fn ergocub_urdf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/ergocub/ergoCubSN001.urdf")
}

const LEG: [&str; 6] = [
    "l_hip_pitch",
    "l_hip_roll",
    "l_hip_yaw",
    "l_knee",
    "l_ankle_pitch",
    "l_ankle_roll",
];

/// A column of the fixture's reference CSV (1 kHz from t = 0).
pub(crate) fn leg_ref(column: &str) -> Vec<f64> {
    let cols = frictionless_dataset::read_columns(&leg_fixture().join("leg_ref.csv")).unwrap();
    cols.get(column)
        .unwrap_or_else(|| panic!("leg_ref.csv has no {column}"))
        .clone()
}

/// RMS of `column(ds) − reference` over the dataset's valid samples, the reference indexed by the
/// sample time (both 1 kHz grids from the log's first sample).
pub(crate) fn rms_vs(
    ds: &frictionless_dataset::Dataset,
    got: &[f64],
    reference: &[f64],
) -> (f64, usize) {
    let (mut e2, mut n) = (0.0, 0usize);
    for ((t, valid), g) in ds.time_s.iter().zip(&ds.valid).zip(got) {
        let i = (t * 1000.0).round() as usize;
        if *valid && i < reference.len() {
            e2 += (g - reference[i]).powi(2);
            n += 1;
        }
    }
    ((e2 / n.max(1) as f64).sqrt(), n)
}

pub(crate) fn dataset(path: &Path) -> frictionless_dataset::Dataset {
    frictionless_dataset::Dataset::read_csv(path).unwrap()
}

fn sidecar(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path.with_extension("json")).unwrap()).unwrap()
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the whole-body log"]
fn csv_whole_body_label_matches_pinocchio_and_the_single_joint_view_does_not() {
    let d = leg_fixture();
    let log = d.join("leg.csv");
    let urdf = ergocub_urdf();
    let tau_ref = leg_ref("tau_id_l_knee");
    let f_ref = leg_ref("tau_f_l_knee");
    let common = [
        "--column",
        "time=t",
        "--column",
        "s=q_{joint}",
        "--column",
        "current=i_{joint}",
        "--urdf",
        s(&urdf),
        "--gear-ratio",
        "100",
        "--kt",
        "0.1",
    ];
    // Whole body: every q_<joint> column of a URDF joint.
    let out = d.join("whole_knee.csv");
    let mut args = vec!["import", "csv", s(&log), "--joint", "l_knee"];
    args.extend(common);
    args.extend(["--positions", "q_{joint}", "-o", s(&out)]);
    let run = ok(frictl(&args), "import csv --positions");
    let err = String::from_utf8_lossy(&run.stderr);
    let ds = dataset(&out);
    let (rms, n) = rms_vs(&ds, &ds.tau_id_nm, &tau_ref);
    eprintln!("whole body: knee tau_ID RMS {rms:.4} Nm on {n} samples");
    assert!(n > 10_000, "{n} valid samples");
    assert!(
        rms < 0.15,
        "whole-body knee tau_ID RMS {rms} Nm vs Pinocchio"
    );
    let (label_rms, _) = rms_vs(&ds, &ds.tau_f_label_nm, &f_ref);
    eprintln!("whole body: knee label RMS {label_rms:.4} Nm vs the true friction");
    assert!(label_rms < 0.3, "knee label RMS {label_rms}");
    let side = sidecar(&out);
    let wb = &side["settings"]["import"]["whole_body"];
    let from_log: Vec<&str> = wb["from_log"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(from_log.len(), 15, "{from_log:?}");
    for j in LEG.iter().chain(&["torso_pitch", "r_knee"]) {
        assert!(from_log.contains(j), "{j} not in {from_log:?}");
    }
    let held0 = wb["held_at_zero"].to_string();
    assert!(
        held0.contains("neck_pitch") && held0.contains("r_elbow"),
        "{held0}"
    );
    // The whole left leg is logged: the joints held at 0 (arms, head, the other leg) leave the
    // knee's label unchanged and are held silently.
    assert_eq!(wb["held_at_zero_relevant"], serde_json::json!([]), "{wb}");
    assert!(!err.contains("held at 0 rad"), "{err}");
    assert!(
        side["dynamics"]
            .as_str()
            .unwrap()
            .starts_with("whole-body RNEA"),
        "{}",
        side["dynamics"]
    );

    // The single-joint view on the same log, the other joints at their mean positions.
    let mut fixed = Vec::new();
    let cols = frictionless_dataset::read_columns(&log).unwrap();
    for (name, v) in &cols {
        if let Some(j) = name.strip_prefix("q_")
            && j != "l_knee"
        {
            fixed.push(format!("{j}={}", v.iter().sum::<f64>() / v.len() as f64));
        }
    }
    let single = d.join("single_knee.csv");
    let mut args = vec!["import", "csv", s(&log), "--joint", "l_knee"];
    args.extend(common);
    for f in &fixed {
        args.extend(["--fixed-joint", f.as_str()]);
    }
    args.extend(["-o", s(&single)]);
    ok(frictl(&args), "import csv (single-joint view)");
    let ds1 = dataset(&single);
    let (rms1, _) = rms_vs(&ds1, &ds1.tau_id_nm, &tau_ref);
    eprintln!("single-joint view: knee tau_ID RMS {rms1:.4} Nm");
    assert!(
        rms1 > 0.5,
        "the single-joint view should miss the other joints' motion: {rms1}"
    );
    assert!(
        sidecar(&single)["dynamics"]
            .as_str()
            .unwrap()
            .starts_with("single-joint view"),
    );
    // Pinocchio's own single-joint view agrees with ours.
    let (rms_pin, _) = rms_vs(&ds1, &ds1.tau_id_nm, &leg_ref("tau_single_l_knee"));
    assert!(
        rms_pin < 0.15,
        "single-joint view vs Pinocchio's: {rms_pin}"
    );
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the whole-body log"]
fn csv_joints_all_labels_every_leg_joint_in_one_pass() {
    let d = leg_fixture();
    let out = d.join("all_{joint}.csv");
    let urdf = ergocub_urdf();
    let run = ok(
        frictl(&[
            "import",
            "csv",
            s(&d.join("leg.csv")),
            "--joints",
            "all",
            "--column",
            "time=t",
            "--column",
            "s=q_{joint}",
            "--column",
            "current=i_{joint}",
            "--positions",
            "q_{joint}",
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            "-o",
            s(&out),
        ]),
        "import csv --joints all",
    );
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("6 joint(s)"), "{err}");
    for j in LEG {
        let p = d.join(format!("all_{j}.csv"));
        let ds = dataset(&p);
        let (rms, n) = rms_vs(&ds, &ds.tau_id_nm, &leg_ref(&format!("tau_id_{j}")));
        eprintln!("{j}: tau_ID RMS {rms:.4} Nm on {n} samples");
        assert!(n > 10_000 && rms < 0.15, "{j}: RMS {rms} on {n}");
        assert_eq!(sidecar(&p)["joint"], j);
    }
    // Held joints have no current column: not labelled, and said so.
    assert!(!d.join("all_torso_pitch.csv").exists());
    let notes =
        sidecar(&d.join("all_l_knee.csv"))["settings"]["import"]["runs"][0]["report"]["notes"]
            .to_string();
    assert!(
        notes.contains("not labelled") && notes.contains("torso_pitch"),
        "{notes}"
    );
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the whole-body log"]
fn mcap_whole_body_labels_two_joints_from_every_name() {
    let d = leg_fixture();
    let out = d.join("bag_{joint}.csv");
    let urdf = ergocub_urdf();
    let run = ok(
        frictl(&[
            "import",
            "mcap",
            s(&d.join("leg.mcap")),
            "--joint",
            "l_knee",
            "--joint",
            "l_ankle_pitch",
            "--effort",
            "current",
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            "-o",
            s(&out),
        ]),
        "import mcap",
    );
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("l_foot_dummy"),
        "a name the URDF lacks is listed: {err}"
    );
    for j in ["l_knee", "l_ankle_pitch"] {
        let ds = dataset(&d.join(format!("bag_{j}.csv")));
        let (rms, n) = rms_vs(&ds, &ds.tau_id_nm, &leg_ref(&format!("tau_id_{j}")));
        eprintln!("mcap {j}: tau_ID RMS {rms:.4} Nm on {n} samples");
        assert!(n > 10_000 && rms < 0.15, "{j}: RMS {rms} on {n}");
    }
    let wb = &sidecar(&d.join("bag_l_knee.csv"))["settings"]["import"]["whole_body"];
    assert_eq!(wb["not_in_urdf"], serde_json::json!(["l_foot_dummy"]));
}

#[cfg(feature = "mat")]
#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the whole-body log"]
fn mat_whole_body_label_matches_pinocchio() {
    let d = leg_fixture();
    let out = d.join("mat_knee.csv");
    let urdf = ergocub_urdf();
    ok(
        frictl(&[
            "import",
            "mat",
            s(&d.join("leg.mat")),
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            "-o",
            s(&out),
        ]),
        "import mat",
    );
    let ds = dataset(&out);
    let (rms, n) = rms_vs(&ds, &ds.tau_id_nm, &leg_ref("tau_id_l_knee"));
    eprintln!("mat: knee tau_ID RMS {rms:.4} Nm on {n} samples");
    assert!(n > 10_000 && rms < 0.15, "RMS {rms} on {n}");
    let side = sidecar(&out);
    assert_eq!(side["joint"], "l_knee");
    assert_eq!(
        side["settings"]["import"]["whole_body"]["not_in_urdf"],
        serde_json::json!(["l_foot_dummy"])
    );
    // This log has positions only: logged derivatives are a clear error.
    let e = err_text(
        frictl(&[
            "import",
            "mat",
            s(&d.join("leg.mat")),
            "--logged-derivatives",
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            "-o",
            s(&d.join("mat_knee_logged.csv")),
        ]),
        "import mat --logged-derivatives without them",
    );
    assert!(
        e.contains("joints_state/velocities") && e.contains("leg.mat"),
        "{e}"
    );
}

/// The same 500 Hz whole-leg motion as `.mat` and as CSV with the motor currents missing for 0.2 s
/// (`make_fixtures.py leg`: `leg_gap.mat`, whose current channel's own timestamps skip those ticks,
/// and `leg_gap.csv`, whose current cells there are NaN): the `.mat` import aligns the current
/// channel onto the positions' ticks by its timestamps, drops the rows in its gap (counted and
/// said) and labels the knee as the CSV import does (before: the channel, of another length than
/// the positions', was not used).
#[cfg(feature = "mat")]
#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the whole-body log"]
fn mat_channel_with_a_gap_is_aligned_by_its_timestamps_and_labels_as_the_csv() {
    let d = leg_fixture();
    let urdf = ergocub_urdf();
    let robot = ["--urdf", s(&urdf), "--gear-ratio", "100", "--kt", "0.1"];
    let (csv_log, mat_log) = (d.join("leg_gap.csv"), d.join("leg_gap.mat"));
    let csv_out = d.join("gap_csv_knee.csv");
    let mut args = vec![
        "import",
        "csv",
        s(&csv_log),
        "--joint",
        "l_knee",
        "--column",
        "time=t",
        "--column",
        "s=q_{joint}",
        "--column",
        "current=i_{joint}",
        "--positions",
        "q_{joint}",
        "-o",
        s(&csv_out),
    ];
    args.extend(robot);
    ok(frictl(&args), "import csv leg_gap.csv");
    let mat_out = d.join("gap_mat_knee.csv");
    let mut args = vec!["import", "mat", s(&mat_log), "-o", s(&mat_out)];
    args.extend(robot);
    let mat = ok(frictl(&args), "import mat leg_gap.mat");
    let err = String::from_utf8_lossy(&mat.stderr);
    // 0.2 s at 500 Hz: 100 ticks without a current.
    assert!(
        err.contains("motors_state/currents: 100 rows dropped"),
        "{err}"
    );
    let f_ref = leg_ref("tau_f_l_knee");
    let (dc, dm) = (dataset(&csv_out), dataset(&mat_out));
    let (rms_csv, n_csv) = rms_vs(&dc, &dc.tau_f_label_nm, &f_ref);
    let (rms_mat, n_mat) = rms_vs(&dm, &dm.tau_f_label_nm, &f_ref);
    eprintln!(
        "knee label RMS vs the true friction: csv {rms_csv:.4} Nm on {n_csv}, mat {rms_mat:.4} Nm \
         on {n_mat}"
    );
    assert!(
        n_mat > 10_000 && n_mat.abs_diff(n_csv) < 50,
        "{n_mat} vs {n_csv}"
    );
    assert!(
        rms_mat <= 1.1 * rms_csv + 0.005,
        "mat {rms_mat} Nm vs csv {rms_csv} Nm"
    );
    // Sample by sample on the common 1 kHz grid, the two labels are the same.
    let by_ms: std::collections::HashMap<i64, f64> = dc
        .time_s
        .iter()
        .zip(&dc.valid)
        .zip(&dc.tau_f_label_nm)
        .filter(|((_, v), _)| **v)
        .map(|((t, _), f)| ((t * 1000.0).round() as i64, *f))
        .collect();
    let (mut e2, mut n) = (0.0, 0usize);
    for ((t, v), f) in dm.time_s.iter().zip(&dm.valid).zip(&dm.tau_f_label_nm) {
        if let (true, Some(g)) = (*v, by_ms.get(&((t * 1000.0).round() as i64))) {
            e2 += (f - g).powi(2);
            n += 1;
        }
    }
    let diff = (e2 / n.max(1) as f64).sqrt();
    eprintln!("mat vs csv label: RMS difference {diff:.2e} Nm on {n} samples");
    assert!(n > 10_000 && diff < 1e-3, "{diff} Nm on {n}");
}

/// The logs of `make_fixtures.py tilted` (the leg of [`leg_fixture`] on a root link tilted 20° in roll
/// and −10° in pitch, yawed 30°, swaying 2°; `tilted.mat` with a 250–350 N wrench applied at
/// `l_foot_rear_ft`, `tilted.mcap` without it, `tilted_wrench.mcap` with it; the currents from Pinocchio's rnea with that gravity
/// and `fext`), written once per test process.
fn tilted_fixture() -> PathBuf {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let py = std::env::var_os("FRICTIONLESS_PY")
            .expect("FRICTIONLESS_PY must name a python with pinocchio, h5py (tests/run.sh)");
        let d = dir().join("tilted");
        let script =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../logs/tests/fixtures/make_fixtures.py");
        let st = Command::new(py)
            .arg(script)
            .arg("tilted")
            .arg(ergocub_urdf())
            .arg(&d)
            .status()
            .unwrap();
        assert!(st.success(), "make_fixtures.py tilted failed");
        d
    })
    .clone()
}

/// The base orientation channels and the wrench of the tilted log.
#[cfg(feature = "mat")]
const TILT_RPY: [&str; 2] = ["--base-orientation", "orientations/waist_imu_0"];
#[cfg(feature = "mat")]
const TILT_QUAT: [&str; 2] = ["--base-orientation", "frames/world/root_link/orientation"];
#[cfg(feature = "mat")]
const TILT_WRENCH: [&str; 2] = ["--wrench", "l_foot_rear_ft=FTs/l_foot_rear_ft"];

/// `frictl import mat tilted.mat` of the knee and the hip pitch into `DIR/<name>_{joint}.csv` with
/// `extra` options; the output.
#[cfg(feature = "mat")]
fn import_tilted(name: &str, extra: &[&str]) -> std::process::Output {
    import_tilted_log("tilted.mat", name, extra)
}

/// `frictl import mat|mcap FILE` (a file of the tilted fixture, the format from its extension) of
/// the knee and the hip pitch into `DIR/<name>_{joint}.csv` with `extra` options; the output.
fn import_tilted_log(file: &str, name: &str, extra: &[&str]) -> std::process::Output {
    let d = tilted_fixture();
    let out = d.join(format!("{name}_{{joint}}.csv"));
    let urdf = ergocub_urdf();
    let log = d.join(file);
    let format = if file.ends_with(".mcap") {
        "mcap"
    } else {
        "mat"
    };
    let mut args = vec![
        "import",
        format,
        s(&log),
        "--joint",
        "l_knee",
        "--joint",
        "l_hip_pitch",
        "--urdf",
        s(&urdf),
        "--gear-ratio",
        "100",
        "--kt",
        "0.1",
        "-o",
        s(&out),
    ];
    args.extend(extra);
    frictl(&args)
}

/// RMS of the knee's and the hip pitch's τ_ID in `DIR/<name>_{joint}.csv` against Pinocchio's (the
/// reference column `<reference><joint>`), and the valid samples.
fn tilted_rms_vs(name: &str, reference_prefix: &str) -> [(f64, usize); 2] {
    let d = tilted_fixture();
    let reference =
        frictionless_dataset::read_columns(&d.join("tilted_ref.csv")).expect("tilted_ref.csv");
    ["l_knee", "l_hip_pitch"].map(|j| {
        let ds = dataset(&d.join(format!("{name}_{j}.csv")));
        let r = rms_vs(
            &ds,
            &ds.tau_id_nm,
            &reference[&format!("{reference_prefix}{j}")],
        );
        eprintln!("{name} {j}: tau_ID RMS {:.4} Nm on {} samples", r.0, r.1);
        r
    })
}

/// Asserts that both joints' τ_ID are over 1 N·m RMS off Pinocchio's: `what` (left out of the
/// import) matters.
fn assert_far_off([(knee, _), (hip, _)]: [(f64, usize); 2], what: &str) {
    assert!(
        knee > 1.0 && hip > 1.0,
        "the {what} must matter: knee {knee}, hip {hip}"
    );
}

/// [`tilted_rms_vs`] against τ_ID with the wrench.
#[cfg(feature = "mat")]
fn tilted_rms(name: &str) -> [(f64, usize); 2] {
    tilted_rms_vs(name, "tau_id_")
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the tilted log"]
fn mcap_imu_base_orientation_tilts_the_gravity_like_pinocchio() {
    let d = tilted_fixture();
    let import = |name: &str, base: Option<&str>| {
        let mut extra = vec!["--effort", "current"];
        if let Some(topic) = base {
            extra.extend(["--base-orientation", topic]);
        }
        import_tilted_log("tilted.mcap", name, &extra)
    };
    // The Imu orientation's sign alternates from message to message in this bag.
    ok(
        import("mcap_imu", Some("/imu")),
        "import mcap --base-orientation",
    );
    for (rms, n) in tilted_rms_vs("mcap_imu", "tau_id_nw_") {
        assert!(n > 7000 && rms < 0.15, "RMS {rms} on {n}");
    }
    let side = sidecar(&d.join("mcap_imu_l_knee.csv"));
    assert!(
        side["settings"]["import"]["whole_body"]["base"]
            .as_str()
            .unwrap()
            .contains("orientation from the log"),
        "{side}"
    );
    // The waist IMU's topic: its messages' frame_id names the URDF frame of its orientation.
    ok(
        import("mcap_waist_imu", Some("/waist_imu")),
        "import mcap --base-orientation /waist_imu",
    );
    for (rms, n) in tilted_rms_vs("mcap_waist_imu", "tau_id_nw_") {
        assert!(n > 7000 && rms < 0.15, "waist IMU: RMS {rms} on {n}");
    }
    let base =
        sidecar(&d.join("mcap_waist_imu_l_knee.csv"))["settings"]["import"]["whole_body"]["base"]
            .clone();
    assert!(
        base.as_str().unwrap().contains("frame `waist_imu_0`"),
        "{base}"
    );
    ok(import("mcap_upright", None), "import mcap (upright)");
    assert_far_off(tilted_rms_vs("mcap_upright", "tau_id_nw_"), "tilt");
    let e = err_text(import("mcap_bad", Some("/nope")), "an absent topic");
    assert!(e.contains("/nope") && e.contains("/imu"), "{e}");
    let e = err_text(
        import("mcap_bad", Some("/joint_states")),
        "a topic that is not an Imu",
    );
    assert!(e.contains("sensor_msgs/msg/Imu"), "{e}");
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the tilted log"]
fn mcap_measured_wrench_enters_the_label_like_pinocchio() {
    let d = tilted_fixture();
    let import = |name: &str, wrench: Option<&str>| {
        let mut extra = vec!["--effort", "current", "--base-orientation", "/imu"];
        if let Some(w) = wrench {
            extra.extend(["--wrench", w]);
        }
        import_tilted_log("tilted_wrench.mcap", name, &extra)
    };
    ok(
        import("mcap_wrench", Some("l_foot_rear_ft=/l_foot_rear_ft")),
        "import mcap --wrench",
    );
    for (rms, n) in tilted_rms_vs("mcap_wrench", "tau_id_") {
        assert!(n > 7000 && rms < 0.15, "RMS {rms} on {n}");
    }
    let side = sidecar(&d.join("mcap_wrench_l_knee.csv"));
    assert_eq!(
        side["settings"]["import"]["whole_body"]["wrenches"],
        serde_json::json!(["l_foot_rear_ft"]),
        "{side}"
    );
    // Without it the label misses the foot's 250–350 N.
    ok(import("mcap_no_wrench", None), "import mcap (no wrench)");
    assert_far_off(tilted_rms_vs("mcap_no_wrench", "tau_id_"), "wrench");
    let e = err_text(
        import("mcap_bad", Some("l_foot_rear_ft=/nope")),
        "an absent wrench topic",
    );
    assert!(
        e.contains("/nope") && e.contains("/l_foot_rear_ft ("),
        "{e}"
    );
    let e = err_text(
        import("mcap_bad", Some("l_foot_rear_ft=/imu")),
        "a topic that is not a WrenchStamped",
    );
    assert!(
        e.contains("/imu") && e.contains("geometry_msgs/msg/WrenchStamped"),
        "{e}"
    );
    let e = err_text(
        import("mcap_bad", Some("l_foot_nowhere=/l_foot_rear_ft")),
        "a frame the URDF lacks",
    );
    assert!(
        e.contains("l_foot_nowhere") && e.contains("/l_foot_rear_ft"),
        "{e}"
    );
    let e = err_text(
        import("mcap_bad", Some("l_foot_rear_ft=/l_foot_rear_ft_late")),
        "no wrench before the first joint state",
    );
    assert!(
        e.contains("/l_foot_rear_ft_late") && e.contains("message 1 on /joint_states"),
        "{e}"
    );
    assert!(!d.join("mcap_bad_l_knee.csv").exists());
    // A message whose header.frame_id is not the URDF frame named: warned about.
    let out = ok(
        import("mcap_other_frame", Some("l_foot_rear=/l_foot_rear_ft")),
        "import mcap --wrench (another frame)",
    );
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("header.frame_id `l_foot_rear_ft` is not the URDF frame `l_foot_rear`"),
        "{e}"
    );
}

#[cfg(feature = "mat")]
#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the tilted log"]
fn mat_imu_mounted_rotated_gives_the_root_orientation_through_the_urdf() {
    // `orientations/waist_imu_0` is the waist IMU's own orientation (on torso_1, rotated 90° about
    // two axes against the root link): its name is a URDF frame, placed on the root link at each q.
    let d = tilted_fixture();
    let mut extra = TILT_RPY.to_vec();
    extra.extend(TILT_WRENCH);
    ok(import_tilted("imu", &extra), "import mat (the IMU's frame)");
    for (rms, n) in tilted_rms("imu") {
        assert!(n > 7000 && rms < 0.15, "RMS {rms} on {n}");
    }
    let base =
        sidecar(&d.join("imu_l_knee.csv"))["settings"]["import"]["whole_body"]["base"].clone();
    assert!(
        base.as_str().unwrap().contains("frame `waist_imu_0`"),
        "{base}"
    );
    // The same orientation taken as the root link's is far off.
    extra.extend(["--base-frame", "root_link"]);
    ok(
        import_tilted("imu_as_root", &extra),
        "import mat --base-frame root_link",
    );
    assert_far_off(tilted_rms("imu_as_root"), "IMU's mounting");
    // A channel whose name is no URDF frame needs --base-frame: refused, saying so.
    let mut root = vec!["--base-orientation", "orientations/root_rpy"];
    root.extend(TILT_WRENCH);
    let e = err_text(
        import_tilted("imu_bad", &root),
        "an orientation of an unknown frame",
    );
    assert!(
        e.contains("`root_rpy`") && e.contains("--base-frame"),
        "{e}"
    );
    root.extend(["--base-frame", "root_link"]);
    ok(
        import_tilted("root_rpy", &root),
        "import mat --base-frame root_link",
    );
    for (rms, n) in tilted_rms("root_rpy") {
        assert!(n > 7000 && rms < 0.15, "RMS {rms} on {n}");
    }
    let e = err_text(
        import_tilted(
            "imu_bad",
            &[TILT_RPY[0], TILT_RPY[1], "--base-frame", "nowhere"],
        ),
        "a --base-frame the URDF lacks",
    );
    assert!(e.contains("--base-frame nowhere"), "{e}");
    let e = err_text(
        import_tilted("imu_bad", &["--base-frame", "waist_imu_0"]),
        "a --base-frame without a base orientation",
    );
    assert!(e.contains("give --base-orientation"), "{e}");
    assert!(!d.join("imu_bad_l_knee.csv").exists());
}

#[cfg(feature = "mat")]
#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the tilted log"]
fn mat_base_orientation_tilts_the_gravity_like_pinocchio() {
    // Roll, pitch, yaw [rad] (the IMU channel) and the quaternion x y z w (a logged frame).
    for (name, base) in [("rpy", TILT_RPY), ("quat", TILT_QUAT)] {
        let mut extra = base.to_vec();
        extra.extend(TILT_WRENCH);
        ok(import_tilted(name, &extra), "import mat --base-orientation");
        for (rms, n) in tilted_rms(name) {
            assert!(n > 7000 && rms < 0.15, "{name}: RMS {rms} on {n}");
        }
        let wb = &sidecar(&tilted_fixture().join(format!("{name}_l_knee.csv")))["settings"]["import"]
            ["whole_body"];
        // The IMU's own frame, or the root link's (the logged frame `root_link`).
        let frame = if name == "rpy" {
            "of frame `waist_imu_0` from the log"
        } else {
            "root-link orientation from the log"
        };
        assert!(wb["base"].as_str().unwrap().contains(frame), "{wb}");
    }
    // Without it the root link is upright: the gravity is 20° off.
    ok(
        import_tilted("upright", &TILT_WRENCH),
        "import mat (upright)",
    );
    assert_far_off(tilted_rms("upright"), "tilt");
    // A channel that is not there, or not an orientation, is named.
    let e = err_text(
        import_tilted("bad", &["--base-orientation", "orientations/waist_imu_9"]),
        "an absent orientation channel",
    );
    assert!(e.contains("orientations/waist_imu_9"), "{e}");
    let e = err_text(
        import_tilted("bad", &["--base-orientation", "FTs/l_foot_rear_ft"]),
        "a 6-element orientation channel",
    );
    assert!(
        e.contains("FTs/l_foot_rear_ft") && e.contains("3 or 4"),
        "{e}"
    );
    // Another label has no whole-body state for the orientation to enter: said, not ignored.
    let e = err_text(
        import_tilted(
            "bad",
            &[TILT_RPY[0], TILT_RPY[1], "--label", "torque-sensor"],
        ),
        "a base orientation with the torque-sensor label",
    );
    assert!(e.contains("whole-body state"), "{e}");
    assert!(!tilted_fixture().join("bad_l_knee.csv").exists());
}

#[cfg(feature = "mat")]
#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the tilted log"]
fn mat_measured_wrench_enters_the_label_like_pinocchio() {
    let mut extra = TILT_RPY.to_vec();
    extra.extend(TILT_WRENCH);
    ok(import_tilted("wrench", &extra), "import mat --wrench");
    for (rms, n) in tilted_rms("wrench") {
        assert!(n > 7000 && rms < 0.15, "RMS {rms} on {n}");
    }
    let wb =
        &sidecar(&tilted_fixture().join("wrench_l_knee.csv"))["settings"]["import"]["whole_body"];
    assert_eq!(
        wb["wrenches"],
        serde_json::json!(["l_foot_rear_ft"]),
        "{wb}"
    );
    // The same wrench logged with its elements in another order: matched by name.
    let mut reordered = TILT_RPY.to_vec();
    reordered.extend([
        "--wrench",
        "l_foot_rear_ft=cartesian_wrenches/l_foot_rear_ft",
    ]);
    ok(
        import_tilted("reordered", &reordered),
        "import mat --wrench (reordered)",
    );
    for (rms, n) in tilted_rms("reordered") {
        assert!(n > 7000 && rms < 0.15, "reordered: RMS {rms} on {n}");
    }
    // The joints' velocities and accelerations as logged (exact in this log) instead of smoothed.
    extra.push("--logged-derivatives");
    ok(
        import_tilted("logged", &extra),
        "import mat --logged-derivatives",
    );
    for (rms, n) in tilted_rms("logged") {
        assert!(n > 7000 && rms < 0.15, "logged: RMS {rms} on {n}");
    }
    let notes = sidecar(&tilted_fixture().join("logged_l_knee.csv"))["settings"]["import"]["runs"]
        [0]["report"]["notes"]
        .to_string();
    assert!(
        notes.contains("joints_state/accelerations as logged"),
        "{notes}"
    );
    ok(
        import_tilted("no_wrench", &TILT_RPY),
        "import mat (no wrench)",
    );
    assert_far_off(tilted_rms("no_wrench"), "wrench");
    let e = err_text(
        import_tilted("bad", &["--wrench", "l_foot_rear_ft=FTs/r_foot_rear_ft"]),
        "an absent wrench channel",
    );
    assert!(e.contains("FTs/r_foot_rear_ft"), "{e}");
    let e = err_text(
        import_tilted("bad", &["--wrench", "l_foot_nowhere=FTs/l_foot_rear_ft"]),
        "a frame the URDF lacks",
    );
    assert!(e.contains("l_foot_nowhere"), "{e}");
}

#[cfg(feature = "mat")]
#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the tilted log"]
fn mat_streamed_import_equals_the_whole_read() {
    // The joints' derivatives smoothed from q (the default) and as logged.
    for (tag, derivatives) in [("smoothed", None), ("logged", Some("--logged-derivatives"))] {
        let mut extra = TILT_RPY.to_vec();
        extra.extend(TILT_WRENCH);
        extra.extend(derivatives);
        ok(import_tilted(&format!("whole_{tag}"), &extra), "import mat");
        extra.extend(["--window-samples", "500"]);
        ok(
            import_tilted(&format!("streamed_{tag}"), &extra),
            "import mat --window-samples",
        );
        streamed_equals_whole(tag);
    }
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the tilted log"]
fn mcap_streamed_import_equals_the_whole_read() {
    // Base orientation and wrench sampled and held onto the JointState rows, in both reads.
    let mut extra = vec![
        "--effort",
        "current",
        "--base-orientation",
        "/imu",
        "--wrench",
        "l_foot_rear_ft=/l_foot_rear_ft",
    ];
    ok(
        import_tilted_log("tilted_wrench.mcap", "whole_mcap", &extra),
        "import mcap",
    );
    extra.extend(["--window-samples", "500"]);
    let out = import_tilted_log("tilted_wrench.mcap", "streamed_mcap", &extra);
    ok(out, "import mcap --window-samples");
    streamed_equals_whole("mcap");
    for (rms, n) in tilted_rms_vs("streamed_mcap", "tau_id_") {
        assert!(n > 7000 && rms < 0.15, "RMS {rms} on {n}");
    }
}

/// The tilted log's `whole_<tag>_{joint}.csv` and `streamed_<tag>_{joint}.csv` agree to 1e-9 in
/// every column, and the streamed import held a fraction of the log.
fn streamed_equals_whole(tag: &str) {
    let d = tilted_fixture();
    for j in ["l_knee", "l_hip_pitch"] {
        let whole =
            frictionless_dataset::read_columns(&d.join(format!("whole_{tag}_{j}.csv"))).unwrap();
        let streamed =
            frictionless_dataset::read_columns(&d.join(format!("streamed_{tag}_{j}.csv"))).unwrap();
        let mut names: Vec<&String> = whole.keys().collect();
        names.sort();
        assert_eq!(
            names,
            {
                let mut v: Vec<&String> = streamed.keys().collect();
                v.sort();
                v
            },
            "{j}: columns"
        );
        let rows = whole["time_s"].len();
        assert!(rows > 7000, "{j}: {rows} rows");
        for name in names {
            let (a, b) = (&whole[name], &streamed[name]);
            assert_eq!(a.len(), b.len(), "{j} {name}: rows");
            for (k, (x, y)) in a.iter().zip(b).enumerate() {
                assert!(
                    (x.is_nan() && y.is_nan()) || (x - y).abs() <= 1e-9,
                    "{tag} {j} {name} row {k}: whole {x}, streamed {y}"
                );
            }
        }
        let stream =
            &sidecar(&d.join(format!("streamed_{tag}_{j}.csv")))["settings"]["import"]["stream"];
        assert_eq!(stream["window_samples"], 500, "{stream}");
        let held = stream["max_grid_samples_held"].as_u64().unwrap() as usize;
        assert!(held < rows / 4, "held {held} of {rows}: {stream}");
    }
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the whole-body log"]
fn whole_body_bad_templates_are_clear_errors() {
    let d = leg_fixture();
    let urdf = ergocub_urdf();
    let base = |positions: &str| {
        frictl(&[
            "import",
            "csv",
            s(&d.join("leg.csv")),
            "--joint",
            "l_knee",
            "--column",
            "time=t",
            "--column",
            "s=q_l_knee",
            "--column",
            "current=i_l_knee",
            "--positions",
            positions,
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            "-o",
            s(&d.join("bad.csv")),
        ])
    };
    let e = err_text(base("pos_{joint}"), "a template matching no column");
    assert!(
        e.contains("pos_{joint}") && e.contains("matches no column") && e.contains("q_l_knee"),
        "{e}"
    );
    let e = err_text(base("q_knee"), "a template without {joint}");
    assert!(e.contains("{joint}"), "{e}");
    assert!(!d.join("bad.csv").exists());
    // Several joints need {joint} in -o.
    let e = err_text(
        frictl(&[
            "import",
            "csv",
            s(&d.join("leg.csv")),
            "--joint",
            "l_knee",
            "--joint",
            "l_hip_pitch",
            "--column",
            "time=t",
            "--column",
            "s=q_{joint}",
            "--column",
            "current=i_{joint}",
            "--positions",
            "q_{joint}",
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            "-o",
            s(&d.join("two.csv")),
        ]),
        "two joints, one output",
    );
    assert!(e.contains("-o must hold {joint}"), "{e}");
}

/// An acquisition log of the knee of `virtual_leg` (the format `frictl preprocess` reads) with a
/// `q_l_hip_pitch` column: `hip_amp_rad` · sin(2π·0.7 t).
fn knee_acquisition_log(path: &Path, hip_amp_rad: f64) {
    let mut text = String::from(
        "time_s,chunk,s_rad,theta_motor_rad,omega_motor_rad_s,i_meas_a,q_l_hip_pitch\n",
    );
    for k in 0..6000 {
        let t = k as f64 * 1e-3;
        let s = -0.8 + 0.3 * (std::f64::consts::TAU * 0.5 * t).sin();
        let hip = hip_amp_rad * (std::f64::consts::TAU * 0.7 * t).sin();
        let i = 0.5 * (3.0 * t).sin();
        text += &format!("{t},0,{s},{},{},{i},{hip}\n", 100.0 * s, 0.0);
    }
    std::fs::write(path, text).unwrap();
    std::fs::write(
        path.with_extension("json"),
        r#"{"joint": "l_knee", "gear_ratio_signed": 100.0, "kt_nm_per_a": 0.1}"#,
    )
    .unwrap();
}

#[test]
fn preprocess_reads_the_other_joints_positions_the_same_way() {
    let d = dir();
    let tau = |log: &Path, out: &Path, whole: bool| {
        let mut args = vec!["preprocess", s(log), "--out", s(out), "--link", "urdf"];
        if whole {
            args.extend(["--positions", "q_{joint}"]);
        }
        ok(frictl(&args), "preprocess");
        (dataset(out).tau_id_nm, sidecar(out))
    };
    // The hip still at 0: the whole body and the single-joint view (others at 0) agree.
    let still = d.join("acq_still.csv");
    knee_acquisition_log(&still, 0.0);
    let (single, _) = tau(&still, &d.join("pre_single.csv"), false);
    let (whole, side) = tau(&still, &d.join("pre_whole.csv"), true);
    assert_eq!(single.len(), whole.len());
    let max = single
        .iter()
        .zip(&whole)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(max < 1e-6, "max difference {max} N·m");
    assert_eq!(
        side["settings"]["whole_body"]["from_log"],
        serde_json::json!(["l_hip_pitch", "l_knee"])
    );
    // The hip moving 0.3 rad changes the knee's τ_ID; the single-joint view cannot see it.
    let moving = d.join("acq_moving.csv");
    knee_acquisition_log(&moving, 0.3);
    let (whole_m, _) = tau(&moving, &d.join("pre_moving.csv"), true);
    let rms = (single
        .iter()
        .zip(&whole_m)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        / single.len() as f64)
        .sqrt();
    assert!(
        rms > 0.1,
        "hip motion changes the knee's tau_ID by {rms} N·m RMS"
    );
    let e = err_text(
        frictl(&[
            "preprocess",
            s(&moving),
            "--out",
            s(&d.join("pre_bad.csv")),
            "--positions",
            "q_hip",
        ]),
        "template without {joint}",
    );
    assert!(e.contains("{joint}"), "{e}");
}

/// `import csv` of `log` into `out` (a wrist joint with a given friction column).
fn import_args<'a>(log: &'a Path, out: &'a Path) -> Vec<&'a str> {
    vec![
        "import",
        "csv",
        s(log),
        "--joint",
        "wrist",
        "--column",
        "time=time",
        "--column",
        "s=q_deg",
        "--column",
        "tau_f=friction_nm",
        "--unit",
        "s=deg",
        "-o",
        s(out),
    ]
}

#[test]
fn import_over_a_device_a_fifo_or_a_symlink_is_refused_and_leaves_it() {
    use std::os::unix::fs::FileTypeExt;
    let d = dir().join("occupied");
    std::fs::create_dir_all(&d).unwrap();
    let log = d.join("log.csv");
    write_log(&log, 2.0, 5);
    let e = err_text(
        frictl(&import_args(&log, Path::new("/dev/null"))),
        "import to /dev/null",
    );
    assert!(
        e.contains("/dev/null") && e.contains("character device"),
        "{e}"
    );
    assert!(
        std::fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device()
    );
    // A FIFO: the old importer blocked in its open; the hang is caught by the process ending at all
    // (the refusal happens before any read of the log).
    let fifo = d.join("ds.fifo");
    let _ = std::fs::remove_file(&fifo);
    let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let mut child = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(import_args(&log, &fifo))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > std::time::Duration::from_secs(120) {
            child.kill().unwrap();
            let _ = child.wait();
            panic!("import csv -o FIFO hung");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let e = err_text(child.wait_with_output().unwrap(), "import to a FIFO");
    assert!(e.contains(s(&fifo)) && e.contains("FIFO"), "{e}");
    assert!(
        std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo()
    );
    // A symlink `current.csv -> v1.csv`: refused, the link and v1 kept.
    let v1 = d.join("v1.csv");
    std::fs::write(&v1, "the previous dataset\n").unwrap();
    let link = d.join("current.csv");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink("v1.csv", &link).unwrap();
    let e = err_text(
        frictl(&import_args(&log, &link)),
        "import through a symlink",
    );
    assert!(
        e.contains(s(&link)) && e.contains("symbolic link to v1.csv"),
        "{e}"
    );
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(
        std::fs::read_to_string(&v1).unwrap(),
        "the previous dataset\n"
    );
    assert!(!d.join("current.json").exists());
}

#[test]
fn an_import_stopped_mid_write_keeps_the_previous_dataset_and_sidecar() {
    use std::os::unix::process::CommandExt;
    let d = dir().join("stopped");
    std::fs::create_dir_all(&d).unwrap();
    let log = d.join("log.csv");
    write_log(&log, 2.0, 7);
    let ds = d.join("ds.csv");
    ok(frictl(&import_args(&log, &ds)), "first import");
    let csv_before = std::fs::read(&ds).unwrap();
    let side_before = std::fs::read(ds.with_extension("json")).unwrap();
    // Another log, imported again over the same dataset by a process that dies once it has written
    // half the old dataset's bytes into any one file (RLIMIT_FSIZE: SIGXFSZ, as a full disk or a
    // kill would stop it mid-write).
    let log2 = d.join("log2.csv");
    write_log(&log2, 3.0, 8);
    let limit = (csv_before.len() / 2) as libc::rlim_t;
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_frictl"));
    cmd.args(import_args(&log2, &ds));
    // SAFETY: setrlimit is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            let r = libc::rlimit {
                rlim_cur: limit,
                rlim_max: limit,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &r) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let out = cmd.output().unwrap();
    assert!(!out.status.success(), "the limited import should die");
    assert_eq!(
        std::fs::read(&ds).unwrap(),
        csv_before,
        "the dataset CSV was cut"
    );
    assert_eq!(
        std::fs::read(ds.with_extension("json")).unwrap(),
        side_before
    );
    ok(frictl(&["fit", "cv", s(&ds)]), "fit cv on the kept dataset");
}

#[test]
fn a_dataset_cut_at_a_line_boundary_is_refused_with_both_counts() {
    let d = dir().join("cut");
    std::fs::create_dir_all(&d).unwrap();
    let log = d.join("log.csv");
    write_log(&log, 2.0, 9);
    let ds = d.join("ds.csv");
    ok(frictl(&import_args(&log, &ds)), "import");
    let side: frictionless_dataset::DatasetSidecar =
        serde_json::from_str(&std::fs::read_to_string(ds.with_extension("json")).unwrap()).unwrap();
    let text = std::fs::read_to_string(&ds).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len() - 1, side.samples);
    let keep = 1 + side.samples / 2;
    std::fs::write(&ds, lines[..keep].join("\n") + "\n").unwrap();
    let e = err_text(frictl(&["fit", "cv", s(&ds)]), "fit cv on a cut dataset");
    assert!(
        e.contains(s(&ds))
            && e.contains(&format!("{} data rows", keep - 1))
            && e.contains(&format!("records {} samples", side.samples)),
        "{e}"
    );
}

#[test]
fn the_current_label_of_a_robot_log_needs_its_urdf() {
    // `l_knee` is a joint of the simulator's virtual leg too: without --urdf the label was computed
    // with the wrong robot's dynamics and the import succeeded.
    let d = dir();
    let log = d.join("knee_current.csv");
    let mut text = String::from("t,q,i\n");
    for k in 0..3000 {
        let t = k as f64 * 1e-3;
        text += &format!("{t},{},{}\n", 0.3 * (2.0 * t).sin(), 0.5 * (2.0 * t).cos());
    }
    std::fs::write(&log, text).unwrap();
    let out = d.join("knee_current_ds.csv");
    let args = [
        "import",
        "csv",
        s(&log),
        "--joint",
        "l_knee",
        "--column",
        "time=t",
        "--column",
        "s=q",
        "--column",
        "current=i",
        "--label",
        "current",
        "--gear-ratio",
        "-100",
        "--kt",
        "0.1",
        "-o",
        s(&out),
    ];
    let e = err_text(frictl(&args), "current label without --urdf");
    assert!(e.contains("--urdf"), "{e}");
    assert!(!out.exists(), "nothing written on error");
    // Named explicitly, the virtual leg is a URDF like any other.
    let mut with = args.to_vec();
    with.extend(["--urdf", "virtual_leg"]);
    ok(frictl(&with), "current label with --urdf");
    assert!(out.is_file());
}

/// A 1 kHz log `t,q,qd,f` of `rows` rows, time written as `t·t_scale`.
fn plain_log(path: &Path, rows: usize, dt: f64, t_scale: f64) {
    let mut text = String::from("t,q,qd,f\n");
    for k in 0..rows {
        let t = k as f64 * dt;
        text += &format!(
            "{},{},{},{}\n",
            t * t_scale,
            0.3 * (2.0 * t).sin(),
            0.6 * (2.0 * t).cos(),
            0.3 * (2.0 * t).cos()
        );
    }
    std::fs::write(path, text).unwrap();
}

const COLUMNS: [&str; 10] = [
    "--joint", "wrist", "--column", "time=t", "--column", "s=q", "--column", "sdot=qd", "--column",
    "tau_f=f",
];

#[test]
fn import_numbers_parse_alike_and_are_checked() {
    let d = dir();
    let log = d.join("numbers.csv");
    plain_log(&log, 2000, 1e-3, 1.0);
    let out = d.join("numbers_ds.csv");
    let run = |extra: &[&str]| {
        let mut a = vec!["import", "csv", s(&log), "-o", s(&out)];
        a.extend(COLUMNS);
        a.extend(extra);
        frictl(&a)
    };
    // `--kt -0.1` reaches the check (not refused by the parser as an unknown option).
    let e = err_text(run(&["--kt", "-0.1"]), "--kt -0.1");
    assert!(e.contains("--kt -0.1: must be finite and > 0"), "{e}");
    let e = err_text(run(&["--gear-ratio", "nan"]), "--gear-ratio nan");
    assert!(e.contains("--gear-ratio nan: must be finite"), "{e}");
    let e = err_text(
        run(&["--negate", "tau_f", "--negate", "tau_f"]),
        "negate twice",
    );
    assert!(e.contains("--negate tau_f is given twice"), "{e}");
    assert!(!out.exists(), "nothing written on error");
    ok(
        run(&["--gear-ratio", "-100", "--kt", "0.1"]),
        "negative gear ratio",
    );
}

#[test]
fn an_import_that_would_be_empty_is_refused_with_the_likely_unit() {
    let d = dir();
    let out = d.join("empty_ds.csv");
    let run = |log: &Path, extra: &[&str]| {
        let mut a = vec!["import", "csv", s(log), "-o", s(&out)];
        a.extend(COLUMNS);
        a.extend(extra);
        frictl(&a)
    };
    // Seconds declared ms: 5 000 rows would collapse into 5 ms.
    let log = d.join("seconds.csv");
    plain_log(&log, 5000, 1e-3, 1.0);
    let e = err_text(run(&log, &["--unit", "time=ms"]), "s declared ms");
    assert!(e.contains("--unit time=s"), "{e}");
    // Milliseconds declared s.
    let log = d.join("millis.csv");
    plain_log(&log, 5000, 1e-3, 1e3);
    let e = err_text(run(&log, &[]), "ms declared s");
    assert!(e.contains("--unit time=ms"), "{e}");
    // 80 rows 0.2 s apart with --gap-s 0.1: no chunk would be left.
    let log = d.join("slow.csv");
    plain_log(&log, 80, 0.2, 1.0);
    let e = err_text(run(&log, &[]), "slower than --gap-s");
    assert!(
        e.contains("longer than --gap-s 0.1") && e.contains("--gap-s 0.600"),
        "{e}"
    );
    assert!(!out.exists(), "nothing written on error");
    ok(
        run(&log, &["--gap-s", "0.6"]),
        "the slow log with a wide gap",
    );
}

/// `frictl acquire --preset leg` excites every leg joint at once and writes one log with every
/// joint's columns; `frictl import csv --joints all --positions 'q_{joint}'` turns it into six
/// datasets labelled from the whole leg's state. Against the log's truth τ_F per joint (valid,
/// active, sliding rows), the whole-state label is printed next to the single-joint view's (the
/// other joints held at their mean positions); on the knee it must be far smaller.
#[test]
fn leg_acquisition_imports_per_joint_and_the_whole_state_label_beats_the_single_joint_view() {
    let d = dir().join("legacq");
    let _ = std::fs::remove_dir_all(&d);
    let run = ok(
        frictl(&[
            "acquire",
            "--preset",
            "leg",
            "--seed",
            "5",
            "--out",
            s(&d),
            "--set",
            "protocol.n_starts=1",
            "--set",
            "protocol.current_scale=0.4",
            "--set",
            "protocol.sines.amplitude_to_a=0.7",
            "--set",
            "protocol.sines.frequencies_hz=[0.7]",
            "--set",
            "protocol.ramps.slopes_a_per_s=[0.39]",
            "--set",
            "protocol.steps.levels_a=[0.8, -0.8]",
        ]),
        "acquire --preset leg",
    );
    assert!(
        String::from_utf8_lossy(&run.stderr).contains("6 joints excited at once"),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let log = d.join("leg_seed5.csv");
    let cols = frictionless_dataset::read_columns(&log).unwrap();
    let leg = frictionless_sim::LegParams::preset().unwrap();
    let urdf = ergocub_urdf();
    let mut constants = Vec::new();
    for p in &leg.joints {
        for c in ["q", "qd", "i", "i_ref", "theta", "tau_f_true", "active"] {
            assert!(
                cols.contains_key(&format!("{c}_{}", p.joint)),
                "{c}_{}",
                p.joint
            );
        }
        constants.push(format!("--gear-ratio={}={}", p.joint, p.gear_ratio_signed));
        constants.push(format!("--kt={}={}", p.joint, p.kt_nm_per_a));
    }
    let base = [
        "import",
        "csv",
        s(&log),
        "--label",
        "current",
        "--column",
        "time=time_s",
        "--column",
        "s=q_{joint}",
        "--column",
        "current=i_{joint}",
        "--column",
        "theta=theta_{joint}",
        "--column",
        "omega=omega_{joint}",
        "--urdf",
        s(&urdf),
    ];
    // whole state: every joint in one pass
    let mut args: Vec<&str> = base.to_vec();
    args.extend(constants.iter().map(String::as_str));
    let whole_out = d.join("ds_{joint}.csv");
    args.extend([
        "--joints",
        "all",
        "--positions",
        "q_{joint}",
        "-o",
        s(&whole_out),
    ]);
    let run = ok(frictl(&args), "import csv --joints all (leg)");
    assert!(
        String::from_utf8_lossy(&run.stderr).contains("6 joint(s)"),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    // single-joint view of the knee: the other leg joints at their mean logged positions
    let mut fixed = Vec::new();
    for p in &leg.joints {
        if p.joint != "l_knee" {
            let q = &cols[&format!("q_{}", p.joint)];
            fixed.push(format!(
                "--fixed-joint={}={}",
                p.joint,
                q.iter().sum::<f64>() / q.len() as f64
            ));
        }
    }
    let mut args: Vec<&str> = base.to_vec();
    args.extend(constants.iter().map(String::as_str));
    args.extend(fixed.iter().map(String::as_str));
    let single_out = d.join("single_l_knee.csv");
    args.extend(["--joint", "l_knee", "-o", s(&single_out)]);
    ok(frictl(&args), "import csv (knee, single-joint view)");

    // label − truth on valid, active, sliding rows (the log's 1 kHz grid, indexed by time)
    let label_error = |ds: &frictionless_dataset::Dataset, joint: &str| {
        let truth = &cols[&format!("tau_f_true_{joint}")];
        let active = &cols[&format!("active_{joint}")];
        let (mut e2, mut n) = (0.0, 0usize);
        for k in 0..ds.len() {
            let i = (ds.time_s[k] * 1000.0).round() as usize;
            if ds.valid[k] && active[i] == 1.0 && ds.sdot_rad_s[k].abs() > 0.03 {
                e2 += (ds.tau_f_label_nm[k] - truth[i]).powi(2);
                n += 1;
            }
        }
        ((e2 / n.max(1) as f64).sqrt(), n)
    };
    for p in &leg.joints {
        let ds = dataset(&d.join(format!("ds_{}.csv", p.joint)));
        let (e, n) = label_error(&ds, &p.joint);
        eprintln!(
            "{:14} whole-state label − truth RMS {e:.3} Nm ({n} rows)",
            p.joint
        );
        assert!(n > 100, "{}: {n} sliding rows", p.joint);
    }
    let (ew, _) = label_error(&dataset(&d.join("ds_l_knee.csv")), "l_knee");
    let (es, n) = label_error(&dataset(&single_out), "l_knee");
    eprintln!("l_knee single-joint view label − truth RMS {es:.3} Nm ({n} rows)");
    assert!(
        ew < 0.2 * es,
        "knee: whole state {ew} Nm vs single-joint view {es} Nm"
    );
}

/// A CSV log of three moving ergoCub leg joints (q, current; 1 kHz with jitter, a 0.5 s pause and
/// a few rows of NaN) with `rows` rows.
fn leg_csv(path: &Path, rows: usize) {
    let mut text =
        String::from("t,q_l_hip_pitch,q_l_knee,q_l_ankle_pitch,i_l_hip_pitch,i_l_knee\n");
    let (mut t, mut k) = (0.0f64, 1u64);
    for n in 0..rows {
        if n == rows / 3 {
            t += 0.5;
        }
        let w = std::f64::consts::TAU * 0.6;
        let (hip, knee, ankle) = (
            0.3 * (w * t).sin(),
            -0.6 + 0.3 * (1.3 * w * t).sin(),
            0.1 * (2.1 * w * t).cos(),
        );
        let (ih, ik) = (0.4 * (3.0 * t).sin(), 0.3 * (2.0 * t).cos());
        if n % 4999 == 17 {
            text += &format!("{t:.6},nan,{knee},{ankle},{ih},{ik}\n");
        } else {
            text += &format!("{t:.6},{hip},{knee},{ankle},{ih},{ik}\n");
        }
        k = k
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        t += 1e-3 * (0.9 + 0.2 * ((k >> 40) as f64 / f64::from(1u32 << 24)));
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn csv_streamed_import_equals_the_whole_log_and_holds_a_window() {
    let d = dir().join("stream");
    std::fs::create_dir_all(&d).unwrap();
    let log = d.join("leg.csv");
    leg_csv(&log, 14_000);
    let urdf = ergocub_urdf();
    let import = |out: &Path, window: Option<&str>| {
        let mut args = vec![
            "import",
            "csv",
            s(&log),
            "--joint",
            "l_knee",
            "--joint",
            "l_hip_pitch",
            "--column",
            "time=t",
            "--column",
            "s=q_{joint}",
            "--column",
            "current=i_{joint}",
            "--positions",
            "q_{joint}",
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            // The knee's s̈ reaches 7 rad/s²: some rows are dropped for it.
            "--joint-acc-limit",
            "5",
            "-o",
            s(out),
        ];
        if let Some(w) = window {
            args.extend(["--window-samples", w]);
        }
        let run = ok(frictl(&args), "import csv");
        String::from_utf8_lossy(&run.stderr).into_owned()
    };
    let whole_err = import(&d.join("whole_{joint}.csv"), None);
    let streamed_err = import(&d.join("streamed_{joint}.csv"), Some("1000"));
    for j in ["l_knee", "l_hip_pitch"] {
        // Every dropped row counted once per reason, the same whole and streamed, in the sidecar
        // and on the console; the default gravity recorded.
        let (sw, ss) = (
            sidecar(&d.join(format!("whole_{j}.csv"))),
            sidecar(&d.join(format!("streamed_{j}.csv"))),
        );
        assert_eq!(sw["dropped_rows"], ss["dropped_rows"], "{j}");
        let dropped = &sw["dropped_rows"];
        let total: u64 = dropped
            .as_object()
            .unwrap()
            .values()
            .map(|v| v.as_u64().unwrap())
            .sum();
        let (samples, valid) = (
            sw["samples"].as_u64().unwrap(),
            sw["valid_samples"].as_u64().unwrap(),
        );
        assert_eq!(total, samples - valid, "{j}: {dropped}");
        let acc = dropped["joint_acc"].as_u64().unwrap();
        if j == "l_knee" {
            assert!(acc > 100, "{j}: {dropped}");
        }
        if acc > 0 {
            let line = format!(
                "  {j}: dropped {total} of {samples} rows: {acc} |s̈| ≥ --joint-acc-limit 5 rad/s²"
            );
            assert!(whole_err.contains(&line), "{line}\n{whole_err}");
            assert!(streamed_err.contains(&line), "{line}\n{streamed_err}");
        }
        for side in [&sw, &ss] {
            assert_eq!(
                side["settings"]["import"]["gravity_m_s2"].as_f64(),
                Some(9.80665),
                "{j}"
            );
            assert!(
                side["dynamics"]
                    .as_str()
                    .unwrap()
                    .contains("g = 9.80665 m/s²"),
                "{j}"
            );
        }
        let w = dataset(&d.join(format!("whole_{j}.csv")));
        let st = dataset(&d.join(format!("streamed_{j}.csv")));
        assert!(w.len() > 13_000, "{}", w.len());
        assert_eq!(w.len(), st.len(), "{j}: rows");
        assert_eq!(w.chunk, st.chunk, "{j}: chunks");
        assert_eq!(w.valid, st.valid, "{j}: valid");
        for (name, a, b) in [
            ("time_s", &w.time_s, &st.time_s),
            ("sdot_rad_s", &w.sdot_rad_s, &st.sdot_rad_s),
            ("sddot_rad_s2", &w.sddot_rad_s2, &st.sddot_rad_s2),
            ("i_filt_a", &w.i_filt_a, &st.i_filt_a),
            ("tau_id_nm", &w.tau_id_nm, &st.tau_id_nm),
            ("tau_f_label_nm", &w.tau_f_label_nm, &st.tau_f_label_nm),
        ] {
            for (k, (x, y)) in a.iter().zip(b.iter()).enumerate() {
                assert!(
                    (x.is_nan() && y.is_nan()) || (x - y).abs() <= 1e-9,
                    "{j} {name} row {k}: whole {x}, streamed {y}"
                );
            }
        }
        let side = sidecar(&d.join(format!("streamed_{j}.csv")));
        let stream = &side["settings"]["import"]["stream"];
        let n = |k: &str| {
            stream[k]
                .as_u64()
                .unwrap_or_else(|| panic!("{k}: {stream}")) as usize
        };
        let bound = n("window_samples") + n("lead_margin_samples") + n("trail_margin_samples");
        assert_eq!(n("window_samples"), 1000);
        assert!(n("max_grid_samples_held") <= bound, "{stream}");
        // Raw rows: one step's (rows every ≥ 0.9 ms on a 1 ms grid) plus the block being read.
        assert!(
            n("max_raw_samples_held") <= bound * 10 / 9 + 2 + 1000,
            "{stream}"
        );
        assert!(
            bound < w.len() / 4,
            "the log is long against what is held: {stream}"
        );
        assert_eq!(side["samples"].as_u64(), Some(w.len() as u64));
    }
}

/// `--gravity-m-s2` of `frictl import`: the whole-body τ_ID is linear in g (its gravity term at
/// 2·g0 twice the one at g0), the sidecar and the dynamics line record the value, and a value
/// outside [0, 30] m/s² is refused naming the flag.
#[test]
fn csv_gravity_is_an_option_of_the_whole_body_label_and_recorded() {
    let d = dir().join("gravity");
    std::fs::create_dir_all(&d).unwrap();
    let log = d.join("leg.csv");
    leg_csv(&log, 3_000);
    let urdf = ergocub_urdf();
    let import = |g: &str, out: &Path| {
        let flag = format!("--gravity-m-s2={g}");
        frictl(&[
            "import",
            "csv",
            s(&log),
            "--joint",
            "l_knee",
            "--column",
            "time=t",
            "--column",
            "s=q_{joint}",
            "--column",
            "current=i_{joint}",
            "--positions",
            "q_{joint}",
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            &flag,
            "-o",
            s(out),
        ])
    };
    let g0 = 9.80665;
    let tau = |g: f64| {
        let out = d.join(format!("ds_{g}.csv"));
        let run = ok(import(&g.to_string(), &out), "import --gravity-m-s2");
        let side = sidecar(&out);
        assert_eq!(side["settings"]["import"]["gravity_m_s2"].as_f64(), Some(g));
        let text = format!("g = {g} m/s²");
        assert!(side["dynamics"].as_str().unwrap().contains(&text), "{side}");
        assert!(String::from_utf8_lossy(&run.stderr).contains(&text));
        dataset(&out).tau_id_nm
    };
    let (t0, t1, t2) = (tau(0.0), tau(g0), tau(2.0 * g0));
    let mut grav2 = 0.0;
    for k in 0..t1.len() {
        let grav = t1[k] - t0[k];
        grav2 += grav * grav;
        assert!(
            (t2[k] - t0[k] - 2.0 * grav).abs() < 1e-9 * (1.0 + t1[k].abs()),
            "row {k}"
        );
    }
    assert!(
        (grav2 / t1.len() as f64).sqrt() > 1.0,
        "the knee carries the shank"
    );
    let bad = d.join("bad.csv");
    for v in ["31", "-0.5", "nan"] {
        let e = err_text(import(v, &bad), v);
        assert!(e.contains("--gravity-m-s2") && e.contains(v), "{v}: {e}");
    }
    assert!(!bad.exists());
}

#[test]
fn csv_streamed_import_checks_the_units_on_the_first_window() {
    let d = dir().join("stream_units");
    std::fs::create_dir_all(&d).unwrap();
    let log = d.join("leg.csv");
    leg_csv(&log, 3_000);
    let urdf = ergocub_urdf();
    let out = d.join("ds_{joint}.csv");
    let import = |unit: &str| {
        frictl(&[
            "import",
            "csv",
            s(&log),
            "--joint",
            "l_knee",
            "--column",
            "time=t",
            "--column",
            "s=q_{joint}",
            "--column",
            "current=i_{joint}",
            "--unit",
            unit,
            "--positions",
            "q_{joint}",
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            "--window-samples",
            "1000",
            "-o",
            s(&out),
        ])
    };
    // Seconds declared as milliseconds: 1 kHz rows would be 1 MHz.
    let e = err_text(import("time=ms"), "a time in s declared ms, streamed");
    assert!(
        e.contains("--unit time=s") && e.contains("first window") && e.contains("leg.csv"),
        "{e}"
    );
    assert!(
        !d.join("ds_l_knee.csv").exists() && !d.join("ds_l_knee.json").exists(),
        "nothing written"
    );
    ok(import("time=s"), "import csv --window-samples");
    // The log's one NaN position and the URDF joints held at 0 that change the knee's label (the
    // leg's unlogged ones; not the torso, arms or the other leg) are reported as the whole-log
    // import reports them; the units pass.
    let side = sidecar(&d.join("ds_l_knee.csv"));
    let w = &side["settings"]["import"]["warnings"];
    let w: Vec<&str> = w
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap())
        .collect();
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(
        w[0].ends_with("leg.csv: 1 non-finite values dropped (q:l_hip_pitch: 1)"),
        "{w:?}"
    );
    let wb = &side["settings"]["import"]["whole_body"];
    let held0 = wb["held_at_zero"].as_array().unwrap().len();
    assert!(
        wb["held_at_zero"].to_string().contains("torso_roll"),
        "{wb}"
    );
    assert!(
        w[1].starts_with(
            "URDF joints neither in the log nor given with --fixed-joint, held at 0 rad, that \
             change the label (on the path from the root to a labelled joint or below it): \
             l_hip_roll, l_hip_yaw, l_ankle_roll; "
        ) && w[1].contains(&format!(
            "; {} other joints held at 0 rad do not change it",
            held0 - 3
        )),
        "{w:?}"
    );
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the log with a foot wrench"]
fn csv_measured_wrench_enters_the_label_like_pinocchio_rnea_with_fext() {
    let py = std::env::var_os("FRICTIONLESS_PY")
        .expect("FRICTIONLESS_PY must name a python with pinocchio (tests/run.sh)");
    let d = dir().join("wrench");
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../logs/tests/fixtures/make_fixtures.py");
    let urdf = ergocub_urdf();
    let st = Command::new(py)
        .arg(script)
        .arg("wrench")
        .arg(&urdf)
        .arg(&d)
        .status()
        .unwrap();
    assert!(st.success(), "make_fixtures.py wrench failed");
    let log = d.join("wrench.csv");
    let cols = frictionless_dataset::read_columns(&log).unwrap();
    let import = |out: &Path, wrench: bool| {
        let mut args = vec![
            "import",
            "csv",
            s(&log),
            "--joint",
            "l_knee",
            "--joint",
            "l_hip_pitch",
            "--column",
            "time=t",
            "--column",
            "s=q_{joint}",
            "--column",
            "current=i_{joint}",
            "--positions",
            "q_{joint}",
            "--velocities",
            "qd_{joint}",
            "--accelerations",
            "qdd_{joint}",
            "--urdf",
            s(&urdf),
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            "-o",
            s(out),
        ];
        if wrench {
            args.extend(["--wrench", "l_foot_rear=ft_{c}"]);
        }
        ok(frictl(&args), "import csv --wrench")
    };
    import(&d.join("with_{joint}.csv"), true);
    import(&d.join("without_{joint}.csv"), false);
    for j in ["l_knee", "l_hip_pitch"] {
        let reference = &cols[&format!("tau_w_{j}")];
        let with = dataset(&d.join(format!("with_{j}.csv")));
        let without = dataset(&d.join(format!("without_{j}.csv")));
        let (mut worst, mut n) = (0.0f64, 0);
        for (t, tau) in with.time_s.iter().zip(&with.tau_id_nm) {
            let i = (t * 1000.0).round() as usize;
            worst = worst.max((tau - reference[i]).abs());
            n += 1;
        }
        let (rms_without, _) = rms_vs(&without, &without.tau_id_nm, reference);
        eprintln!(
            "{j}: with the wrench max |error| {worst:.2e} Nm on {n}; without it RMS {rms_without:.2} Nm"
        );
        assert!(n > 2900 && worst < 1e-6, "{j}: {worst} on {n}");
        assert!(
            rms_without > 1.0,
            "{j}: the wrench must matter: {rms_without}"
        );
        let side = sidecar(&d.join(format!("with_{j}.csv")));
        assert_eq!(
            side["settings"]["import"]["whole_body"]["wrenches"][0], "l_foot_rear",
            "{side}"
        );
    }
}

/// A small simulated knee acquisition (seed 4) in `dir()/NAME`: (the directory, the log).
fn small_knee_log(name: &str) -> (PathBuf, PathBuf) {
    let d = dir().join(name);
    std::fs::create_dir_all(&d).unwrap();
    ok(
        frictl(&crate::util::small_acquire_args(
            "knee",
            "4",
            &d,
            "knee",
            &[],
        )),
        "acquire",
    );
    let log = d.join("knee.csv");
    (d, log)
}

#[test]
fn preprocess_label_filter_matched_is_closer_to_the_truth_and_is_recorded() {
    let (d, log) = small_knee_log("label-filter");
    let run = |filter: Option<&str>, out: &Path| {
        // J_eq·φ̈ subtracted: what remains of the label's error is the estimation's.
        let mut args = vec![
            "preprocess",
            s(&log),
            "--out",
            s(out),
            "--subtract-reflected-inertia",
            "sidecar",
        ];
        if let Some(f) = filter {
            args.extend(["--label-filter", f]);
        }
        ok(frictl(&args), "preprocess");
        let ds = dataset(out);
        let rows = (0..ds.len())
            .filter(|&k| ds.valid[k] && ds.active[k] && ds.sdot_rad_s[k].abs() > 0.03)
            .count();
        let rms =
            frictionless_acquire::leg::label_error_rms_nm(&ds).expect("truth and sliding rows");
        ((rms, rows), sidecar(out))
    };
    let ((e_sep, n_sep), side_sep) = run(None, &d.join("separate.csv"));
    let ((e_mat, n_mat), side_mat) = run(Some("matched"), &d.join("matched.csv"));
    assert_eq!(side_sep["settings"]["label_filter"], "separate");
    assert_eq!(side_mat["settings"]["label_filter"], "matched");
    eprintln!(
        "label − truth RMS: matched {e_mat:.3} Nm ({n_mat} rows), separate {e_sep:.3} Nm ({n_sep} rows)"
    );
    // The matched label also rejects the rows next to rejected ones, so it keeps fewer.
    assert!(
        n_mat > n_sep / 2 && n_mat <= n_sep,
        "{n_mat} of {n_sep} rows"
    );
    assert!(
        e_mat < 0.8 * e_sep,
        "label − truth RMS: matched {e_mat} Nm, separate {e_sep} Nm"
    );
    let e = err_text(
        frictl(&[
            "preprocess",
            s(&log),
            "--out",
            s(&d.join("bad.csv")),
            "--label-filter",
            "butterworth",
        ]),
        "an unknown label filter",
    );
    assert!(
        e.contains("butterworth") && e.contains("separate, matched"),
        "{e}"
    );
    assert!(!d.join("bad.csv").exists());
}

/// `--ripple wave-generator` on a simulated knee log (the preset's friction ripple e₁ at twice the
/// motor angle): the identified amplitude is the plant's e₁·f_c0 within 30 %, the label gets closer
/// to the truth than the matched label alone, and the sidecar records the setting and the fit.
/// Without the matched label, or with an unknown step, nothing is written.
#[test]
fn preprocess_ripple_wave_generator_identifies_the_plant_ripple() {
    let (d, log) = small_knee_log("ripple");
    let run = |extra: &[&str], out: &Path| {
        let mut args = vec![
            "preprocess",
            s(&log),
            "--out",
            s(out),
            "--subtract-reflected-inertia",
            "sidecar",
            "--label-filter",
            "matched",
        ];
        args.extend(extra);
        ok(frictl(&args), "preprocess");
        let ds = dataset(out);
        let rms =
            frictionless_acquire::leg::label_error_rms_nm(&ds).expect("truth and sliding rows");
        (rms, sidecar(out))
    };
    let (e_mat, side_mat) = run(&[], &d.join("matched.csv"));
    let (e_rip, side_rip) = run(&["--ripple", "wave-generator"], &d.join("ripple.csv"));
    assert_eq!(side_mat["settings"]["ripple"], "off");
    assert_eq!(side_rip["settings"]["ripple"], "wave-generator");
    let fit = &side_rip["settings"]["ripple_fit"];
    let (a, b) = (
        fit["sin_nm"].as_f64().unwrap(),
        fit["cos_nm"].as_f64().unwrap(),
    );
    let plant = &sidecar(&log)["plant"];
    let expected = plant["e1"].as_f64().unwrap() * plant["f_c0_nm"].as_f64().unwrap();
    eprintln!(
        "ripple amplitude {:.3} Nm (plant e1·f_c0 {expected:.3} Nm); label − truth RMS: matched \
         {e_mat:.3} Nm, with the ripple step {e_rip:.3} Nm",
        a.hypot(b)
    );
    assert_eq!(fit["applied"], true, "{fit}");
    assert!(
        (a.hypot(b) / expected - 1.0).abs() < 0.3,
        "amplitude {} vs {expected}",
        a.hypot(b)
    );
    assert!(e_rip < 0.95 * e_mat, "{e_rip} vs {e_mat}");
    for (extra, needle) in [
        (&["--ripple", "wave-generator"][..], "matched"),
        (
            &["--label-filter", "matched", "--ripple", "gears"][..],
            "off, wave-generator",
        ),
    ] {
        let out = d.join("bad.csv");
        let mut args = vec!["preprocess", s(&log), "--out", s(&out)];
        args.extend(extra);
        let e = err_text(frictl(&args), "a refused ripple setting");
        assert!(e.contains(needle), "{e}");
        assert!(!out.exists());
    }
}

/// A log that leaves no valid row (the first 0.2 s of an acquisition: the joint mostly at rest,
/// every row within the matched smoother's reach of a rejected one) is refused by `frictl
/// preprocess --label-filter matched`, with and without `--ripple wave-generator`, naming the
/// dataset and the counts, and nothing is written (before: a dataset and sidecar of 200 rows,
/// 0 valid, that looked complete).
#[test]
fn preprocess_writes_no_dataset_without_a_valid_row() {
    let (d, log) = small_knee_log("no-valid");
    let text = std::fs::read_to_string(&log).unwrap();
    let head: Vec<&str> = text.lines().take(201).collect();
    let short = d.join("short.csv");
    std::fs::write(&short, head.join("\n") + "\n").unwrap();
    std::fs::copy(log.with_extension("json"), short.with_extension("json")).unwrap();
    for extra in [
        &["--label-filter", "matched", "--ripple", "wave-generator"][..],
        &["--label-filter", "matched"][..],
    ] {
        let out = d.join("short_ds.csv");
        let mut args = vec!["preprocess", s(&short), "--out", s(&out)];
        args.extend_from_slice(extra);
        let e = err_text(frictl(&args), &format!("preprocess {extra:?} of 200 rows"));
        assert!(
            e.contains("short_ds.csv: not written")
                && e.contains("none of its 200 samples is valid"),
            "{extra:?}: {e}"
        );
        assert!(
            !out.exists() && !out.with_extension("json").exists(),
            "{extra:?}: a dataset was written"
        );
    }
    // One motor-angle glitch (1e308 rad: its double, the ripple's angle, is not finite): that
    // chunk gets no ripple correction and every valid label stays finite (before: the ripple
    // step failed with "position sample … = NaN is not finite").
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let col = lines[0]
        .split(',')
        .position(|c| c == "theta_motor_rad")
        .unwrap();
    let mid = lines.len() / 2;
    let mut cells: Vec<String> = lines[mid].split(',').map(str::to_owned).collect();
    cells[col] = "1e308".into();
    lines[mid] = cells.join(",");
    let glitch = d.join("glitch.csv");
    std::fs::write(&glitch, lines.join("\n") + "\n").unwrap();
    std::fs::copy(log.with_extension("json"), glitch.with_extension("json")).unwrap();
    let out = d.join("glitch_ds.csv");
    ok(
        frictl(&[
            "preprocess",
            s(&glitch),
            "--out",
            s(&out),
            "--label-filter",
            "matched",
            "--ripple",
            "wave-generator",
        ]),
        "preprocess --ripple of a log with a motor-angle glitch",
    );
    let ds = dataset(&out);
    let valid: Vec<f64> = (0..ds.len())
        .filter(|&k| ds.valid[k])
        .map(|k| ds.tau_f_label_nm[k])
        .collect();
    assert!(
        valid.len() > 1000 && valid.iter().all(|f| f.is_finite()),
        "{} valid rows",
        valid.len()
    );
}

/// The robot's options are refused, before the log is read, when they would change the label
/// silently: the labelled joint held by `--fixed-joint` (before: accepted, the knee's label moved
/// by 11.8 Nm RMS), a joint held twice or at an absurd position (1e308 rad), a `--joint` twice.
#[test]
fn held_joints_that_are_labelled_repeated_or_absurd_are_refused_before_reading() {
    let d = crate::util::scratch("frictl-import-held");
    std::fs::create_dir_all(&d).unwrap();
    let log = d.join("log.csv");
    std::fs::write(&log, "t,q\n").unwrap();
    let out = d.join("out.csv");
    for (extra, says) in [
        (
            &["--joint", "l_knee", "--joint", "l_knee"][..],
            "--joint l_knee: given twice",
        ),
        (
            &["--joint", "l_knee", "--fixed-joint", "l_knee=0.1"][..],
            "`l_knee` is the labelled joint",
        ),
        (
            &[
                "--joint",
                "l_knee",
                "--urdf-joint",
                "knee",
                "--fixed-joint",
                "knee=0.1",
            ][..],
            "`knee` is the labelled joint",
        ),
        (
            &["--joint", "l_knee", "--fixed-joint", "l_hip_pitch=1e308"][..],
            "more than three turns",
        ),
        (
            &[
                "--joint",
                "l_knee",
                "--fixed-joint",
                "l_hip_pitch=0.1",
                "--fixed-joint",
                "l_hip_pitch=0.2",
            ][..],
            "held twice",
        ),
    ] {
        let mut a = vec![
            "import",
            "csv",
            s(&log),
            "--column",
            "time=t",
            "--column",
            "s=q",
            "--urdf",
            "virtual_leg",
            "-o",
            s(&out),
        ];
        a.extend_from_slice(extra);
        let err = err_text(frictl(&a), &format!("{extra:?}"));
        assert!(err.contains(says), "{extra:?}: {err}");
        assert!(!out.exists());
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// The other joints' positions are checked like the labelled joint's before labelling: in degrees
/// (every sample outside the URDF limits; before: no warning, the knee's label off by 17.9 Nm RMS)
/// or with one glitch sample (1e6 or 1e308 rad; before: 74 rows valid with label errors up to
/// 109 Nm, or "0 valid … check the units") the import is refused naming the joint's column.
#[test]
fn the_other_joints_positions_are_checked_against_the_urdf_before_labelling() {
    let d = dir().join("legstate");
    let _ = std::fs::remove_dir_all(&d);
    ok(
        frictl(&[
            "acquire",
            "--preset",
            "leg",
            "--seed",
            "3",
            "--out",
            s(&d),
            "--set",
            "protocol.n_starts=1",
            "--set",
            "protocol.current_scale=0.4",
            "--set",
            "protocol.sines.frequencies_hz=[0.7]",
            "--set",
            "protocol.ramps.slopes_a_per_s=[0.39]",
            "--set",
            "protocol.steps.levels_a=[0.8]",
        ]),
        "acquire --preset leg",
    );
    let log = d.join("leg_seed3.csv");
    let leg = frictionless_sim::LegParams::preset().unwrap();
    let knee = leg.joints.iter().find(|p| p.joint == "l_knee").unwrap();
    let (r, kt) = (
        format!("{}", knee.gear_ratio_signed),
        format!("{}", knee.kt_nm_per_a),
    );
    let urdf = ergocub_urdf();
    let import = |log: &Path, out: &Path| {
        frictl(&[
            "import",
            "csv",
            s(log),
            "--label",
            "current",
            "--joint",
            "l_knee",
            "--column",
            "time=time_s",
            "--column",
            "s=q_{joint}",
            "--column",
            "current=i_{joint}",
            "--column",
            "theta=theta_{joint}",
            "--column",
            "omega=omega_{joint}",
            "--gear-ratio",
            &r,
            "--kt",
            &kt,
            "--urdf",
            s(&urdf),
            "--positions",
            "q_{joint}",
            "-o",
            s(out),
        ])
    };
    ok(import(&log, &d.join("good.csv")), "import of the clean log");
    // The log with the hip pitch's position column rewritten row by row.
    let text = std::fs::read_to_string(&log).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let col = header
        .split(',')
        .position(|c| c == "q_l_hip_pitch")
        .unwrap();
    let rewrite = |name: &str, f: &dyn Fn(usize, f64) -> f64| {
        let mut out = format!("{header}\n");
        for (k, l) in text.lines().skip(1).enumerate() {
            let mut v: Vec<String> = l.split(',').map(str::to_owned).collect();
            let q: f64 = v[col].parse().unwrap();
            v[col] = format!("{:?}", f(k, q));
            out.push_str(&v.join(","));
            out.push('\n');
        }
        let p = d.join(name);
        std::fs::write(&p, out).unwrap();
        p
    };
    let n = text.lines().count() - 1;
    for (name, f, says) in [
        (
            "deg.csv",
            &(|_, q: f64| q.to_degrees() + 90.0) as &dyn Fn(usize, f64) -> f64,
            "declare the unit",
        ),
        (
            "glitch6.csv",
            &|k, q| if k == n / 2 { 1e6 } else { q },
            "a glitch",
        ),
        (
            "glitch308.csv",
            &|k, q| if k == n / 3 { 1e308 } else { q },
            "a glitch",
        ),
    ] {
        let bad = rewrite(name, f);
        let out = d.join(format!("out_{name}"));
        let err = err_text(import(&bad, &out), name);
        assert!(
            err.contains("joint `l_hip_pitch`")
                && err.contains("URDF limits")
                && err.contains(says),
            "{name}: {err}"
        );
        assert!(!out.exists(), "{name}: a dataset was written");
    }
    // A missing --base-quat column is named as that option's, not as a role's (before: "(role s)").
    let err = err_text(
        frictl(&[
            "import",
            "csv",
            s(&log),
            "--label",
            "current",
            "--joint",
            "l_knee",
            "--column",
            "time=time_s",
            "--column",
            "s=q_{joint}",
            "--column",
            "current=i_{joint}",
            "--gear-ratio",
            &r,
            "--kt",
            &kt,
            "--urdf",
            s(&urdf),
            "--positions",
            "q_{joint}",
            "--base-quat",
            "qx,qy,qz,qw",
            "-o",
            s(&d.join("quat.csv")),
        ]),
        "a missing --base-quat column",
    );
    assert!(err.contains("column `qx` (of --base-quat)"), "{err}");
    // An all-zero base quaternion is named as such (before: "check the units and --gap-s").
    let quat = d.join("quat0.csv");
    let mut out = format!("{header},qx,qy,qz,qw\n");
    for l in text.lines().skip(1) {
        out.push_str(l);
        out.push_str(",0,0,0,0\n");
    }
    std::fs::write(&quat, out).unwrap();
    let err = err_text(
        frictl(&[
            "import",
            "csv",
            s(&quat),
            "--label",
            "current",
            "--joint",
            "l_knee",
            "--column",
            "time=time_s",
            "--column",
            "s=q_{joint}",
            "--column",
            "current=i_{joint}",
            "--column",
            "theta=theta_{joint}",
            "--column",
            "omega=omega_{joint}",
            "--gear-ratio",
            &r,
            "--kt",
            &kt,
            "--urdf",
            s(&urdf),
            "--positions",
            "q_{joint}",
            "--base-quat",
            "qx,qy,qz,qw",
            "-o",
            s(&d.join("quat0_out.csv")),
        ]),
        "an all-zero base quaternion",
    );
    assert!(
        err.contains("is not a rotation") && err.contains("norm 0.000"),
        "{err}"
    );
    std::fs::remove_dir_all(&d).unwrap();
}

/// A gear ratio the import needs but was not given is an error naming `--gear-ratio` (not the NaN it
/// stands for inside), and `frictl preprocess` on a robot's CSV (no acquisition sidecar) points to
/// `frictl import`.
#[test]
fn a_missing_gear_ratio_names_the_flag_and_preprocess_of_a_robot_csv_points_to_import() {
    let d = dir().join("noratio");
    std::fs::create_dir_all(&d).unwrap();
    let log = d.join("robot.csv");
    write_log(&log, 1.0, 1);
    let out = d.join("ds.csv");
    let e = err_text(
        frictl(&[
            "import",
            "csv",
            s(&log),
            "--joint",
            "wrist",
            "--column",
            "time=time",
            "--column",
            "s=q_deg",
            "--column",
            "theta=theta_motor",
            "--column",
            "tau_f=friction_nm",
            "--unit",
            "s=deg",
            "--kt",
            "0.1",
            "-o",
            s(&out),
        ]),
        "import without --gear-ratio",
    );
    assert!(e.contains("--gear-ratio"), "{e}");
    assert!(!e.contains("NaN"), "{e}");
    assert!(!out.exists(), "nothing written on error");
    let e = err_text(
        frictl(&["preprocess", s(&log), "--out", s(&out)]),
        "preprocess of a robot CSV",
    );
    assert!(e.contains("frictl import"), "{e}");
    assert!(e.contains("robot.json"), "{e}");
}
