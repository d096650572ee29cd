//! `frictl preprocess` on a small simulated knee log: every dropped row counted per reason in the
//! console and the sidecar, and gravity an option of τ_ID from the URDF, recorded and checked.

use crate::util::{err_text, frictl, ok, s, small_acquire_args};
use std::path::{Path, PathBuf};

fn sidecar(csv: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(csv.with_extension("json")).unwrap()).unwrap()
}

/// A small knee log in a scratch directory: (directory, log).
fn knee_log(name: &str) -> (PathBuf, PathBuf) {
    let dir = crate::util::scratch(name);
    std::fs::create_dir_all(&dir).unwrap();
    ok(
        frictl(&small_acquire_args("knee", "1", &dir, "knee", &[])),
        "acquire",
    );
    let log = dir.join("knee.csv");
    (dir, log)
}

/// `frictl preprocess LOG -o OUT EXTRA…`: the console text.
fn preprocess(log: &Path, out: &Path, extra: &[&str]) -> String {
    let mut args = vec!["preprocess", s(log), "-o", s(out)];
    args.extend_from_slice(extra);
    let run = ok(frictl(&args), "frictl preprocess");
    String::from_utf8_lossy(&run.stderr).into_owned()
}

#[test]
fn every_dropped_row_is_counted_per_reason_in_the_console_and_the_sidecar() {
    let (dir, log) = knee_log("preprocess-dropped");
    let out = dir.join("ds.csv");
    // A tight |s̈| limit drops the rows of the excitation's fast moves.
    let err = preprocess(&log, &out, &["--joint-acc-limit", "2"]);
    let ds = frictionless_dataset::Dataset::read_csv(&out).unwrap();
    let side = sidecar(&out);
    let d = &side["dropped_rows"];
    let n = |k: &str| d[k].as_u64().unwrap_or_else(|| panic!("{k}: {d}")) as usize;
    let reasons = [
        "short_chunk",
        "non_finite",
        "joint_acc",
        "joint_vel",
        "current",
        "tau_f",
        "near_invalid",
    ];
    let total: usize = reasons.iter().map(|k| n(k)).sum();
    println!("--joint-acc-limit 2: {err}");
    let invalid = ds.valid.iter().filter(|v| !**v).count();
    assert_eq!(total, invalid, "each dropped row once: {d}");
    // The |s̈| column is the one the limit reads (non-causal columns): every invalid row over it
    // counts under the acceleration (the log has no short chunk and no non-finite row).
    let over = (0..ds.len())
        .filter(|&k| !ds.valid[k] && ds.sddot_rad_s2[k].abs() >= 2.0)
        .count();
    assert_eq!((n("short_chunk"), n("non_finite")), (0, 0), "{d}");
    assert!(over > 100, "{over} rows over 2 rad/s²");
    assert_eq!(n("joint_acc"), over, "{d}");
    assert!(
        err.contains(&format!(
            "dropped {total} of {} rows: {over} |s̈| ≥ --joint-acc-limit 2 rad/s²",
            ds.len()
        )),
        "{err}"
    );
    // The default limits drop fewer rows; a row dropped for a limit is named with its flag.
    let err = preprocess(&log, &out, &[]);
    let loose = sidecar(&out)["dropped_rows"]["joint_acc"].as_u64().unwrap() as usize;
    assert!(loose < over, "{loose} >= {over}");
    println!("default limits: {err}");
    if loose > 0 {
        assert!(err.contains("|s̈| ≥ --joint-acc-limit 10 rad/s²"), "{err}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn gravity_is_an_option_of_the_urdf_label_recorded_and_checked() {
    let (dir, log) = knee_log("preprocess-gravity");
    let g0 = 9.80665;
    // The single-joint view of the URDF: τ_ID = I·s̈ + c + g·G(s)/g0, linear in g.
    let tau = |g: f64| {
        let out = dir.join(format!("ds_{g}.csv"));
        let gs = g.to_string();
        let err = preprocess(&log, &out, &["--link", "urdf", "--gravity-m-s2", &gs]);
        let side = sidecar(&out);
        assert_eq!(side["settings"]["gravity_m_s2"].as_f64(), Some(g), "{side}");
        let dynamics = side["dynamics"].as_str().unwrap();
        assert!(dynamics.contains(&format!("g = {g} m/s²")), "{dynamics}");
        assert!(
            err.contains("tau_ID: URDF virtual_leg joint l_knee"),
            "{err}"
        );
        assert!(err.contains(&format!("g = {g} m/s²")), "{err}");
        frictionless_dataset::Dataset::read_csv(&out)
            .unwrap()
            .tau_id_nm
    };
    let (t0, t1, t2) = (tau(0.0), tau(g0), tau(2.0 * g0));
    assert_eq!(t0.len(), t1.len());
    let mut gravity_rms = 0.0;
    for k in 0..t1.len() {
        let grav = t1[k] - t0[k];
        gravity_rms += grav * grav;
        // The gravity term at 2·g0 is twice the one at g0.
        assert!(
            (t2[k] - t0[k] - 2.0 * grav).abs() < 1e-9 * (1.0 + t1[k].abs()),
            "row {k}: {} {} {}",
            t0[k],
            t1[k],
            t2[k]
        );
    }
    let gravity_rms = (gravity_rms / t1.len() as f64).sqrt();
    println!("knee gravity torque at g0: RMS {gravity_rms:.3} Nm");
    assert!(
        gravity_rms > 1.0,
        "the knee's gravity torque: RMS {gravity_rms} Nm"
    );

    // The whole-body RNEA records it in the settings and the dynamics line.
    let out = dir.join("ds_whole.csv");
    let err = preprocess(
        &log,
        &out,
        &["--positions", "q_{joint}", "--gravity-m-s2", "3.5"],
    );
    assert!(
        err.contains("tau_ID: whole-body RNEA") && err.contains("g = 3.5 m/s²"),
        "{err}"
    );
    let side = sidecar(&out);
    assert_eq!(
        side["settings"]["gravity_m_s2"].as_f64(),
        Some(3.5),
        "{side}"
    );
    let dynamics = side["dynamics"].as_str().unwrap();
    assert!(
        dynamics.starts_with("whole-body RNEA") && dynamics.contains("g = 3.5 m/s²"),
        "{dynamics}"
    );

    // Refused, naming the flag and the value: out of range, not a number, and with the
    // simulator's own link model.
    let bad = dir.join("ds_bad.csv");
    for v in ["40", "-1", "nan", "inf", "fast"] {
        let flag = format!("--gravity-m-s2={v}");
        let e = err_text(
            frictl(&[
                "preprocess",
                s(&log),
                "-o",
                s(&bad),
                "--link",
                "urdf",
                &flag,
            ]),
            &flag,
        );
        assert!(e.contains("--gravity-m-s2") && e.contains(v), "{flag}: {e}");
    }
    let e = err_text(
        frictl(&[
            "preprocess",
            s(&log),
            "-o",
            s(&bad),
            "--link",
            "sidecar",
            "--gravity-m-s2",
            "5",
        ]),
        "--link sidecar --gravity-m-s2",
    );
    assert!(
        e.contains("--gravity-m-s2 5") && e.contains("--link urdf"),
        "{e}"
    );
    assert!(!bad.exists() && !bad.with_extension("json").exists());
    std::fs::remove_dir_all(&dir).ok();
}
