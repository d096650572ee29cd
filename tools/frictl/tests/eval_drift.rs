//! `frictl eval --drift` end to end on the virtual ankle roll: a tiny protocol recorded at a fixed
//! starting temperature, an SCV fit and a small PINN trained on it; then two new logs of the same
//! protocol with another noise seed — one from the same plant, one with the output-side Coulomb level
//! F_c0 tripled (`--set plant.f_c0_nm=2.7`).
//!
//! Checks that the same plant gives `ok` and the changed plant `retrain` (against the training
//! dataset as `--reference`, and against the train report's stored `residual_reference`), that the
//! fired checks are the sliding bands and show the Coulomb change in the mean residual along the motion
//! (≈ +1.8 Nm for SCV), that the PINN's input-range coverage is reported, that the JSON `drift` key and
//! the figure are written, and that bad thresholds are refused by name.

use crate::util::{frictl, ok, s, small_acquire_args};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

struct Fixture {
    dir: PathBuf,
    train_ds: PathBuf,
    same_ds: PathBuf,
    changed_ds: PathBuf,
    scv: PathBuf,
    fwt: PathBuf,
    report: PathBuf,
}

/// Records and labels one log of the tiny ankle-roll protocol (T₀ fixed at 30 °C) into `<name>_ds.csv`.
fn dataset(dir: &Path, name: &str, seed: &str, extra: &[&str]) -> PathBuf {
    let fixed_t0 = [
        "protocol.sines.amplitude_to_a=0.4",
        "plant.t0_min_c=30",
        "plant.t0_max_c=30",
    ];
    let mut args = small_acquire_args("ankle_roll", seed, dir, name, &fixed_t0);
    for set in extra {
        args.extend_from_slice(&["--set", set]);
    }
    ok(frictl(&args), "acquire");
    let raw = dir.join(format!("{name}.csv"));
    let ds = dir.join(format!("{name}_ds.csv"));
    ok(
        frictl(&[
            "preprocess",
            s(&raw),
            "--out",
            s(&ds),
            "--link-from-sidecar",
        ]),
        "preprocess",
    );
    std::fs::remove_file(&raw).ok(); // the raw log is large; the dataset is all the tests read
    ds
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = crate::util::scratch("frictl-eval-drift");
        std::fs::create_dir_all(&dir).unwrap();
        let train_ds = dataset(&dir, "train", "1", &[]);
        let same_ds = dataset(&dir, "same", "2", &[]);
        let changed_ds = dataset(&dir, "changed", "2", &["plant.f_c0_nm=2.7"]);
        let scv = dir.join("scv.json");
        ok(
            frictl(&["fit", "scv", s(&train_ds), "--json", s(&scv)]),
            "fit scv",
        );
        let fwt = dir.join("m.fwt");
        let report = dir.join("train.json");
        ok(
            frictl(&[
                "train",
                "--quiet",
                "--dataset",
                s(&train_ds),
                "--scv",
                s(&scv),
                "--out",
                s(&fwt),
                "--report",
                s(&report),
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
                "--epochs",
                "3",
            ]),
            "train",
        );
        Fixture {
            dir,
            train_ds,
            same_ds,
            changed_ds,
            scv,
            fwt,
            report,
        }
    })
}

/// `frictl eval --drift` on `ds` with SCV and the PINN; returns the JSON `drift` key.
fn drift(ds: &Path, extra: &[&str], tag: &str) -> serde_json::Value {
    let f = fixture();
    let json = f.dir.join(format!("eval_{tag}.json"));
    let mut args = vec![
        "eval",
        "--dataset",
        s(ds),
        "--scv",
        s(&f.scv),
        "--pinn",
        s(&f.fwt),
        "--drift",
        "--json",
        s(&json),
    ];
    args.extend_from_slice(extra);
    let out = ok(frictl(&args), "eval --drift");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("Drift (residual"), "{text}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(v["models"].is_object(), "the eval report's keys stay");
    v["drift"].clone()
}

fn model<'a>(d: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    d["models"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["model"] == name)
        .unwrap_or_else(|| panic!("no model {name} in {d}"))
}

