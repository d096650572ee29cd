//! On-policy data (DAgger) end to end on tiny settings: a PINN trained on a short open-loop
//! protocol compensates in `frictl experiment record` (plant `frictl sim serve` ↔ `frictiond` ↔ the
//! experiment controller, in lockstep) for a few seconds; the raw log reads back through `frictl
//! preprocess` with compensation-active rows and the plant's true friction; `frictl train --init`
//! continues from the model (its first epoch starts below a fresh initialisation's on the model's
//! own data, the union with the on-policy dataset trains) and refuses another architecture, naming
//! both. Needs `frictiond` built next to `frictl` (`cargo build --workspace --bins`).

use crate::util::{frictl, ok, s, small_acquire_args};
use std::path::{Path, PathBuf};

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).expect("read JSON")).expect("parse JSON")
}

/// Columns of a CSV by name.
fn columns(p: &Path) -> std::collections::BTreeMap<String, Vec<f64>> {
    let text = std::fs::read_to_string(p).expect("read CSV");
    let mut lines = text.lines();
    let names: Vec<String> = lines
        .next()
        .expect("header")
        .split(',')
        .map(str::to_owned)
        .collect();
    let mut cols: Vec<Vec<f64>> = vec![vec![]; names.len()];
    for l in lines {
        for (c, v) in cols.iter_mut().zip(l.split(',')) {
            c.push(v.parse().expect("number"));
        }
    }
    names.into_iter().zip(cols).collect()
}

/// First-epoch training loss of a `frictl train` report.
fn first_epoch_loss(report: &Path) -> f64 {
    json(report)["epochs"][0]["train_loss"]
        .as_f64()
        .expect("epochs[0].train_loss")
}

