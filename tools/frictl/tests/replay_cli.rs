//! `frictl replay`: recorded data played through `frictiond` as deployed. On the virtual knee with
//! an incremental motor encoder (every power-up its own zero), `frictl robot run` trains on one boot
//! and is held out on another boot at another pose; the config it writes, replayed on the held-out
//! log, gives the estimate of the offline evaluation that latches Δθ per log. A config that carries
//! the training boot's encoder zero instead sees every row out of its training range and drives the
//! static fallback, which replay shows. Bad input is refused before frictiond starts.
//!
//! Needs `frictiond` built next to `frictl` (`cargo build --workspace --bins`, as `tests/run.sh`).

use std::path::{Path, PathBuf};

use crate::util::{SMALL_PROTOCOL, err_text, frictl, frictl_cmd, ok, s, scratch};

/// A one-joint robot: the virtual knee, an incremental motor encoder on the plant for both the
/// training and the held-out acquisition (the latter booted at another pose, so with another
/// encoder zero), a small fixed network. `declared` is the robot file's `motor_encoder` line.
fn robot_file(dir: &Path, name: &str, declared: &str) -> PathBuf {
    let train_set: Vec<String> = SMALL_PROTOCOL
        .iter()
        .map(|s| format!("{s:?}"))
        .chain(["\"plant.sensors.motor_encoder=incremental\"".into()])
        .collect();
    let text = format!(
        r#"[robot]
name = "incremental knee"
seed = 5

[acquire]
set = [{}]
test_set = [
    "protocol.n_starts=1",
    "protocol.tracking.test.amplitudes_rad=[0.15]",
    "protocol.tracking.test.frequencies_hz=[0.7]",
    "protocol.tracking.test.cycles=2.0",
    "plant.sensors.motor_encoder=incremental",
    "plant.initial_s_rad=-0.5",
]

[search]
trials = 0

[train]
hidden = [32, 32]
history = 10
epochs = 20
batch = 512

[[joint]]
name = "l_knee"
preset = "knee"
gear_ratio = -100.0
kt_nm_per_a = 0.157
max_curr_a = 5.0
kfc = 0.85
{declared}
"#,
        train_set.join(", ")
    );
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn run_in(dir: &Path, args: &[&str]) {
    ok(
        frictl_cmd().args(args).current_dir(dir).output().unwrap(),
        &format!("frictl {args:?}"),
    );
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// The PINN's and CV's held-out RMSE [Nm] from `frictl robot run`'s evaluation.
fn eval_rmse(out: &Path) -> (f64, f64) {
    let e = json(&out.join("joints/l_knee/eval.json"));
    let m = &e["datasets"][0]["models"];
    (
        m["pinn"]["rmse_all"].as_f64().unwrap(),
        m["cv"]["rmse_all"].as_f64().unwrap(),
    )
}

fn replay(dir: &Path, out: &str, replay_dir: &str) -> serde_json::Value {
    run_in(
        dir,
        &[
            "replay",
            "--config",
            &format!("{out}/frictiond.toml"),
            "--dataset",
            &format!("l_knee={out}/joints/l_knee/test_ds.csv"),
            "--out",
            replay_dir,
        ],
    );
    json(&dir.join(replay_dir).join("replay.json"))
}

#[test]
fn replay_of_another_boot_matches_the_latched_evaluation_and_a_fixed_zero_falls_back() {
    let dir = scratch("frictl-replay");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();

    // Declared incremental: trained latched per chunk, no offset in the config.
    let robot = robot_file(&dir, "robot.toml", "motor_encoder = \"incremental\"");
    run_in(&dir, &["robot", "run", s(&robot), "--out", "inc"]);
    let cfg = frictiond_config::load(&dir.join("inc/frictiond.toml")).unwrap();
    assert_eq!(cfg.raw.joint[0].delta_theta_offset_motor_rad, None);
    let md = std::fs::read_to_string(dir.join("inc/report.md")).unwrap();
    assert!(
        md.contains(
            "one training ([train]: hidden [32, 32], history 10, 20 epoch(s), batch 512) per joint"
        ),
        "the report names what trained the PINN: {md}"
    );
    let r = replay(&dir, "inc", "replay_inc");
    let j = &r["joints"][0];
    let rows = j["rows"].as_u64().unwrap();
    let test = frictionless_dataset::Dataset::read_csv(&dir.join("inc/joints/l_knee/test_ds.csv"))
        .unwrap();
    assert_eq!(
        rows as usize,
        test.len(),
        "one replayed row per dataset row"
    );
    let csv = std::fs::read_to_string(dir.join("replay_inc/l_knee.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        frictionless_experiment::replay::REPLAY_COLUMNS.join(",")
    );
    assert_eq!(lines.count(), test.len());
    let replayed = j["rmse_vs_label_nm"].as_f64().unwrap();
    let (latched, cv) = eval_rmse(&dir.join("inc"));
    eprintln!(
        "incremental: replay {replayed:.4} Nm, latched offline eval {latched:.4} Nm, CV {cv:.4} Nm"
    );
    assert!(
        replayed <= 1.2 * latched,
        "frictiond on another boot: {replayed} Nm against the per-log latched {latched} Nm"
    );
    assert!(
        replayed < cv,
        "the PINN beats CV through frictiond: {replayed} vs {cv}"
    );
    let ood = j["out_of_range_rows"].as_u64().unwrap();
    assert!(ood * 10 < rows, "{ood} of {rows} rows out of range");

    // Declared absolute: the config keeps the training boot's zero, which is wrong on this boot.
    let robot = robot_file(&dir, "robot_abs.toml", "");
    run_in(&dir, &["robot", "run", s(&robot), "--out", "abs"]);
    let cfg = frictiond_config::load(&dir.join("abs/frictiond.toml")).unwrap();
    assert!(cfg.raw.joint[0].delta_theta_offset_motor_rad.is_some());
    let r = replay(&dir, "abs", "replay_abs");
    let j = &r["joints"][0];
    let ood = j["out_of_range_rows"].as_u64().unwrap();
    assert!(
        ood * 10 > 9 * rows,
        "only {ood} of {rows} rows out of range"
    );
    // Out of range under `ood = "static"`: the estimate frictiond uses is the CV fallback's.
    let fallback = j["rmse_vs_label_nm"].as_f64().unwrap();
    let (_, cv) = eval_rmse(&dir.join("abs"));
    eprintln!("fixed zero: replay {fallback:.4} Nm (static fallback), CV {cv:.4} Nm");
    assert!(
        (fallback - cv).abs() < 0.02 * cv,
        "the static fallback drives the motor: {fallback} vs CV {cv}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_replays_are_refused_naming_the_joint_the_rate_or_the_input() {
    let dir = scratch("frictl-replay-bad");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // A CV joint needs no model file; a 1 kHz and a 500 Hz dataset.
    let cfg = dir.join("frictiond.toml");
    std::fs::write(
        &cfg,
        "[backend]\nkind = \"shm\"\n[[joint]]\nname = \"knee\"\nindex = 0\ngear_ratio = -100.0\nkt = 0.157\nmax_curr = 5.0\nfriction_model = \"cv\"\nkc = 1.0\nka = 50.0\nkv = 0.5\n",
    )
    .unwrap();
    let dataset = |name: &str, dt: f64| {
        let n = 600;
        let col = |v: f64| vec![v; n];
        let time_s: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let s_rad: Vec<f64> = time_s.iter().map(|t| 0.3 * t.sin()).collect();
        let ds = frictionless_dataset::Dataset {
            // Two chunks: replay re-enables the joint at the second's first row.
            chunk: (0..n).map(|k| u32::from(k >= 300)).collect(),
            source_chunk: vec![0; n],
            active: vec![true; n],
            valid: vec![true; n],
            theta_motor_rad: s_rad.iter().map(|s| -100.0 * s).collect(),
            sdot_rad_s: time_s.iter().map(|t| 0.3 * t.cos()).collect(),
            s_rad,
            sddot_rad_s2: col(0.0),
            delta_theta_motor_rad: col(0.0),
            omega_motor_rad_s: col(0.0),
            i_meas_a: col(0.0),
            i_filt_a: col(0.0),
            tau_id_nm: col(0.0),
            tau_f_label_nm: col(1.0),
            temperature_c: col(f64::NAN),
            tau_f_true_nm: None,
            phi_ddot_rad_s2: None,
            time_s,
        };
        let p = dir.join(name);
        ds.write_csv(&p).unwrap();
        p
    };
    let ds = dataset("ds.csv", 1e-3);
    let slow = dataset("slow.csv", 2e-3);
    let replay = |args: &[&str]| {
        let mut a = vec!["replay", "--config", s(&cfg), "--out"];
        a.extend_from_slice(args);
        frictl(&a)
    };
    let out = dir.join("out");
    let e = err_text(
        replay(&[s(&out), "--dataset", &format!("elbow={}", s(&ds))]),
        "unknown joint",
    );
    assert!(e.contains("`elbow`") && e.contains("knee"), "{e}");
    let e = err_text(
        replay(&[s(&out), "--dataset", &format!("knee={}", s(&slow))]),
        "500 Hz dataset",
    );
    assert!(e.contains("2000.0 µs") && e.contains("1000 µs"), "{e}");
    let e = err_text(
        replay(&[
            s(&out),
            "--dataset",
            &format!("knee={}", s(&ds)),
            "--dataset",
            &format!("knee={}", s(&ds)),
        ]),
        "two datasets for a joint",
    );
    assert!(e.contains("`knee` is given two datasets"), "{e}");
    let e = err_text(replay(&[s(&out), "--dataset", "knee"]), "no =");
    assert!(e.contains("JOINT=DATASET.csv"), "{e}");
    // `--out` = the dataset's directory with the joint's CSV being the dataset itself.
    let same = dir.join("same");
    std::fs::create_dir_all(&same).unwrap();
    let knee_csv = same.join("knee.csv");
    std::fs::copy(&ds, &knee_csv).unwrap();
    let before = std::fs::read(&knee_csv).unwrap();
    let e = err_text(
        replay(&[s(&same), "--dataset", &format!("knee={}", s(&knee_csv))]),
        "output over input",
    );
    assert!(e.contains("also an input"), "{e}");
    assert_eq!(
        std::fs::read(&knee_csv).unwrap(),
        before,
        "the input is kept"
    );
    assert!(
        !out.join("replay.json").exists(),
        "nothing written by a refused replay"
    );
    // And the good one runs: a CV joint through frictiond, its estimate the CV model's.
    ok(
        replay(&[s(&out), "--dataset", &format!("knee={}", s(&ds))]),
        "replay",
    );
    let r = json(&out.join("replay.json"));
    assert_eq!(r["joints"][0]["rows"], 600);
    assert_eq!(r["joints"][0]["model_rows"], 600);
    assert_eq!(
        (r["ticks"].as_u64(), r["reenables"].as_u64()),
        (Some(601), Some(1))
    );
    let text = std::fs::read_to_string(out.join("knee.csv")).unwrap();
    let row: Vec<f64> = text
        .lines()
        .nth(101)
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let t: f64 = row[0];
    let v = 0.3 * t.cos();
    let want = (50.0 * v).tanh() + 0.5 * v;
    assert!(
        (row[4] - want).abs() < 1e-9,
        "τ̂_F {} against CV {want}",
        row[4]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