fn fired(m: &serde_json::Value) -> Vec<String> {
    m["checks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["fired"] == true)
        .map(|c| c["what"].as_str().unwrap().to_owned())
        .collect()
}

#[test]
fn same_plant_is_ok_and_a_tripled_coulomb_level_asks_for_retraining() {
    let f = fixture();
    let reference = ["--reference", s(&f.train_ds)];

    let same = drift(&f.same_ds, &reference, "same");
    assert_eq!(same["verdict"], "ok", "{same:#}");
    assert_eq!(same["extrapolating"], false);
    for name in ["scv", "pinn"] {
        let m = model(&same, name);
        assert_eq!(m["verdict"], "ok", "{name}: {:?}", fired(m));
        assert_eq!(m["reference_source"], "reference_datasets");
        // all rows, the stick band and the two sliding bands the protocol covers, one 5 °C bin.
        assert!(m["checks"].as_array().unwrap().len() >= 4, "{m:#}");
        assert!(!m["new"]["temperature"].as_array().unwrap().is_empty());
    }
    let cov = &model(&same, "pinn")["coverage"];
    assert!(cov["rows"].as_u64().unwrap() > 40_000, "{cov}");
    assert!(cov["out_of_range_share"].as_f64().unwrap() < 0.05, "{cov}");
    assert!(model(&same, "scv")["coverage"].is_null());

    let changed = drift(&f.changed_ds, &reference, "changed");
    assert_eq!(changed["verdict"], "retrain", "{changed:#}");
    for name in ["scv", "pinn"] {
        let m = model(&changed, name);
        assert_eq!(m["verdict"], "retrain", "{name}");
        let fired = fired(m);
        assert!(
            fired.iter().any(|w| w.starts_with("band [0.5, 1)")),
            "{name}: {fired:?}"
        );
        assert!(
            !fired.iter().any(|w| w.starts_with("band [0, 0.02)")),
            "{name}: the stick band is held by stiction, not the Coulomb level: {fired:?}"
        );
        assert!(!m["reasons"].as_array().unwrap().is_empty());
    }
    // SCV's Coulomb level is fixed: the new log's friction is ≈ 1.8 Nm larger along the motion.
    let band = model(&changed, "scv")["checks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["what"].as_str().unwrap().starts_with("band [0.5, 1)"))
        .unwrap()
        .clone();
    let shift = band["new"]["mean_along_motion_nm"].as_f64().unwrap()
        - band["reference"]["mean_along_motion_nm"].as_f64().unwrap();
    assert!((1.2..2.4).contains(&shift), "{band:#}");

    // Without --reference: the reference the train report stored.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&f.report).unwrap()).unwrap();
    let rr = &report["residual_reference"];
    assert_eq!(rr["set"], "val", "{rr}");
    assert_eq!(rr["bands"].as_array().unwrap().len(), 5);
    let tr = ["--train-report", s(&f.report)];
    let same = drift(&f.same_ds, &tr, "same_tr");
    let changed = drift(&f.changed_ds, &tr, "changed_tr");
    assert_eq!(model(&same, "pinn")["reference_source"], "train_report:val");
    assert_eq!(model(&same, "pinn")["verdict"], "ok");
    assert_eq!(model(&changed, "pinn")["verdict"], "retrain");
    // The report belongs to the PINN: SCV has no reference then.
    assert_eq!(model(&same, "scv")["verdict"], "no_reference");
}

#[test]
fn drift_writes_its_figure_and_refuses_bad_thresholds() {
    let f = fixture();
    let out = f.dir.join("figs");
    ok(
        frictl(&[
            "eval",
            "--dataset",
            s(&f.same_ds),
            "--pinn",
            s(&f.fwt),
            "--drift",
            "--out",
            s(&out),
        ]),
        "eval --drift --out",
    );
    let png = std::fs::read(out.join("drift_pinn.png")).unwrap();
    assert_eq!(&png[..4], b"\x89PNG");
    // Only the .fwt's validation RMSE as reference: one all-rows check.
    let d = drift(&f.same_ds, &[], "fwt");
    let m = model(&d, "pinn");
    assert_eq!(m["reference_source"], "fwt:val_rmse_nm");
    assert_eq!(m["checks"].as_array().unwrap().len(), 1);

    for (flag, value) in [
        ("--drift-rmse-ratio", "-1"),
        ("--drift-max-out-of-range", "1.5"),
        ("--drift-temperature-bin", "0"),
    ] {
        let arg = format!("{flag}={value}");
        let o = frictl(&[
            "eval",
            "--dataset",
            s(&f.same_ds),
            "--pinn",
            s(&f.fwt),
            "--drift",
            &arg,
        ]);
        assert!(!o.status.success());
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(e.contains(flag), "{flag}: {e}");
    }
}

/// A copy of `ds` (and its sidecar) with every row marked invalid.
fn all_invalid(ds: &Path, name: &str) -> PathBuf {
    let f = fixture();
    let out = f.dir.join(format!("{name}.csv"));
    std::fs::copy(ds.with_extension("json"), out.with_extension("json")).unwrap();
    let text = std::fs::read_to_string(ds).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let col = header.split(',').position(|c| c == "valid").unwrap();
    let mut o = String::from(header) + "\n";
    for l in lines {
        let mut fields: Vec<&str> = l.split(',').collect();
        fields[col] = "0";
        o += &fields.join(",");
        o.push('\n');
    }
    std::fs::write(&out, o).unwrap();
    out
}

#[test]
fn nothing_scored_or_nothing_checked_fails_instead_of_saying_ok() {
    let f = fixture();
    let zero = all_invalid(&f.same_ds, "zero_valid");
    for extra in [&[][..], &["--drift", "--reference", s(&f.train_ds)]] {
        let mut args = vec!["eval", "--dataset", s(&zero), "--scv", s(&f.scv)];
        args.extend_from_slice(extra);
        let out = frictl(&args);
        let e = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success(),
            "eval {extra:?} on 0 valid rows succeeded: {e}"
        );
        assert!(
            e.contains("0 rows scored") && e.contains("0 valid") && e.contains(s(&zero)),
            "{e}"
        );
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(!text.contains("verdict ok"), "{text}");
    }
    // Rows scored, but fewer than --drift-min-samples in every set: no check made, no `ok`.
    let out = frictl(&[
        "eval",
        "--dataset",
        s(&f.same_ds),
        "--scv",
        s(&f.scv),
        "--drift",
        "--reference",
        s(&f.train_ds),
        "--drift-min-samples",
        "100000000",
    ]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "eval --drift with nothing checked succeeded: {e}"
    );
    assert!(
        e.contains("nothing was checked") && e.contains("scv: nothing checked"),
        "{e}"
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("verdict unchecked"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}
