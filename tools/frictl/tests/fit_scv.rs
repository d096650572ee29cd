//! `frictl fit scv` is never worse than `frictl fit cv` on held-out data: on the virtual joints of the
//! demo (knee and ankle roll presets, labels from `frictl preprocess`) and on the virtual leg's knee
//! (labelled by `frictl import` from the whole leg's state), the SCV's held-out RMSE is at
//! most the CV's, and the JSON and the console say whether the SCV won its validation block or fell
//! back to the CV (and why), and which parameters sit on a bound.

use crate::util::{err_text, frictl, frictl_ok, s, small_acquire_args};
use std::path::{Path, PathBuf};

/// A held-out run's protocol: other sine, ramp, step and tracking settings than the training run.
const OTHER_PROTOCOL: [&str; 6] = [
    "protocol.n_starts=1",
    "protocol.sines.frequencies_hz=[0.5]",
    "protocol.ramps.slopes_a_per_s=[0.5]",
    "protocol.steps.levels_a=[0.4]",
    "protocol.tracking.train.amplitudes_rad=[0.15]",
    "protocol.tracking.train.frequencies_hz=[0.7]",
];

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

fn preprocess(dir: &Path, name: &str) -> PathBuf {
    let ds = dir.join(format!("ds_{name}.csv"));
    frictl_ok(&[
        "preprocess",
        s(&dir.join(format!("{name}.csv"))),
        "--out",
        s(&ds),
        "--link-from-sidecar",
    ]);
    ds
}

/// Fits `model` on `train`, scored on `held`: the fit JSON and the console text.
fn fit(dir: &Path, model: &str, train: &Path, held: &Path) -> (serde_json::Value, String) {
    let out = dir.join(format!("{model}.json"));
    let run = frictl(&[
        "fit",
        model,
        s(train),
        "--test-dataset",
        s(held),
        "--json",
        s(&out),
    ]);
    let err = String::from_utf8_lossy(&run.stderr).into_owned();
    assert!(run.status.success(), "frictl fit {model}: {err}");
    (json(&out), err)
}

fn held_rmse(f: &serde_json::Value) -> f64 {
    let h = &f["held_out"][0];
    assert!(h["rows"].as_u64().unwrap() > 1000, "{h}");
    h["rmse_nm"].as_f64().unwrap()
}

/// The SCV's held-out RMSE ≤ the CV's, and the report says what the SCV fit decided.
fn scv_is_not_worse_than_cv(dir: &Path, train: &Path, held: &Path) {
    let (cv, _) = fit(dir, "cv", train, held);
    let (scv, err) = fit(dir, "scv", train, held);
    let (c, v) = (held_rmse(&cv), held_rmse(&scv));
    println!(
        "{}: held-out RMSE CV {c:.4} Nm, SCV {v:.4} Nm; {}",
        dir.display(),
        scv["scv"]
    );
    assert!(
        v <= c * (1.0 + 1e-9),
        "held-out RMSE: SCV {v} Nm > CV {c} Nm: {scv}"
    );
    let r = &scv["scv"];
    let val = &r["validation"];
    assert!(val["rows"].as_u64().unwrap() > 100, "{r}");
    let p = &scv["params"];
    match r["fallback"].as_str() {
        Some(why) => {
            assert!(err.contains(why), "the console says why: {err}");
            assert_eq!(p["ks"], p["kc"], "a fallback is the CV: {p}");
            assert_eq!(
                p["kc"], cv["params"]["kc"],
                "the same CV as `frictl fit cv`"
            );
        }
        None => {
            assert!(err.contains("validation block"), "{err}");
            assert!(
                val["scv_rmse_nm"].as_f64().unwrap() < val["cv_rmse_nm"].as_f64().unwrap(),
                "{r}"
            );
        }
    }
    let at = scv["at_bounds"].as_array().unwrap();
    if !at.is_empty() {
        assert!(err.contains("parameters on a bound"), "{err}");
    }
}

