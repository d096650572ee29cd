//! `frictl robot run` on the tiny two-joint robot of `python/ray/tests/robot_tiny.toml` (the virtual
//! knee and ankle roll, 4 trials of 2 epochs): one frictiond config with both PINNs that `frictiond
//! --check` accepts, a report per joint, every stage skipped on a second run; and the external-
//! scheduler entry points of `frictl search`: two processes running disjoint `--only-trials` into one
//! directory, then `frictl search finish`, give the table a single `frictl search` gives.
//!
//! Needs `frictiond` built next to `frictl` (`cargo build --workspace --bins`, as `tests/run.sh`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::util::s;
use frictionless_experiment::session::Binaries;
use frictionless_train::search::{TrialResult, read_results};

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

fn tmp(name: &str) -> PathBuf {
    let d = crate::util::scratch(&format!("frictl-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `frictiond --config CFG --check` (the frictiond built next to this frictl) accepts `cfg`.
fn frictiond_check(cfg: &Path) {
    let bins = Binaries::with_frictl(PathBuf::from(env!("CARGO_BIN_EXE_frictl")))
        .expect("frictiond built next to frictl (cargo build --workspace --bins)");
    let check = Command::new(&bins.frictiond)
        .args(["--config", s(cfg), "--check"])
        .output()
        .unwrap();
    assert!(
        check.status.success(),
        "frictiond --check: {}{}",
        String::from_utf8_lossy(&check.stdout),
        String::from_utf8_lossy(&check.stderr)
    );
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
        assert_eq!(j.friction_model, frictiond_config::ModelKind::Pinn);
        assert_eq!((j.gear_ratio, j.kfc), (r, kfc), "{}", j.name);
        let model = j.model.as_ref().unwrap();
        assert_eq!(
            std::fs::read(out.join(model)).unwrap(),
            std::fs::read(out.join(format!("joints/{}/search/best.fwt", j.name))).unwrap()
        );
    }
    // frictiond itself accepts it (models, joint names and k_t checked against the files).
    frictiond_check(&cfg_path);

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

/// A joint's dataset: `frictl import csv` of a log with time, s, ṡ, a given friction column and the
/// motor temperature (with `motor`: also the motor position θ = r·s − 0.002·τ_F), 1 kHz, eight 1 s
/// segments, written as `dir/rel`. Without `motor` it is a torque-sensed joint's (no motor encoder).
fn torque_sensed_dataset(dir: &Path, rel: &str) {
    joint_dataset(dir, rel, false)
}

fn joint_dataset(dir: &Path, rel: &str, motor: bool) {
    let log = dir.join("log.csv");
    let mut text = String::from("t,q,qd,friction,temp,theta\n");
    for k in 0..8000 {
        // Eight 1 s segments, 0.3 s apart: eight chunks for the train/validation/test split.
        let t = k as f64 * 1e-3 + 0.3 * (k / 1000) as f64;
        let (q, v) = (0.4 * (2.0 * t).sin(), 0.8 * (2.0 * t).cos());
        let f = 0.3 * (50.0 * v).tanh() + 0.2 * v;
        text += &format!("{t},{q},{v},{f},{},{}\n", 30.0 + t, 100.0 * q - 0.002 * f);
    }
    std::fs::write(&log, text).unwrap();
    let out = dir.join(rel);
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    let theta: &[&str] = if motor {
        &["--column", "theta=theta"]
    } else {
        &[]
    };
    let args: Vec<&str> = [
        "import",
        "csv",
        s(&log),
        "--joint",
        "r_wrist",
        "--column",
        "time=t",
        "--column",
        "s=q",
        "--column",
        "sdot=qd",
        "--column",
        "tau_f=friction",
        "--column",
        "temperature=temp",
        "--gear-ratio",
        "100",
        "--kt",
        "0.1",
        "-o",
        s(&out),
    ]
    .iter()
    .chain(theta)
    .copied()
    .collect();
    ok_in(dir, &args);
}

/// A one-joint robot file of the dataset `data/ds.csv` (relative) with `extra` lines in the joint.
fn torque_sensed_robot(dir: &Path, search: &str, extra: &str) {
    std::fs::write(
        dir.join("robot.toml"),
        format!(
            "{search}\n[[joint]]\nname = \"r_wrist\"\ndatasets = [\"data/ds.csv\"]\ngear_ratio = 100.0\nkt_nm_per_a = 0.1\nmax_curr_a = 3.0\n{extra}\n"
        ),
    )
    .unwrap();
}

#[test]
fn a_relative_robot_file_finds_its_relative_datasets() {
    // The README's form: `frictl robot run robot.toml` in the robot file's directory, datasets
    // relative to it, a relative --out.
    let dir = tmp("robot-relative");
    torque_sensed_dataset(&dir, "data/ds.csv");
    torque_sensed_robot(&dir, "[search]\ntrials = 0", "");
    ok_in(
        &dir,
        &["robot", "run", "robot.toml", "--out", "o", "--until", "fit"],
    );
    assert!(dir.join("o/joints/r_wrist/cv.json").is_file());
    assert!(dir.join("o/joints/r_wrist/scv.json").is_file());
    // The plan names the datasets by absolute path (a Ray worker runs elsewhere).
    let plan: serde_json::Value =
        serde_json::from_slice(&ok_in(&dir, &["robot", "plan", "robot.toml", "--out", "o"]).stdout)
            .unwrap();
    let train = plan["joints"][0]["train"][0].as_str().unwrap();
    assert_eq!(Path::new(train), dir.join("data/ds.csv"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The PIDs whose parent is `pid` (from `/proc/*/stat`).
fn children_of(pid: u32) -> Vec<u32> {
    let mut out = vec![];
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Some(child) = e.file_name().to_str().and_then(|n| n.parse::<u32>().ok()) else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
            continue;
        };
        // `pid (comm) state ppid …`: comm may hold spaces, so split after the last ')'.
        let rest = &stat[stat.rfind(')').map_or(0, |k| k + 1)..];
        let ppid = rest.split_whitespace().nth(1).and_then(|p| p.parse().ok());
        if ppid == Some(pid) {
            out.push(child);
        }
    }
    out
}

/// Whether `pid` is a live process (not absent, not a zombie).
fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
        let rest = &stat[stat.rfind(')').map_or(0, |k| k + 1)..];
        rest.split_whitespace().next() != Some("Z")
    })
}

/// Polls `cond` every 50 ms; panics with `what` after 10 minutes (a hung test, not a timing assert).
fn wait_for<T>(what: &str, mut cond: impl FnMut() -> Option<T>) -> T {
    let t0 = std::time::Instant::now();
    loop {
        if let Some(v) = cond() {
            return v;
        }
        assert!(t0.elapsed().as_secs() < 600, "gave up waiting for {what}");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// A robot whose search runs for minutes (100 trials × 350 epochs), started in `dir` on `--out o`;
/// returns it once its `frictl search` child runs, with that child's PID.
fn long_search(dir: &Path) -> (std::process::Child, u32) {
    joint_dataset(dir, "data/ds.csv", true);
    torque_sensed_robot(dir, "[search]\ntrials = 100\nepochs = 350", "");
    let robot = dir.join("robot.toml");
    let mut parent = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(["robot", "run", s(&robot), "--out", "o"])
        .current_dir(dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let pid = parent.id();
    let search = wait_for("the search child", || {
        if let Some(st) = parent.try_wait().unwrap() {
            panic!("robot run ended ({st}) before its search started");
        }
        children_of(pid).into_iter().find(|c| {
            std::fs::read(format!("/proc/{c}/cmdline"))
                .is_ok_and(|cmd| String::from_utf8_lossy(&cmd).contains("search\0"))
        })
    });
    (parent, search)
}

#[test]
fn a_second_robot_run_on_one_output_directory_is_refused_naming_the_first() {
    let dir = tmp("robot-lock");
    let (mut first, search) = long_search(&dir);
    let robot = dir.join("robot.toml");
    let second = frictl_in(
        &dir,
        &["robot", "run", s(&robot), "--out", "o", "--until", "fit"],
    );
    let err = String::from_utf8_lossy(&second.stderr).into_owned();
    // Ends the first before asserting (SIGKILL: the lock goes with the process).
    let _ = first.kill();
    let _ = first.wait();
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(search as i32),
        nix::sys::signal::Signal::SIGKILL,
    );
    assert!(
        !second.status.success(),
        "the second run was not refused:\n{err}"
    );
    assert!(
        err.contains(&format!("pid {}", first.id())) && err.contains(".robot-run.lock"),
        "{err}"
    );
    // The lock went with the first: a new run on the directory proceeds.
    ok_in(
        &dir,
        &["robot", "run", s(&robot), "--out", "o", "--until", "fit"],
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn sigterm_to_robot_run_ends_and_reaps_its_search_child() {
    let dir = tmp("robot-sigterm");
    let (mut parent, search) = long_search(&dir);
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(parent.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let status = parent.wait().unwrap();
    let orphan = alive(search);
    if orphan {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(search as i32),
            nix::sys::signal::Signal::SIGKILL,
        );
    }
    assert!(!status.success());
    assert!(!orphan, "the search child {search} outlived robot run");
    assert!(!dir.join("o/joints/r_wrist/search/best.fwt").exists());
    assert!(!dir.join("o/joints/r_wrist/stamps/search.sha256").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn sigkill_of_robot_run_takes_its_search_child_and_a_rerun_owns_the_directory() {
    // Before: the search child lived on under PID 1 and a rerun started a second search in the
    // same directory.
    let dir = tmp("robot-sigkill");
    let (mut parent, search) = long_search(&dir);
    parent.kill().unwrap();
    let _ = parent.wait();
    let gone = (0..2400).any(|_| {
        std::thread::sleep(std::time::Duration::from_millis(50));
        !alive(search)
    });
    if !gone {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(search as i32),
            nix::sys::signal::Signal::SIGKILL,
        );
    }
    assert!(
        gone,
        "the search child {search} outlived a SIGKILLed robot run"
    );
    // The locks went with both processes: a rerun proceeds.
    let robot = dir.join("robot.toml");
    ok_in(
        &dir,
        &["robot", "run", s(&robot), "--out", "o", "--until", "fit"],
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_torque_sensed_joint_trains_on_joint_pos_joint_vel_with_temperature() {
    // No motor encoder: the dataset has s, ṡ and the temperature but no θ or ω.
    let dir = tmp("robot-torque-sensed");
    torque_sensed_dataset(&dir, "data/ds.csv");
    torque_sensed_robot(
        &dir,
        "[search]\ntrials = 0\n[train]\nhidden = [8]\nhistory = 4\nepochs = 2\nbatch = 256",
        "features = \"joint-pos-joint-vel\"\ntemperature = true",
    );
    ok_in(&dir, &["robot", "run", "robot.toml", "--out", "o"]);
    let model = frictionless::weights::read_file(&dir.join("o/joints/r_wrist/pinn.fwt")).unwrap();
    assert_eq!(
        model.meta.features.set,
        frictionless::features::FeatureSet::JointPosJointVel
    );
    assert!(model.meta.features.temperature);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("o/report.json")).unwrap()).unwrap();
    assert_eq!(
        report["joints"]["r_wrist"]["features"],
        "joint-pos-joint-vel"
    );
    assert_eq!(report["joints"]["r_wrist"]["temperature"], true);
    // Every feature set of the core is accepted by name (one list: the core's).
    for set in frictionless::features::FeatureSet::ALL {
        torque_sensed_robot(&dir, "", &format!("features = \"{set}\""));
        let plan = ok_in(&dir, &["robot", "plan", "robot.toml"]);
        assert!(
            String::from_utf8_lossy(&plan.stdout).contains(&format!("\"{set}\"")),
            "{set}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `[search] pick = true`: the robot runs the search's pick (the fastest trial within
/// `max_rmse_ratio` × the best validation RMSE), passes the ratio to the search, and its frictiond
/// config loads that model.
#[test]
fn a_search_pick_is_the_model_the_robot_runs() {
    let dir = tmp("robot-search-pick");
    torque_sensed_dataset(&dir, "data/ds.csv");
    torque_sensed_robot(
        &dir,
        "[search]\ntrials = 3\nepochs = 1\nhidden = [4, 12]\nhistory = [3, 5]\npick = true\nmax_rmse_ratio = 1.5",
        "features = \"joint-pos-joint-vel\"",
    );
    let plan: serde_json::Value =
        serde_json::from_slice(&ok_in(&dir, &["robot", "plan", "robot.toml", "--out", "o"]).stdout)
            .unwrap();
    let joint = &plan["joints"][0];
    assert_eq!(joint["model"], "joints/r_wrist/search/pick.fwt");
    let args: Vec<&str> = joint["search_args"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap())
        .collect();
    assert!(args.contains(&"--max-rmse-ratio=1.5"), "{args:?}");
    ok_in(&dir, &["robot", "run", "robot.toml", "--out", "o"]);
    let search = dir.join("o/joints/r_wrist/search");
    let pick = std::fs::read(search.join("pick.fwt")).unwrap();
    // The pick is one of the trials, and the frictiond config names it.
    let config = std::fs::read_to_string(dir.join("o/frictiond.toml")).unwrap();
    assert!(config.contains("search/pick.fwt"), "{config}");
    let trial_files: Vec<Vec<u8>> = std::fs::read_dir(search.join("trials"))
        .unwrap()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "fwt"))
        .map(|e| std::fs::read(e.path()).unwrap())
        .collect();
    assert!(trial_files.contains(&pick), "pick.fwt is a trial's model");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// One uninterrupted 14 s recording of a joint with joint and motor encoders (`frictl import csv`,
/// 1 kHz, θ = 100·s − 0.002·τ_F + 3 rad: the encoder's zero of that boot), written as `dir/rel`.
fn one_recording(dir: &Path, rel: &str) {
    let log = dir.join("one.csv");
    let mut text = String::from("t,q,qd,friction,theta\n");
    for k in 0..14_000 {
        let t = k as f64 * 1e-3;
        let w = 2.0 + 0.5 * (0.3 * t).sin();
        let (q, v) = (0.4 * (w * t).sin(), 0.4 * w * (w * t).cos());
        let f = 0.3 * (50.0 * v).tanh() + 0.2 * v;
        text += &format!("{t},{q},{v},{f},{}\n", 100.0 * q - 0.002 * f + 3.0);
    }
    std::fs::write(&log, text).unwrap();
    let out = dir.join(rel);
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    ok_in(
        dir,
        &[
            "import",
            "csv",
            s(&log),
            "--joint",
            "r_wrist",
            "--column",
            "time=t",
            "--column",
            "s=q",
            "--column",
            "sdot=qd",
            "--column",
            "tau_f=friction",
            "--column",
            "theta=theta",
            "--gear-ratio",
            "100",
            "--kt",
            "0.1",
            "-o",
            s(&out),
        ],
    );
}

/// A robot whose joint has one recording and an incremental motor encoder: `robot run` trains with
/// validation and test blocks of that recording (the default fractions), latches Δθ per chunk, and
/// writes a frictiond joint with `motor_encoder = "incremental"`, no fixed offset and its CV fit as
/// the static fallback (`ood = "static"`), which frictiond's own checker accepts.
#[test]
fn one_recording_with_an_incremental_encoder_gives_a_latched_joint_with_a_static_fallback() {
    let dir = tmp("robot-one-recording");
    one_recording(&dir, "data/ds.csv");
    torque_sensed_robot(
        &dir,
        "[search]\ntrials = 0\n[train]\nhidden = [8]\nhistory = 4\nepochs = 1\nbatch = 256",
        "motor_encoder = \"incremental\"",
    );
    ok_in(&dir, &["robot", "run", "robot.toml", "--out", "o"]);
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("o/joints/r_wrist/pinn.train.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(report["delta_theta_offset"], "chunk");
    assert!(report["datasets"][0]["delta_theta_offset_motor_rad"].is_null());
    assert!(report["split"]["val_samples"].as_u64().unwrap() > 0);
    assert!(!report["split"]["blocks"].as_array().unwrap().is_empty());
    let cfg = frictiond_config::load(&dir.join("o/frictiond.toml")).unwrap();
    let j = &cfg.raw.joint[0];
    assert_eq!(j.motor_encoder, frictiond_config::MotorEncoder::Incremental);
    assert_eq!(j.delta_theta_offset_motor_rad, None);
    assert_eq!(j.ood, frictiond_config::OodMode::Static);
    // The evaluation scores the test blocks of the recording.
    let eval: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("o/joints/r_wrist/eval.json")).unwrap(),
    )
    .unwrap();
    let n = eval
        .pointer("/datasets/0/evaluated")
        .and_then(|v| v.as_u64());
    let test_rows: u64 = report["split"]["blocks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|b| {
            report["split"]["test"]
                .as_array()
                .unwrap()
                .contains(&b["key"])
        })
        .map(|b| b["end_row"].as_u64().unwrap() - b["start_row"].as_u64().unwrap())
        .sum();
    assert!(
        n.is_some_and(|n| n > 0 && n <= test_rows),
        "eval of the test blocks ({test_rows} rows): {n:?}"
    );
    let cv =
        frictionless_dataset::fit_file::FittedModel::read_cv(&dir.join("o/joints/r_wrist/cv.json"))
            .unwrap();
    assert_eq!((j.kc, j.ka, j.kv), (Some(cv.kc), Some(cv.ka), Some(cv.kv)));
    // The same robot with an absolute encoder keeps the training log's offset.
    torque_sensed_robot(
        &dir,
        "[search]\ntrials = 0\n[train]\nhidden = [8]\nhistory = 4\nepochs = 1\nbatch = 256",
        "",
    );
    ok_in(&dir, &["robot", "run", "robot.toml", "--out", "o"]);
    let cfg = frictiond_config::load(&dir.join("o/frictiond.toml")).unwrap();
    let off = cfg.raw.joint[0].delta_theta_offset_motor_rad.unwrap();
    assert!((off - 3.0).abs() < 0.05, "the log's encoder zero: {off}");
    assert_eq!(
        cfg.raw.joint[0].motor_encoder,
        frictiond_config::MotorEncoder::Absolute
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// One 14 s recording of a two-joint robot in its own CSV format (milliseconds, degrees, a column per
/// joint named after it; θ = 100·s − 0.002·τ_F + 3 rad, the given friction τ_F), as `dir/rel`.
fn robot_log(dir: &Path, rel: &str, seed: f64) {
    let mut text = String::from("t_ms,q_a_deg,friction_a,theta_a,q_b_deg,friction_b,theta_b\n");
    for k in 0..14_000 {
        let t = k as f64 * 1e-3;
        let mut row = format!("{}", t * 1e3);
        for (amp, w0) in [(0.4, 2.0 + seed), (0.3, 1.5 + seed)] {
            let w = w0 + 0.5 * (0.3 * t).sin();
            let (q, v) = (amp * (w * t).sin(), amp * w * (w * t).cos());
            let f = 0.3 * (50.0 * v).tanh() + 0.2 * v;
            row += &format!(",{},{f},{}", q.to_degrees(), 100.0 * q - 0.002 * f + 3.0);
        }
        text += &row;
        text.push('\n');
    }
    let p = dir.join(rel);
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(p, text).unwrap();
}

/// `frictl robot run` from the robot's own CSV log named in the robot file: `[import]` maps its
/// columns and units once for both joints (`{joint}` in the templates); joint `a` takes one
/// recording (evaluated on its split's test blocks), joint `b` its own import table with a held-out
/// recording. The frictiond config it writes is accepted by `frictiond --check`; a second run redoes
/// nothing; an option `frictl import` does not have is refused before any stage, naming the joint.
#[test]
fn robot_run_from_the_robots_own_csv_log_gives_a_checked_config() {
    let dir = tmp("robot-import-csv");
    robot_log(&dir, "logs/walk.csv", 0.0);
    robot_log(&dir, "logs/walk_again.csv", 0.3);
    let robot = |extra: &str| {
        format!(
            r#"[search]
trials = 0
[train]
hidden = [8]
history = 4
epochs = 1
batch = 256

[import]
format = "csv"
logs = ["logs/walk.csv"]
column = {{ time = "t_ms", s = "q_{{joint}}_deg", tau_f = "friction_{{joint}}", theta = "theta_{{joint}}" }}
unit = {{ time = "ms", s = "deg" }}
{extra}
[[joint]]
name = "a"
gear_ratio = 100.0
kt_nm_per_a = 0.1
max_curr_a = 5.0

[[joint]]
name = "b"
gear_ratio = 100.0
kt_nm_per_a = 0.1
max_curr_a = 4.0
import = {{ logs = ["logs/walk.csv"], test_logs = ["logs/walk_again.csv"] }}
"#
        )
    };
    std::fs::write(dir.join("robot.toml"), robot("")).unwrap();
    let run = ok_in(&dir, &["robot", "run", "robot.toml", "--out", "o"]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("joints/a: import_train …"), "{err}");
    assert!(err.contains("joints/b: import_test …"), "{err}");
    assert!(!err.contains("joints/a: import_test"), "{err}");
    // Each joint's dataset is its own columns, in SI units.
    for (j, amp) in [("a", 0.4), ("b", 0.3)] {
        let ds = frictionless_dataset::Dataset::read_csv(
            &dir.join(format!("o/joints/{j}/train_ds.csv")),
        )
        .unwrap();
        let max = ds.s_rad.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(
            (max - amp).abs() < 0.01,
            "{j}: |s| max {max} rad, not {amp}"
        );
        let side: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(format!("o/joints/{j}/train_ds.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(side["joint"], j);
    }
    let cfg_path = dir.join("o/frictiond.toml");
    let cfg = frictiond_config::load(&cfg_path).unwrap();
    let names: Vec<&str> = cfg.raw.joint.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["a", "b"]);
    frictiond_check(&cfg_path);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("o/report.json")).unwrap()).unwrap();
    for j in ["a", "b"] {
        for m in ["cv", "scv", "pinn"] {
            let e = report["joints"][j]["eval_rmse_nm"][m].as_f64();
            assert!(
                e.is_some_and(|e| e > 0.0 && e.is_finite()),
                "{j} {m}: {e:?}"
            );
        }
    }
    let md = std::fs::read_to_string(dir.join("o/report.md")).unwrap();
    assert!(md.contains("1 csv log(s)"), "{md}");
    // Again: nothing to redo.
    let again = ok_in(&dir, &["robot", "run", "robot.toml", "--out", "o"]);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(!err.contains(" …"), "nothing re-run:\n{err}");
    // A key `frictl import csv` has no flag for: refused before anything runs, naming the joint.
    std::fs::write(dir.join("robot.toml"), robot("colum = { s = \"x\" }")).unwrap();
    let bad = frictl_in(&dir, &["robot", "run", "robot.toml", "--out", "o2"]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("joint a") && err.contains("colum"), "{err}");
    assert!(!dir.join("o2/joints").exists(), "no stage ran");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `frictl robot run` from the whole-leg log of an ergoCub (Pinocchio's fixture) as the robot wrote
/// it: the knee from the ROS 2 bag (`[import]`, the effort field holding the motor current), the
/// ankle pitch from the YARP logger's `.mat` (its own import table; the bag without the `mat`
/// feature), each labelled with the current and the whole-body τ_ID on the robot's URDF, as
/// Pinocchio labels them (no motor encoder in these logs: the joint-side feature set); the frictiond
/// config is accepted by `frictiond --check`.
#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh): Pinocchio writes the whole-body log"]
fn robot_run_from_the_robots_own_mcap_and_mat_logs_labels_on_the_urdf() {
    use crate::import_cli::{dataset, ergocub_urdf, leg_fixture, leg_ref, rms_vs};
    let d = leg_fixture();
    let dir = tmp("robot-import-leg");
    let ankle_import = if cfg!(feature = "mat") {
        format!(
            r#"{{ format = "mat", logs = ["{}"] }}"#,
            s(&d.join("leg.mat"))
        )
    } else {
        "{ effort = \"current\" }".to_owned()
    };
    let robot = format!(
        r#"[robot]
urdf = "{urdf}"
[search]
trials = 0
[train]
hidden = [8]
history = 4
epochs = 1
batch = 256

[import]
format = "mcap"
logs = ["{bag}"]
effort = "current"
label = "current"

[[joint]]
name = "l_knee"
gear_ratio = 100.0
kt_nm_per_a = 0.1
max_curr_a = 5.0
features = "joint-pos-joint-vel"

[[joint]]
name = "l_ankle_pitch"
gear_ratio = 100.0
kt_nm_per_a = 0.1
max_curr_a = 5.0
features = "joint-pos-joint-vel"
import = {ankle_import}
"#,
        urdf = s(&ergocub_urdf()),
        bag = s(&d.join("leg.mcap")),
    );
    std::fs::write(dir.join("robot.toml"), robot).unwrap();
    ok_in(&dir, &["robot", "run", "robot.toml", "--out", "o"]);
    for j in ["l_knee", "l_ankle_pitch"] {
        let ds = dataset(&dir.join(format!("o/joints/{j}/train_ds.csv")));
        let (rms, n) = rms_vs(&ds, &ds.tau_id_nm, &leg_ref(&format!("tau_id_{j}")));
        eprintln!("robot run {j}: tau_ID RMS {rms:.4} Nm against Pinocchio on {n} samples");
        assert!(n > 10_000 && rms < 0.15, "{j}: RMS {rms} on {n}");
    }
    let cfg_path = dir.join("o/frictiond.toml");
    frictiond_check(&cfg_path);
    let md = std::fs::read_to_string(dir.join("o/report.md")).unwrap();
    let want = if cfg!(feature = "mat") {
        "1 mat log(s)"
    } else {
        "1 mcap log(s)"
    };
    assert!(md.contains("1 mcap log(s)") && md.contains(want), "{md}");
    std::fs::remove_dir_all(&dir).unwrap();
}