#[test]
fn closed_loop_recording_labels_and_training_continues_from_the_model() {
    let dir: PathBuf = crate::util::scratch("frictl-onpolicy-cli");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // A short open-loop protocol on the ankle roll, labelled, SCV fitted, a tiny PINN trained.
    ok(
        frictl(&small_acquire_args("ankle_roll", "1", &dir, "run", &[])),
        "acquire",
    );
    let ds = dir.join("ds.csv");
    ok(
        frictl(&["preprocess", s(&dir.join("run.csv")), "--out", s(&ds)]),
        "preprocess",
    );
    let scv = dir.join("scv.json");
    ok(
        frictl(&["fit", "scv", s(&ds), "--json", s(&scv)]),
        "fit scv",
    );
    let tiny = [
        "--history",
        "5",
        "--hidden",
        "16,12",
        "--batch",
        "1024",
        "--lr",
        "3e-3",
        "--threads",
        "2",
        "--val-frac",
        "0",
        "--test-frac",
        "0",
        "--quiet",
    ];
    let train = |out: &Path, datasets: &[&Path], epochs: &str, extra: &[&str]| {
        let mut a = vec![
            "train",
            "--scv",
            s(&scv),
            "--out",
            s(out),
            "--epochs",
            epochs,
        ];
        for d in datasets {
            a.extend(["--dataset", s(d)]);
        }
        // an option in `extra` replaces tiny's (clap refuses a repeated scalar option)
        let mut k = 0;
        while k < tiny.len() {
            if tiny[k] == "--history" && extra.contains(&"--history") {
                k += 2;
                continue;
            }
            a.push(tiny[k]);
            k += 1;
        }
        a.extend(extra);
        frictl(&a)
    };
    let model = dir.join("m0.fwt");
    ok(train(&model, &[&ds], "4", &[]), "train");

    // On-policy recording with the PINN compensating, through the real processes.
    let rec = dir.join("rec");
    ok(
        frictl(&[
            "experiment",
            "record",
            "--joint",
            "ankle_roll",
            "--model",
            "pinn",
            "--pinn",
            &format!("ankle_roll={}", s(&model)),
            "--kp",
            "3000",
            "--record-runs",
            "2",
            "--periods",
            "0.6",
            "--skip-periods",
            "0",
            "--no-plots",
            "--quiet",
            "--out",
            s(&rec),
        ]),
        "experiment record",
    );
    let raw = rec.join("l_ankle_roll_onpolicy.csv");
    let c = columns(&raw);
    for name in [
        "time_s",
        "chunk",
        "active",
        "mode",
        "s_rad",
        "theta_motor_rad",
        "omega_motor_rad_s",
        "i_ref_a",
        "i_meas_a",
        "temperature_c",
        "tau_f_true_nm",
        "phi_ddot",
    ] {
        assert!(c.contains_key(name), "raw log has no `{name}` column");
    }
    let n = c["time_s"].len();
    assert!(n > 2000, "{n} rows");
    assert!(c["mode"].iter().all(|&m| m == 3.0), "closed-loop mode");
    // The sine is one chunk; the pulse run two, before and after the pulse (its rows left out: the
    // label would count the external torque as friction).
    assert_eq!(
        c["chunk"].iter().fold(0.0f64, |a, &b| a.max(b)),
        2.0,
        "chunks: sine, before and after the pulse"
    );
    let t = &c["time_s"];
    let gaps = t.windows(2).filter(|w| w[1] - w[0] > 0.9).count();
    assert_eq!(gaps, 2, "a gap between the runs and one at the pulse");
    let nonzero = |k: &str| c[k].iter().filter(|v| v.is_finite() && **v != 0.0).count();
    assert!(nonzero("i_ref_a") > n / 2, "frictiond's commands logged");
    assert!(nonzero("i_meas_a") > n / 2, "measured current logged");
    assert!(nonzero("tau_f_true_nm") > n / 2, "true friction logged");
    let side = json(&rec.join("l_ankle_roll_onpolicy.json"));
    assert_eq!(side["model"], "PINN");
    assert_eq!(side["runs"].as_array().map(Vec::len), Some(2));
    let record = json(&rec.join("record.json"));
    let err = record["l_ankle_roll"]["runs"][0]["tau_f_rmse_nm"]
        .as_f64()
        .expect("τ̂_F error of the first run");
    assert!(err.is_finite() && err > 0.0, "τ̂_F error {err}");

    // The label pipeline reads it back; the dataset keeps the truth.
    let ods = dir.join("onpolicy_ds.csv");
    ok(
        frictl(&[
            "preprocess",
            s(&raw),
            "--out",
            s(&ods),
            "--subtract-reflected-inertia",
            "sidecar",
        ]),
        "preprocess of the on-policy log",
    );
    let d = columns(&ods);
    assert_eq!(d["time_s"].len(), n);
    assert!(d["valid"].iter().filter(|&&v| v == 1.0).count() > n / 2);
    let truth = &d["tau_f_true_nm"];
    let label = &d["tau_f_label_nm"];
    let (mut e2, mut m) = (0.0, 0usize);
    for k in 0..n {
        if d["valid"][k] == 1.0 && d["sdot_rad_s"][k].abs() > 0.03 {
            e2 += (label[k] - truth[k]).powi(2);
            m += 1;
        }
    }
    assert!(m > 100, "{m} sliding rows");
    let label_rms = (e2 / m as f64).sqrt();
    assert!(label_rms < 0.5, "label vs truth RMS {label_rms} Nm");

    // --init: the model's first epoch on its own data starts below a fresh initialisation's.
    let fresh = dir.join("fresh.fwt");
    ok(train(&fresh, &[&ds], "1", &["--seed", "5"]), "fresh train");
    let cont = dir.join("cont.fwt");
    ok(
        train(&cont, &[&ds], "1", &["--seed", "5", "--init", s(&model)]),
        "train --init",
    );
    let (l_fresh, l_cont) = (
        first_epoch_loss(&fresh.with_extension("train.json")),
        first_epoch_loss(&cont.with_extension("train.json")),
    );
    assert!(
        l_cont < 0.5 * l_fresh,
        "first-epoch loss from the model {l_cont} vs fresh {l_fresh}"
    );
    // The union with the on-policy dataset trains from the model.
    let union = dir.join("union.fwt");
    ok(
        train(&union, &[&ds, &ods], "1", &["--init", s(&model)]),
        "train --init on the union",
    );
    assert_eq!(
        json(&union.with_extension("train.json"))["datasets"]
            .as_array()
            .map(Vec::len),
        Some(2)
    );
    // Another architecture is refused, naming both (a second --hidden appends a layer: 16,12,8).
    let out = train(
        &dir.join("bad.fwt"),
        &[&ds],
        "1",
        &["--init", s(&model), "--hidden", "8"],
    );
    assert!(
        !out.status.success(),
        "16,12,8 from a 16,12 model must fail"
    );
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("hidden [16, 12],") && e.contains("hidden [16, 12, 8]"),
        "error names both architectures: {e}"
    );
    let out = train(
        &dir.join("bad2.fwt"),
        &[&ds],
        "1",
        &["--init", s(&model), "--history", "7"],
    );
    assert!(
        !out.status.success(),
        "--history 7 from an H 5 model must fail"
    );
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("H=5") && e.contains("H=7"),
        "error names both inputs: {e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