fn preset_case(preset: &str) {
    let dir = crate::util::scratch(&format!("fit-scv-{preset}"));
    std::fs::create_dir_all(&dir).unwrap();
    frictl_ok(&small_acquire_args(preset, "1", &dir, "train", &[]));
    let mut args = vec![
        "acquire", "--preset", preset, "--seed", "2", "--name", "held", "--out",
    ];
    args.push(s(&dir));
    for set in &OTHER_PROTOCOL {
        args.extend_from_slice(&["--set", set]);
    }
    frictl_ok(&args);
    let train = preprocess(&dir, "train");
    let held = preprocess(&dir, "held");
    scv_is_not_worse_than_cv(&dir, &train, &held);
    // The fit is a frictiond joint: without --gear-ratio `frictl config` names the flag; with it,
    // frictiond's checker accepts the SCV joint.
    let cfg = dir.join("frictiond.toml");
    let fit = dir.join("scv.json");
    let base = [
        "config",
        "--max-curr",
        "5",
        "--joint",
        "j",
        "--kt",
        "0.1",
        "--fit",
        s(&fit),
    ];
    let mut a = base.to_vec();
    a.extend(["--out", s(&cfg)]);
    let e = err_text(frictl(&a), "config without --gear-ratio");
    assert!(e.contains("--gear-ratio"), "{e}");
    assert!(!cfg.exists());
    a.extend(["--gear-ratio", "100"]);
    frictl_ok(&a);
    let c = frictiond_config::load(&cfg).unwrap();
    assert_eq!(
        c.raw.joint[0].friction_model,
        frictiond_config::ModelKind::Scv
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn scv_fit_is_not_worse_than_cv_held_out_on_the_virtual_knee() {
    preset_case("knee");
}

#[test]
fn scv_fit_is_not_worse_than_cv_held_out_on_the_virtual_ankle_roll() {
    preset_case("ankle_roll");
}

/// A short run of the virtual leg (`frictl acquire --preset leg`, every joint excited at once) with
/// `protocol` (sine, ramp, step), imported as the knee's whole-state `current` dataset: its path.
fn leg_knee_dataset(dir: &Path, seed: &str, protocol: [&str; 3]) -> PathBuf {
    let mut args = vec![
        "acquire",
        "--preset",
        "leg",
        "--seed",
        seed,
        "--out",
        s(dir),
        "--set",
        "protocol.n_starts=1",
        "--set",
        "protocol.current_scale=0.4",
        "--set",
        "protocol.sines.amplitude_to_a=0.7",
    ];
    for set in &protocol {
        args.extend_from_slice(&["--set", set]);
    }
    frictl_ok(&args);
    let leg = frictionless_sim::LegParams::preset().unwrap();
    let knee = leg.joints.iter().find(|p| p.joint == "l_knee").unwrap();
    let (r, kt) = (
        knee.gear_ratio_signed.to_string(),
        knee.kt_nm_per_a.to_string(),
    );
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/ergocub/ergoCubSN001.urdf");
    let log = dir.join(format!("leg_seed{seed}.csv"));
    let ds = dir.join(format!("knee_seed{seed}.csv"));
    frictl_ok(&[
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
        "--column",
        "theta=theta_{joint}",
        "--positions",
        "q_{joint}",
        "--urdf",
        s(&urdf),
        "--gear-ratio",
        &r,
        "--kt",
        &kt,
        "-o",
        s(&ds),
    ]);
    ds
}

/// On the leg (the knee's label from the whole leg's state while every joint moves), the SCV is
/// not worse than the CV on a held-out run either.
#[test]
fn scv_fit_is_not_worse_than_cv_held_out_on_the_leg_knee() {
    let dir = crate::util::scratch("fit-scv-leg");
    std::fs::create_dir_all(&dir).unwrap();
    let train = leg_knee_dataset(
        &dir,
        "5",
        [
            "protocol.sines.frequencies_hz=[0.7]",
            "protocol.ramps.slopes_a_per_s=[0.39]",
            "protocol.steps.levels_a=[0.8, -0.8]",
        ],
    );
    let held = leg_knee_dataset(
        &dir,
        "6",
        [
            "protocol.sines.frequencies_hz=[0.5]",
            "protocol.ramps.slopes_a_per_s=[0.5]",
            "protocol.steps.levels_a=[0.6, -0.6]",
        ],
    );
    scv_is_not_worse_than_cv(&dir, &train, &held);
    std::fs::remove_dir_all(&dir).ok();
}
