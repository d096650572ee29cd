//! `frictl robot run` on the tiny two-joint robot of `python/ray/tests/robot_tiny.toml` (the virtual
//! knee and ankle roll, 4 trials of 2 epochs): one frictiond config with both PINNs that `frictiond
//! --check` accepts, a report per joint, every stage skipped on a second run; and the external-
//! scheduler entry points of `frictl search`: two processes running disjoint `--only-trials` into one
//! directory, then `frictl search finish`, give the table a single `frictl search` gives.
//!
//! Needs `frictiond` built next to `frictl` (`cargo build --workspace --bins`, as `tests/run.sh`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use frictionless_train::search::{TrialResult, read_results};
use frictl::experiment::session::Binaries;

const ROBOT: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../python/ray/tests/robot_tiny.toml"
);

fn frictl_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("frictl runs")
}

fn ok_in(dir: &Path, args: &[&str]) -> Output {
    let out = frictl_in(dir, args);
    assert!(
        out.status.success(),
        "frictl {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("frictl-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn ranked(dir: &Path) -> Vec<TrialResult> {
    serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap()
}

#[test]
fn a_two_joint_robot_gives_one_checked_frictiond_config_and_resumes_by_stamp() {
    let dir = tmp("robot-run");
    let out = dir.join("out");
    let run = ok_in(&dir, &["robot", "run", ROBOT, "--out", s(&out)]);
    let cfg_path = out.join("frictiond.toml");
    let cfg = frictiond_config::load(&cfg_path).unwrap();
    let names: Vec<&str> = cfg.raw.joint.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["l_knee", "l_ankle_roll"]);
    for (j, (r, kfc)) in cfg.raw.joint.iter().zip([(-100.0, 0.85), (-160.0, 0.7)]) {
        assert_eq!(j.friction_model, frictiond_config::FrictionModelName::Pinn);
        assert_eq!((j.gear_ratio, j.kfc), (r, kfc), "{}", j.name);
        let model = j.model.as_ref().unwrap();
        assert_eq!(
            std::fs::read(out.join(model)).unwrap(),
            std::fs::read(out.join(format!("joints/{}/search/best.fwt", j.name))).unwrap()
        );
    }
    // frictiond itself accepts it (models, joint names and k_t checked against the files).
    let bins = Binaries::with_frictl(PathBuf::from(env!("CARGO_BIN_EXE_frictl")))
        .expect("frictiond built next to frictl (cargo build --workspace --bins)");
    let check = Command::new(&bins.frictiond)
        .args(["--config", s(&cfg_path), "--check"])
        .output()
        .unwrap();
    assert!(
        check.status.success(),
        "frictiond --check: {}{}",
        String::from_utf8_lossy(&check.stdout),
        String::from_utf8_lossy(&check.stderr)
    );

    // The per-joint report: every joint, its search and its evaluation.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    for joint in ["l_knee", "l_ankle_roll"] {
        let j = &report["joints"][joint];
        assert_eq!(j["search"]["trials"], 4, "{joint}");
        assert_eq!(j["search"]["ok"], 4, "{joint}");
        let best = &ranked(&out.join(format!("joints/{joint}/search")))[0];
        assert_eq!(j["search"]["best_trial"], best.params.trial);
        for m in ["none", "cv", "scv", "pinn"] {
            assert!(j["eval_rmse_nm"][m].as_f64().unwrap() > 0.0, "{joint} {m}");
        }
        assert!(out.join(format!("joints/{joint}/{joint}.onnx")).is_file());
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| l_knee |") && md.contains("| l_ankle_roll |"));
    assert!(String::from_utf8_lossy(&run.stderr).contains("search …"));

    // Again: every stage up to date.
    let again = ok_in(&dir, &["robot", "run", ROBOT, "--out", s(&out)]);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(!err.contains(" …"), "nothing re-run:\n{err}");
    // A damaged output (the knee's test dataset cut to its header) is not used by the stages that
    // read it: the stage that wrote it runs again, naming it, and restores it.
    let test_ds = out.join("joints/l_knee/test_ds.csv");
    let text = std::fs::read_to_string(&test_ds).unwrap();
    std::fs::write(&test_ds, format!("{}\n", text.lines().next().unwrap())).unwrap();
    let third = ok_in(&dir, &["robot", "run", ROBOT, "--out", s(&out)]);
    let err = String::from_utf8_lossy(&third.stderr);
    assert!(
        err.contains("joints/l_knee/test_ds.csv is not the file the stage wrote"),
        "{err}"
    );
    assert!(err.contains("joints/l_knee: preprocess_test …"), "{err}");
    assert_eq!(std::fs::read_to_string(&test_ds).unwrap(), text, "restored");
    assert!(err.contains("joints/l_knee: search up to date"), "{err}");
    assert!(
        !err.contains("joints/l_ankle_roll: preprocess_test …"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn only_trials_from_two_processes_then_finish_equal_one_search() {
    let dir = tmp("robot-trials");
    let out = dir.join("out");
    // The ankle's data and fits only.
    ok_in(
        &dir,
        &[
            "robot",
            "run",
            ROBOT,
            "--out",
            s(&out),
            "--joint",
            "l_ankle_roll",
            "--until",
            "fit",
        ],
    );
    let plan: serde_json::Value =
        serde_json::from_slice(&ok_in(&dir, &["robot", "plan", ROBOT, "--out", s(&out)]).stdout)
            .unwrap();
    let joint = &plan["joints"][1];
    assert_eq!(joint["name"], "l_ankle_roll");
    let base: Vec<String> = joint["search_args"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap().to_owned())
        .collect();
    let with = |extra: &[&str]| -> Vec<String> {
        base.iter()
            .cloned()
            .chain(extra.iter().map(|e| e.to_string()))
            .collect()
    };
    // Reference: one search of the 4 trials, 1 thread each.
    let reference = with(&[
        "--out",
        "single",
        "--parallel",
        "2",
        "--threads",
        "2",
        "--quiet",
    ]);
    ok_in(
        &out,
        &reference.iter().map(String::as_str).collect::<Vec<_>>(),
    );
    // Two processes at the same time into one directory, then finish.
    let spawn = |trials: &str| {
        let a = with(&[
            "--out",
            "shared",
            "--only-trials",
            trials,
            "--threads",
            "1",
            "--quiet",
        ]);
        Command::new(env!("CARGO_BIN_EXE_frictl"))
            .args(&a)
            .current_dir(&out)
            .spawn()
            .unwrap()
    };
    let (mut p1, mut p2) = (spawn("0,2"), spawn("3,1"));
    assert!(p1.wait().unwrap().success() && p2.wait().unwrap().success());
    let shared = out.join("shared");
    let lines = read_results(&shared.join("results.jsonl")).unwrap();
    let mut idx: Vec<usize> = lines.iter().map(|r| r.params.trial).collect();
    idx.sort();
    assert_eq!(idx, [0, 1, 2, 3], "each trial appended once, no torn line");
    assert!(
        !shared.join("results.json").exists(),
        "--only-trials writes no tables"
    );
    // A repeated request runs nothing (the trials are recorded).
    let rerun = ok_in(
        &out,
        &with(&["--out", "shared", "--only-trials", "1", "--threads", "1"])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(String::from_utf8_lossy(&rerun.stdout).contains("0 of 1 requested"));
    assert_eq!(
        read_results(&shared.join("results.jsonl")).unwrap().len(),
        4
    );
    ok_in(&out, &["search", "finish", "shared"]);
    let (a, b) = (ranked(&out.join("single")), ranked(&shared));
    assert_eq!(a.len(), 4);
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(
            x.params, y.params,
            "same trial order, same hyper-parameters"
        );
        let (vx, vy) = (x.val_rmse_nm.unwrap(), y.val_rmse_nm.unwrap());
        assert!(
            (vx - vy).abs() <= 1e-9 * vx,
            "trial {}: {vx} vs {vy}",
            x.params.trial
        );
    }
    assert!(shared.join("best.fwt").is_file());
    // Other settings in the same directory are refused before any work.
    let other = frictl_in(
        &out,
        &with(&["--out", "shared", "--only-trials", "1", "--dtype", "f16"])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(!other.status.success());
    assert!(String::from_utf8_lossy(&other.stderr).contains("dtype"));
    std::fs::remove_dir_all(&dir).unwrap();
}
