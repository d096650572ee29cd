//! `frictl fit lugre` identifies the simulator's LuGre joint: the virtual knee with its extras off
//! (ripple, temperature, load-dependent and direction-dependent Coulomb, motor-side friction), so
//! the plant's output-side friction is a LuGre model; acquire → preprocess → fit on the truth
//! column, scored on a held-out run with another excitation.

use crate::util::{frictl_ok as frictl, s, small_acquire_args};
use std::path::Path;

/// The plant overrides that leave the output-side LuGre as the joint's only friction.
const LUGRE_ONLY: [&str; 8] = [
    "plant.e1=0",
    "plant.e2=0",
    "plant.mu_load=0",
    "plant.delta_f_c_nm=0",
    "plant.beta_v_per_k=0",
    "plant.beta_c_per_k=0",
    "plant.f_cm_nm=0",
    "plant.sigma2m_nms_per_rad=0",
];

/// The held-out run's protocol: other sine, ramp, step and tracking settings than the training run.
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

fn preprocess(dir: &Path, name: &str) -> std::path::PathBuf {
    let ds = dir.join(format!("ds_{name}.csv"));
    frictl(&[
        "preprocess",
        s(&dir.join(format!("{name}.csv"))),
        "--out",
        s(&ds),
        "--link-from-sidecar",
    ]);
    ds
}

#[test]
fn lugre_fit_identifies_the_simulated_joint_and_beats_scv_on_held_out_data() {
    let dir = crate::util::scratch("fit-lugre");
    std::fs::create_dir_all(&dir).unwrap();
    frictl(&small_acquire_args("knee", "1", &dir, "train", &LUGRE_ONLY));
    let mut args = vec![
        "acquire", "--preset", "knee", "--seed", "2", "--name", "held", "--out",
    ];
    args.push(s(&dir));
    for set in OTHER_PROTOCOL.iter().chain(&LUGRE_ONLY) {
        args.extend_from_slice(&["--set", set]);
    }
    frictl(&args);
    let train = preprocess(&dir, "train");
    let held = preprocess(&dir, "held");
    let plant = json(&dir.join("train.json"))["plant"].clone();
    let truth = |k: &str| plant[k].as_f64().unwrap_or_else(|| panic!("plant.{k}"));

    let fit = |model: &str| {
        let out = dir.join(format!("{model}.json"));
        frictl(&[
            "fit",
            model,
            s(&train),
            "--truth",
            "--test-dataset",
            s(&held),
            "--json",
            s(&out),
        ]);
        json(&out)
    };
    let lugre = fit("lugre");
    let scv = fit("scv");
    let p = &lugre["params"];
    for (got, want) in [
        ("kc", "f_c0_nm"),
        ("ks", "f_s0_nm"),
        ("sigma0", "sigma0_nm_per_rad"),
        ("sigma1", "sigma1_nms_per_rad"),
    ] {
        let (g, w) = (p[got].as_f64().unwrap(), truth(want));
        assert!(
            (g - w).abs() <= 0.2 * w,
            "{got} = {g}, plant {want} = {w} (±20 %): {lugre}"
        );
    }
    assert_eq!(
        lugre["param_units"],
        serde_json::json!(["Nm", "Nm·s/rad", "Nm", "rad/s", "1", "Nm/rad", "Nm·s/rad"])
    );
    let held_rmse = |f: &serde_json::Value| {
        let h = &f["held_out"][0];
        assert_eq!(h["source"], s(&held));
        assert!(h["rows"].as_u64().unwrap() > 1000, "{h}");
        h["rmse_nm"].as_f64().unwrap()
    };
    let (l, c) = (held_rmse(&lugre), held_rmse(&scv));
    assert!(l < c, "held-out RMSE: LuGre {l} Nm, SCV {c} Nm");
    // The stages each lower the error on the fitted rows.
    let stages = lugre["lugre"]["stages"].as_array().unwrap();
    let r: Vec<f64> = stages
        .iter()
        .map(|x| x["rmse_nm"].as_f64().unwrap())
        .collect();
    assert!(r.windows(2).all(|w| w[1] <= w[0]), "{stages:?}");
    // The fit is a frictiond joint: `frictl config` writes it and frictiond's checker accepts it.
    let cfg = dir.join("frictiond.toml");
    frictl(&[
        "config",
        "--max-curr",
        "5",
        "--joint",
        "l_knee",
        "--gear-ratio",
        "100",
        "--kt",
        "0.1",
        "--fit",
        s(&dir.join("lugre.json")),
        "--out",
        s(&cfg),
    ]);
    let text = std::fs::read_to_string(&cfg).unwrap();
    assert!(
        text.contains("friction_model = \"lugre\"") && text.contains("sigma0"),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
