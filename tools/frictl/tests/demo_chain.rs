//! The whole chain end to end through real processes, on tiny settings: `frictl demo --quick`
//! (acquire → preprocess → fit CV/SCV → train a tiny PINN → eval → export) and then
//! `frictl experiment track` in lockstep — the plant (`frictl sim serve`) and `frictiond` as child
//! processes, the computed-torque controller in the `frictl` process — at one low K_p per joint with
//! no compensation, the fitted SCV and the trained PINN.
//!
//! Asserts that compensation with the fitted SCV lowers the tracking error against no compensation
//! at the same K_p on both joints; the PINN's numbers are printed (a 3-epoch network is not expected
//! to win) and must be finite. Needs `frictiond` built next to `frictl` (`cargo build --workspace
//! --bins`, as `tests/run.sh` does).

use std::path::Path;
use std::process::Command;

/// Runs frictl to completion; returns its pid (the prefix of its run directories).
fn frictl(args: &[&str]) -> u32 {
    let child = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start frictl");
    let pid = child.id();
    let out = child.wait_with_output().expect("wait for frictl");
    assert!(
        out.status.success(),
        "frictl {} failed: {}\nstdout:\n{}\nstderr:\n{}",
        args.join(" "),
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    pid
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).expect("read JSON")).expect("parse JSON")
}

/// The per-run directories a `frictl experiment` process `pid` created (`$TMPDIR/flx_<pid>_<n>_<t>`).
fn run_dirs(pid: u32) -> Vec<String> {
    let prefix = format!("flx_{pid}_");
    std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(&prefix))
        .collect()
}

#[test]
fn compensation_with_fitted_models_lowers_tracking_error_at_the_same_kp() {
    let dir = std::env::temp_dir().join(format!("frictl_demo_chain_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let demo = dir.join("demo");
    let d = demo.to_str().unwrap();
    frictl(&[
        "demo",
        "--quick",
        "--no-experiments",
        "--seed",
        "3",
        "--out",
        d,
    ]);
    let report = json(&demo.join("report.json"));
    assert_eq!(report["settings"], "quick");
    assert!(report["stages"].as_array().unwrap().len() >= 14, "{report}");
    let m = |name: &str| demo.join("models").join(name).display().to_string();
    for f in [
        "l_knee_scv.json",
        "l_ankle_roll_scv.json",
        "l_knee.fwt",
        "l_ankle_roll.fwt",
    ] {
        assert!(Path::new(&m(f)).is_file(), "{f} written by the demo");
    }
    let exp = dir.join("exp");
    let pid = frictl(&[
        "experiment",
        "track",
        "--joint",
        "both",
        "--model",
        "none,scv,pinn",
        "--scv",
        &format!(
            "knee={},ankle_roll={}",
            m("l_knee_scv.json"),
            m("l_ankle_roll_scv.json")
        ),
        "--pinn",
        &format!(
            "knee={},ankle_roll={}",
            m("l_knee.fwt"),
            m("l_ankle_roll.fwt")
        ),
        "--kp",
        "knee=100,ankle_roll=3000",
        "--periods",
        "2",
        "--no-plots",
        "--out",
        exp.to_str().unwrap(),
    ]);
    let r = json(&exp.join("report.json"));
    for joint in ["l_knee", "l_ankle_roll"] {
        let rmse = |model: &str| {
            r["joints"][joint][model]["track"][1]["rmse_rad"]
                .as_f64()
                .unwrap_or_else(|| panic!("{joint}/{model}: no tracking RMSE in {r}"))
        };
        let (none, scv, pinn) = (rmse("none"), rmse("SCV"), rmse("PINN"));
        eprintln!("{joint}: tracking RMSE none {none:.4}, SCV {scv:.4}, PINN {pinn:.4} rad");
        assert!(
            scv < none,
            "{joint}: SCV compensation must lower the tracking error ({scv} vs none {none})"
        );
        assert!(pinn.is_finite());
        // the true friction was recorded and the SCV estimate is closer to it than zero is
        let t = &r["joints"][joint]["SCV"]["track"][1];
        let est = t["friction_est_rmse_nm"].as_f64().unwrap();
        let true_rms = t["friction_true_rms_nm"].as_f64().unwrap();
        assert!(
            est < true_rms,
            "{joint}: SCV τ̂_F error {est} vs |τ_F| {true_rms}"
        );
    }
    // every run removed its iceoryx2 root / run directory
    let left = run_dirs(pid);
    assert!(left.is_empty(), "run directories left behind: {left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
