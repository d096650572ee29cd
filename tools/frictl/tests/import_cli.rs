//! `frictl import csv|mcap|mat` as a user runs it: two CSV logs of a virtual joint (jittered 2–3 ms
//! time, position in degrees, a given friction column, pauses) → `frictl import csv` → `frictl fit
//! scv` → `frictl train --features delta-theta-joint-vel`; the sidecar's runs, label, absent columns
//! and conversions; errors naming the column and header; `import mcap` on a bag written by the Python
//! `mcap` packages (skipped without `FRICTIONLESS_PY`); `import mat` without the `mat` feature.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn frictl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(args)
        .env("SOURCE_DATE_EPOCH", "1700000000")
        .output()
        .expect("frictl runs")
}

fn ok(out: Output, what: &str) -> Output {
    assert!(
        out.status.success(),
        "{what} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn err_text(out: Output, what: &str) -> String {
    assert!(!out.status.success(), "{what} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("frictl-import-cli-{}", std::process::id()));
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
fn mcap_bag_imports_with_the_effort_as_given_friction() {
    let Some(py) = std::env::var_os("FRICTIONLESS_PY") else {
        eprintln!("SKIPPED: FRICTIONLESS_PY is unset (python with mcap, mcap-ros2-support)");
        return;
    };
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
fn mat_file_imports_with_the_current_label_and_two_chunks() {
    let Some(py) = std::env::var_os("FRICTIONLESS_PY") else {
        eprintln!("SKIPPED: FRICTIONLESS_PY is unset (python with numpy, h5py)");
        return;
    };
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
    assert!(e.contains("--gear-ratio NaN: must be finite"), "{e}");
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
