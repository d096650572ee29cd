//! `frictl train` end to end on a small simulated dataset: `frictl acquire` (tiny protocol) →
//! `frictl preprocess` → `frictl fit scv --json` → `frictl train` (tiny network, few epochs).
//!
//! Checks that the written `.fwt` loads in the daemon's loader (`PinnEstimator::from_model_file`) and,
//! fed sample by sample through its `History` (reset at each chunk start, as the daemon at enable),
//! reproduces the trainer's batched predictions (`Predictor`) on the test split to 1e-5; that its
//! metadata match the dataset sidecar, the fit and the report; that the same seed gives the same
//! bytes; that `--resume` equals an uninterrupted run; and that bad inputs give errors naming the
//! file, key or value.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use crate::util::{EPOCH, err_text, frictl, ok, s, small_acquire_args};
use frictionless::features::{FeatureSet, FeatureSpec, JointSample, WarmupPolicy};
use frictionless::model::{FrictionModel, PinnEstimator};
use frictionless::weights::read_file;
use frictionless_dataset::Dataset;
use frictionless_train::Predictor;
use frictionless_train::data::{DeltaThetaOffset, build_inputs};
use sha2::{Digest, Sha256};

/// The shared fixture: a preprocessed ankle-roll dataset (6 chunks) and its SCV fit.
struct Fixture {
    dir: PathBuf,
    ds: PathBuf,
    scv: PathBuf,
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = crate::util::scratch("frictl-train-cli");
        std::fs::create_dir_all(&dir).unwrap();
        ok(
            frictl(&small_acquire_args(
                "ankle_roll",
                "1",
                &dir,
                "run",
                &["protocol.sines.amplitude_to_a=0.4"],
            )),
            "acquire",
        );
        let ds = dir.join("ds.csv");
        ok(
            frictl(&[
                "preprocess",
                s(&dir.join("run.csv")),
                "--out",
                s(&ds),
                "--link-from-sidecar",
            ]),
            "preprocess",
        );
        let scv = dir.join("scv.json");
        ok(
            frictl(&["fit", "scv", s(&ds), "--json", s(&scv)]),
            "fit scv",
        );
        Fixture { dir, ds, scv }
    })
}

/// `frictl train` with a tiny network; an option in `extra` replaces the default of this helper.
fn train(out: &Path, extra: &[&str]) -> Output {
    let f = fixture();
    let defaults: [(&str, &str); 9] = [
        ("--dataset", s(&f.ds)),
        ("--scv", s(&f.scv)),
        ("--out", s(out)),
        ("--history", "5"),
        ("--hidden", "16,12"),
        ("--batch", "1024"),
        ("--lr", "3e-3"),
        ("--threads", "2"),
        ("--epochs", "3"),
    ];
    let mut args = vec!["train", "--quiet"];
    for (k, v) in defaults {
        if !extra.contains(&k) {
            args.extend_from_slice(&[k, v]);
        }
    }
    args.extend_from_slice(extra);
    frictl(&args)
}

#[test]
fn model_loads_in_the_daemon_loader_and_reproduces_the_trainer_on_the_test_split() {
    let f = fixture();
    let out = f.dir.join("main.fwt");
    ok(train(&out, &["--seed", "2"]), "train");
    let file = read_file(&out).expect("the .fwt reads back");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.with_extension("train.json")).unwrap())
            .unwrap();

    // Metadata against the inputs it came from.
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(f.ds.with_extension("json")).unwrap())
            .unwrap();
    let fit: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&f.scv).unwrap()).unwrap();
    let m = &file.meta;
    assert_eq!(m.joint_name, side["joint"].as_str().unwrap());
    assert_eq!(
        m.gear_ratio.get(),
        side["gear_ratio_signed"].as_f64().unwrap()
    );
    assert_eq!(m.kt_nm_per_a, side["kt_nm_per_a"].as_f64().unwrap());
    let spec = FeatureSpec {
        set: FeatureSet::DeltaThetaJointVel,
        history: 5,
        temperature: false,
    };
    assert_eq!(m.features, spec);
    let scv = m.scv.expect("SCV prior stored");
    for (name, v) in [
        ("kc", scv.kc),
        ("ka", scv.ka),
        ("kv", scv.kv),
        ("ks", scv.ks),
    ] {
        assert_eq!(v, fit["params"][name].as_f64().unwrap(), "scv.{name}");
    }
    let sha: [u8; 32] = Sha256::digest(std::fs::read(&f.ds).unwrap()).into();
    assert_eq!(m.training.dataset_sha256, sha);
    assert_eq!(m.training.created_unix_s, EPOCH.parse::<u64>().unwrap());
    assert_eq!(file.mlp.sizes(), vec![10, 16, 12, 1]);

    // The test split: chunks from the report, samples from build_inputs.
    let ds = Dataset::read_csv(&f.ds).unwrap();
    let test_chunks: Vec<u32> = report["split"]["test"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k["chunk"].as_u64().unwrap() as u32)
        .collect();
    assert!(!test_chunks.is_empty(), "a test split exists");
    let w = build_inputs(
        &ds,
        &spec,
        m.gear_ratio,
        WarmupPolicy::HoldZero,
        DeltaThetaOffset::Run,
    )
    .unwrap();
    let idx: Vec<usize> = (0..w.len())
        .filter(|&i| test_chunks.contains(&w.chunk[i]))
        .collect();
    assert_eq!(
        idx.len() as u64,
        report["split"]["test_samples"].as_u64().unwrap()
    );
    let x: Vec<f32> = idx.iter().flat_map(|&i| w.input(i).to_vec()).collect();
    let batched = Predictor::new(&file.mlp, 2).unwrap().predict(&x).unwrap();

    // The stored input range is the one of the training split's rows (not validation or test).
    let train_chunks: Vec<u32> = report["split"]["train"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k["chunk"].as_u64().unwrap() as u32)
        .collect();
    let train_rows = (0..w.len())
        .filter(|&i| train_chunks.contains(&w.chunk[i]))
        .map(|i| w.input(i));
    let want = frictionless::weights::InputRange::from_rows(&spec, train_rows).unwrap();
    assert_eq!(m.training.input_range, Some(want));

    // The daemon's path: one estimator, enabled (reset) at each chunk start with the Δθ offset the
    // report lists for the dataset (a daemon configured with `delta_theta_offset_motor_rad`), one
    // estimate per row. `reset` latches θ_off = θ − r·s of the sample it is given.
    assert_eq!(report["delta_theta_offset"], "run");
    let off = report["datasets"][0]["delta_theta_offset_motor_rad"]
        .as_f64()
        .expect("the run offset is reported");
    assert!(
        (off - (ds.theta_motor_rad[0] - m.gear_ratio.get() * ds.s_rad[0])).abs() < 1e-12,
        "reported offset {off} is θ₀ − r·s₀ of the first row"
    );
    let mut est = PinnEstimator::from_model_file(&file, WarmupPolicy::HoldZero).unwrap();
    let online: Vec<f64> = (0..ds.len())
        .map(|k| {
            let smp = ds.joint_sample(k);
            if k == 0 || ds.chunk[k] != ds.chunk[k - 1] {
                est.reset(&JointSample {
                    s_rad: 0.0,
                    theta_motor_rad: off,
                    ..smp
                });
            }
            est.estimate(&smp)
        })
        .collect();
    let mut worst = 0f64;
    let (mut sq, mut n) = (0f64, 0usize);
    for (j, &i) in idx.iter().enumerate() {
        let row = w.rows[i];
        let d = (online[row] - batched[j] as f64).abs();
        worst = worst.max(d);
        sq += (batched[j] as f64 - ds.tau_f_label_nm[row]).powi(2);
        n += 1;
    }
    assert!(
        worst <= 1e-5,
        "daemon path vs trainer differ by {worst} Nm on the test split"
    );
    // The stored test RMSE is the one of these predictions.
    let test_rmse = (sq / n as f64).sqrt();
    let stored = m.training.test_rmse_nm as f64;
    assert!(
        (stored - test_rmse).abs() <= 1e-4 * test_rmse.max(1.0),
        "stored test RMSE {stored}, recomputed {test_rmse}"
    );
    assert!(m.training.val_rmse_nm.is_finite());
    let epochs = report["epochs"].as_array().unwrap();
    assert_eq!(epochs.len(), 3);
    assert!(
        epochs
            .iter()
            .all(|e| e["train_loss"].as_f64().unwrap() > 0.0)
    );
}

#[test]
fn same_seed_gives_identical_bytes_and_another_seed_does_not() {
    let f = fixture();
    let (a, b, c) = (
        f.dir.join("seed_a.fwt"),
        f.dir.join("seed_b.fwt"),
        f.dir.join("seed_c.fwt"),
    );
    ok(train(&a, &["--seed", "7"]), "train a");
    ok(train(&b, &["--seed", "7"]), "train b");
    ok(train(&c, &["--seed", "8"]), "train c");
    let (ba, bb, bc) = (
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        std::fs::read(&c).unwrap(),
    );
    assert!(ba == bb, "same seed, same bytes");
    assert!(ba != bc, "another seed, another model");
}

#[test]
fn resume_equals_an_uninterrupted_run() {
    let f = fixture();
    let full = f.dir.join("full.fwt");
    ok(
        train(&full, &["--seed", "3", "--epochs", "4", "--dtype", "f16"]),
        "uninterrupted",
    );
    let ckpt = f.dir.join("half.ckpt");
    let resumed = f.dir.join("resumed.fwt");
    let c = s(&ckpt);
    ok(
        train(
            &resumed,
            &[
                "--seed",
                "3",
                "--epochs",
                "2",
                "--dtype",
                "f16",
                "--checkpoint",
                c,
            ],
        ),
        "first half",
    );
    ok(
        train(
            &resumed,
            &[
                "--seed",
                "3",
                "--epochs",
                "4",
                "--dtype",
                "f16",
                "--checkpoint",
                c,
                "--resume",
            ],
        ),
        "resume",
    );
    let (a, b) = (
        std::fs::read(&full).unwrap(),
        std::fs::read(&resumed).unwrap(),
    );
    assert!(a == b, "resumed run = uninterrupted run, byte for byte");
    let read = |p: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p.with_extension("train.json")).unwrap())
            .unwrap()
    };
    let (rf, rr) = (read(&full), read(&resumed));
    let losses = |r: &serde_json::Value| -> Vec<(f64, f64)> {
        r["epochs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| {
                (
                    e["train_loss"].as_f64().unwrap(),
                    e["val_loss"].as_f64().unwrap(),
                )
            })
            .collect()
    };
    assert_eq!(losses(&rr).len(), 4, "the resumed run has all 4 epochs");
    assert_eq!(losses(&rf), losses(&rr), "identical per-epoch losses");
    assert_eq!(rr["resumed"], true);
    assert_eq!(rf["resumed"], false);
    // Resuming with other hyper-parameters is refused, naming the key and both values.
    let e = err_text(
        train(
            &f.dir.join("x.fwt"),
            &[
                "--seed",
                "3",
                "--epochs",
                "6",
                "--lr",
                "1e-3",
                "--checkpoint",
                c,
                "--resume",
            ],
        ),
        "resume with another lr",
    );
    assert!(
        e.contains("--lr") && e.contains("0.003") && e.contains("0.001"),
        "{e}"
    );
}

#[test]
fn bad_inputs_give_errors_naming_file_key_and_value() {
    let f = fixture();
    let out = f.dir.join("bad.fwt");

    // A dataset without the sdot_rad_s column.
    let text = std::fs::read_to_string(&f.ds).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let drop = header.iter().position(|h| *h == "sdot_rad_s").unwrap();
    let stripped: String = text
        .lines()
        .map(|l| {
            let mut v: Vec<&str> = l.split(',').collect();
            v.remove(drop);
            v.join(",") + "\n"
        })
        .collect();
    let bad_ds = f.dir.join("nosdot.csv");
    std::fs::write(&bad_ds, stripped).unwrap();
    std::fs::copy(f.ds.with_extension("json"), bad_ds.with_extension("json")).unwrap();
    let e = err_text(
        frictl(&[
            "train",
            "--dataset",
            s(&bad_ds),
            "--scv",
            s(&f.scv),
            "--out",
            s(&out),
            "--quiet",
        ]),
        "missing column",
    );
    assert!(e.contains("nosdot.csv") && e.contains("sdot_rad_s"), "{e}");

    // A missing sidecar.
    let lone = f.dir.join("lone.csv");
    std::fs::copy(&f.ds, &lone).unwrap();
    let e = err_text(train(&out, &["--dataset", s(&lone)]), "missing sidecar");
    assert!(e.contains("lone.json"), "{e}");

    // An SCV JSON of an unknown model.
    let bad_scv = f.dir.join("bad_scv.json");
    std::fs::write(&bad_scv, r#"{"model": "Dahl", "params": {}}"#).unwrap();
    let e = err_text(
        frictl(&[
            "train",
            "--dataset",
            s(&f.ds),
            "--scv",
            s(&bad_scv),
            "--out",
            s(&out),
            "--quiet",
        ]),
        "bad scv",
    );
    assert!(
        e.contains("bad_scv.json") && e.contains("`model`") && e.contains("Dahl"),
        "{e}"
    );

    // Fractions that leave no training chunk (6 chunks: 3 test + 3 validation).
    let e = err_text(
        train(&out, &["--val-frac", "0.5", "--test-frac", "0.5"]),
        "empty split",
    );
    assert!(
        e.contains("--val-frac = 0.5") && e.contains("no training chunk"),
        "{e}"
    );

    // A test chunk that does not exist.
    let e = err_text(train(&out, &["--test-chunks", "2,99"]), "unknown chunk");
    assert!(e.contains("--test-chunks = 0:99"), "{e}");

    // Resuming a checkpoint with another input width (H = 5 → 10 inputs, H = 6 → 12).
    let ckpt = f.dir.join("h5.ckpt");
    ok(
        train(&out, &["--epochs", "1", "--checkpoint", s(&ckpt)]),
        "checkpointed run",
    );
    let e = err_text(
        train(
            &out,
            &[
                "--history",
                "6",
                "--epochs",
                "2",
                "--checkpoint",
                s(&ckpt),
                "--resume",
            ],
        ),
        "n_inputs mismatch",
    );
    assert!(
        e.contains("h5.ckpt") && e.contains("n_inputs") && e.contains("12"),
        "{e}"
    );

    // An H the feature code refuses.
    let e = err_text(train(&out, &["--history", "0"]), "H = 0");
    assert!(e.contains("--history") && e.contains("H = 0"), "{e}");
}

/// A torque-sensed copy of the fixture: no motor encoder, no current, no temperature sensor (NaN in
/// every row), listed in the sidecar's `absent_columns`.
fn torque_sensed_dataset(name: &str) -> PathBuf {
    let f = fixture();
    let mut ds = Dataset::read_csv(&f.ds).unwrap();
    for col in [
        &mut ds.theta_motor_rad,
        &mut ds.omega_motor_rad_s,
        &mut ds.delta_theta_motor_rad,
        &mut ds.i_meas_a,
        &mut ds.i_filt_a,
        &mut ds.temperature_c,
    ] {
        col.fill(f64::NAN);
    }
    let out = f.dir.join(format!("{name}.csv"));
    ds.write_csv(&out).unwrap();
    let mut side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(f.ds.with_extension("json")).unwrap())
            .unwrap();
    side["absent_columns"] = serde_json::json!([
        "theta_motor_rad",
        "omega_motor_rad_s",
        "delta_theta_motor_rad",
        "i_meas_a",
        "i_filt_a",
        "temperature_c"
    ]);
    std::fs::write(out.with_extension("json"), side.to_string()).unwrap();
    out
}

/// `joint-pos-joint-vel` and `joint-vel` train, fit and evaluate end to end on a dataset
/// whose motor-side columns are NaN throughout; a set that reads one of them is refused naming the
/// column and the set; the `.fwt` names its blocks and reproduces the trainer through the daemon's
/// estimator.
#[test]
fn sets_without_motor_encoder_train_on_a_torque_sensed_dataset() {
    let f = fixture();
    let ds_path = torque_sensed_dataset("torque_sensed");
    // The SCV fit reads only ṡ and the label.
    let scv = f.dir.join("torque_sensed_scv.json");
    ok(
        frictl(&["fit", "scv", s(&ds_path), "--json", s(&scv)]),
        "fit scv on NaN motor columns",
    );
    let ds = Dataset::read_csv(&ds_path).unwrap();
    for (set, blocks) in [
        ("joint-pos-joint-vel", vec!["joint-pos", "joint-vel"]),
        ("joint-vel", vec!["joint-vel"]),
    ] {
        let out = f.dir.join(format!("ts_{set}.fwt"));
        ok(
            train(
                &out,
                &[
                    "--dataset",
                    s(&ds_path),
                    "--scv",
                    s(&scv),
                    "--features",
                    set,
                ],
            ),
            set,
        );
        let file = read_file(&out).unwrap();
        let spec = file.meta.features;
        assert_eq!(spec.set.name(), set);
        assert_eq!(spec.n_inputs(), 5 * blocks.len());
        let names: Vec<&str> = spec.set.blocks().iter().map(|b| b.name()).collect();
        assert_eq!(names, blocks);
        assert!(file.meta.training.val_rmse_nm.is_finite());
        let report: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.with_extension("train.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(report["features"]["set"], set);
        assert!(
            report["datasets"][0]["delta_theta_offset_motor_rad"].is_null(),
            "no Δθ block, no offset to configure"
        );
        // Every sample of the daemon's path is finite and equals the trainer's batch inference.
        let w = build_inputs(
            &ds,
            &spec,
            file.meta.gear_ratio,
            WarmupPolicy::HoldZero,
            DeltaThetaOffset::Run,
        )
        .unwrap();
        assert!(w.len() > 100, "{set}: {} samples", w.len());
        assert_eq!(w.skipped_non_finite, 0, "NaN columns the set does not read");
        let batched = Predictor::new(&file.mlp, 2).unwrap().predict(&w.x).unwrap();
        let mut est = PinnEstimator::from_model_file(&file, WarmupPolicy::HoldZero).unwrap();
        let mut worst = 0f64;
        let mut i = 0;
        for k in 0..ds.len() {
            let smp = ds.joint_sample(k);
            if k == 0 || ds.chunk[k] != ds.chunk[k - 1] {
                est.reset(&smp);
            }
            let y = est.estimate(&smp);
            if i < w.len() && w.rows[i] == k {
                assert!(y.is_finite(), "{set} row {k}");
                worst = worst.max((y - batched[i] as f64).abs());
                i += 1;
            }
        }
        assert_eq!(i, w.len());
        assert!(
            worst <= 1e-5,
            "{set}: daemon path vs trainer differ by {worst} Nm"
        );
        // eval runs the PINN on the same dataset (and skips the Δθ hysteresis figure).
        let json = f.dir.join(format!("ts_{set}_eval.json"));
        ok(
            frictl(&[
                "eval",
                "--dataset",
                s(&ds_path),
                "--scv",
                s(&scv),
                "--pinn",
                s(&out),
                "--json",
                s(&json),
            ]),
            "eval",
        );
        let ev: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        assert!(ev.to_string().contains("rmse"), "{ev}");
    }

    // Sets that read a motor-side column, or the temperature, are refused naming column and set.
    let out = f.dir.join("ts_refused.fwt");
    for (extra, column, set) in [
        (
            vec!["--features", "delta-theta-joint-vel"],
            "theta_motor_rad",
            "delta-theta-joint-vel",
        ),
        (
            vec!["--features", "motor-vel-joint-vel"],
            "omega_motor_rad_s",
            "motor-vel-joint-vel",
        ),
        (
            vec!["--features", "joint-vel", "--temperature"],
            "temperature_c",
            "joint-vel",
        ),
    ] {
        let mut args = vec!["--dataset", s(&ds_path), "--scv", s(&scv)];
        args.extend(extra);
        let e = err_text(train(&out, &args), column);
        assert!(
            e.contains(&format!("`{column}`")) && e.contains(&format!("`{set}`")),
            "{e}"
        );
        assert!(e.contains("torque_sensed.csv"), "names the dataset: {e}");
    }
    assert!(!out.exists());
    // eval refuses a PINN that reads a column the dataset lacks.
    let dt = f.dir.join("ts_dt.fwt");
    ok(train(&dt, &[]), "train delta-theta on the full fixture");
    let e = err_text(
        frictl(&["eval", "--dataset", s(&ds_path), "--pinn", s(&dt)]),
        "eval of a delta-theta PINN on a torque-sensed dataset",
    );
    assert!(
        e.contains("`theta_motor_rad`") && e.contains("`delta-theta-joint-vel`"),
        "{e}"
    );
}

#[test]
fn an_unwritable_output_is_named_not_a_hidden_temporary_file() {
    // /proc takes no new files, whoever runs the test (root included).
    let out = Path::new("/proc/frictl_train_cli_model.fwt");
    let e = err_text(train(out, &["--epochs", "1"]), "unwritable model");
    assert!(e.contains(s(out)), "names the user's path: {e}");
    assert!(!e.contains(".tmp"), "no temporary file in the message: {e}");
    let ckpt = Path::new("/proc/frictl_train_cli.ckpt");
    let ok_out = fixture().dir.join("unwritable_ckpt.fwt");
    let e = err_text(
        train(&ok_out, &["--epochs", "1", "--checkpoint", s(ckpt)]),
        "unwritable checkpoint",
    );
    assert!(e.contains(s(ckpt)), "names the user's path: {e}");
    assert!(!e.contains(".tmp"), "no temporary file in the message: {e}");
}

#[test]
fn fit_names_the_csv_line_of_a_non_finite_sample() {
    let f = fixture();
    let dir = f.dir.join("fit_nan");
    std::fs::create_dir_all(&dir).unwrap();
    let ds = dir.join("ds.csv");
    std::fs::copy(f.ds.with_extension("json"), ds.with_extension("json")).unwrap();
    let text = std::fs::read_to_string(&f.ds).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|c| *c == "tau_f_label_nm").unwrap();
    // Line 3001 of the file (the header is line 1): a NaN label on a valid sample.
    const LINE: usize = 3001;
    let out: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i + 1 == LINE {
                let mut v: Vec<&str> = l.split(',').collect();
                v[col] = "NaN";
                v.join(",")
            } else {
                l.to_owned()
            }
        })
        .collect();
    std::fs::write(&ds, out.join("\n") + "\n").unwrap();
    let e = err_text(
        frictl(&["fit", "cv", s(&ds), "--sliding-quadrants", "false"]),
        "NaN label",
    );
    assert!(
        e.contains(&format!("line {LINE}")),
        "names the CSV line: {e}"
    );
    assert!(e.contains(s(&ds)), "names the file: {e}");
}

/// What sits at an output path before a command runs, and whether it is still there, untouched,
/// afterwards.
enum Occupant {
    Device,
    Fifo(PathBuf),
    Symlink { link: PathBuf, target: PathBuf },
}

impl Occupant {
    fn all(dir: &Path, name: &str) -> Vec<Occupant> {
        let fifo = dir.join(format!("{name}.fifo"));
        let _ = std::fs::remove_file(&fifo);
        let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let target = dir.join(format!("{name}.v1"));
        std::fs::write(&target, b"the previous version").unwrap();
        let link = dir.join(format!("{name}.current"));
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(target.file_name().unwrap(), &link).unwrap();
        vec![
            Occupant::Device,
            Occupant::Fifo(fifo),
            Occupant::Symlink { link, target },
        ]
    }

    fn path(&self) -> &Path {
        match self {
            Occupant::Device => Path::new("/dev/null"),
            Occupant::Fifo(p) => p,
            Occupant::Symlink { link, .. } => link,
        }
    }

    /// The words the refusal must hold besides the path.
    fn what(&self) -> &'static str {
        match self {
            Occupant::Device => "character device",
            Occupant::Fifo(_) => "FIFO",
            Occupant::Symlink { .. } => "symbolic link",
        }
    }

    fn assert_untouched(&self, cmd: &str) {
        use std::os::unix::fs::FileTypeExt;
        let t = std::fs::symlink_metadata(self.path()).unwrap().file_type();
        match self {
            Occupant::Device => assert!(t.is_char_device(), "{cmd}: /dev/null was replaced"),
            Occupant::Fifo(p) => assert!(t.is_fifo(), "{cmd}: {} was replaced", p.display()),
            Occupant::Symlink { link, target } => {
                assert!(t.is_symlink(), "{cmd}: {} was replaced", link.display());
                assert_eq!(
                    std::fs::read(target).unwrap(),
                    b"the previous version",
                    "{cmd}: written through the symlink"
                );
            }
        }
    }
}

/// Runs `frictl args…` with a hang detector (a FIFO opened for writing blocks until a reader comes):
/// fails the test after two minutes. Returns the output.
fn frictl_unblocked(args: &[&str]) -> Output {
    use std::io::Read;
    let mut child = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(args)
        .env("SOURCE_DATE_EPOCH", EPOCH)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = stderr.read_to_end(&mut s);
        s
    });
    let t0 = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > std::time::Duration::from_secs(120) {
            child.kill().unwrap();
            let _ = child.wait();
            panic!("frictl {} hung on its output", args.join(" "));
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let mut out = child.wait_with_output().unwrap();
    out.stderr = reader.join().unwrap();
    out
}

#[test]
fn outputs_over_a_device_a_fifo_or_a_symlink_are_refused_and_left_untouched() {
    let f = fixture();
    let dir = f.dir.join("occupied");
    std::fs::create_dir_all(&dir).unwrap();
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/models/stress32_paper_f16_r-160.fwt"
    );
    // (command, its arguments writing to the given output path)
    type ArgsFor<'a> = &'a dyn Fn(&str) -> Vec<String>;
    let commands: [(&str, ArgsFor); 5] = [
        ("convert", &|o| {
            ["convert", model, "-o", o, "--dtype", "f16"]
                .map(String::from)
                .to_vec()
        }),
        ("export onnx", &|o| {
            ["export", "onnx", model, "-o", o]
                .map(String::from)
                .to_vec()
        }),
        ("fit --json", &|o| {
            ["fit", "scv", s(&f.ds), "--json", o]
                .map(String::from)
                .to_vec()
        }),
        ("eval --json", &|o| {
            [
                "eval",
                "--dataset",
                s(&f.ds),
                "--scv",
                s(&f.scv),
                "--json",
                o,
            ]
            .map(String::from)
            .to_vec()
        }),
        ("train --out", &|o| {
            let mut a: Vec<String> = [
                "train",
                "--quiet",
                "--dataset",
                s(&f.ds),
                "--scv",
                s(&f.scv),
            ]
            .map(String::from)
            .to_vec();
            a.extend(
                [
                    "--out",
                    o,
                    "--history",
                    "5",
                    "--hidden",
                    "8",
                    "--epochs",
                    "1",
                    "--threads",
                    "2",
                ]
                .map(String::from),
            );
            a
        }),
    ];
    for (i, (name, args)) in commands.iter().enumerate() {
        for occ in Occupant::all(&dir, &format!("out{i}")) {
            let p = s(occ.path());
            let a = args(p);
            let a: Vec<&str> = a.iter().map(String::as_str).collect();
            let out = frictl_unblocked(&a);
            let e = String::from_utf8_lossy(&out.stderr);
            assert!(!out.status.success(), "{name} -o {p}: succeeded: {e}");
            assert!(
                e.contains(p) && e.contains(occ.what()),
                "{name} -o {p}: the error names neither the path nor what it is: {e}"
            );
            occ.assert_untouched(name);
        }
    }
    // No temporary file left behind by a refusal.
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
}

/// A copy of the fixture's dataset (and sidecar) with every row marked invalid.
fn all_invalid_dataset(name: &str) -> PathBuf {
    let f = fixture();
    let out = f.dir.join(format!("{name}.csv"));
    std::fs::copy(f.ds.with_extension("json"), out.with_extension("json")).unwrap();
    let text = std::fs::read_to_string(&f.ds).unwrap();
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
fn zero_epochs_and_zero_valid_rows_are_refused_for_what_they_are() {
    let f = fixture();
    let out = f.dir.join("zero_epochs.fwt");
    let e = err_text(train(&out, &["--epochs", "0"]), "--epochs 0");
    assert!(e.contains("--epochs 0") && e.contains("at least 1"), "{e}");
    assert!(!out.exists(), "an untrained network was written");

    let ds = all_invalid_dataset("invalid_train");
    let out = f.dir.join("zero_valid.fwt");
    let e = err_text(
        train(&out, &["--dataset", s(&ds), "--epochs", "1"]),
        "train on 0 valid rows",
    );
    assert!(
        e.contains("0 valid rows") && e.contains(s(&ds)) && !e.contains("--val-frac"),
        "{e}"
    );
    assert!(!out.exists());
}

#[test]
fn convert_refuses_a_dataset_of_another_gear_ratio_or_without_rows() {
    let f = fixture();
    // The ankle roll dataset has r = -160; this model was trained for r = -100.
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/models/stress32_paper_f16_r-100.fwt"
    );
    let out = f.dir.join("converted.fwt");
    let e = err_text(
        frictl(&[
            "convert",
            model,
            "-o",
            s(&out),
            "--dtype",
            "f16",
            "--dataset",
            s(&f.ds),
        ]),
        "convert --dataset of another gear ratio",
    );
    assert!(
        e.contains("gear ratio -100")
            && e.contains("gear_ratio_signed = -160")
            && e.contains(s(&f.ds)),
        "{e}"
    );
    assert!(!out.exists());
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/models/stress32_paper_f16_r-160.fwt"
    );
    let ds = all_invalid_dataset("invalid_convert");
    let e = err_text(
        frictl(&[
            "convert",
            model,
            "-o",
            s(&out),
            "--dtype",
            "f16",
            "--dataset",
            s(&ds),
        ]),
        "convert --dataset without valid rows",
    );
    assert!(
        e.contains("contributes 0 input rows") && e.contains(s(&ds)),
        "{e}"
    );
    assert!(!out.exists());
}

/// `frictl distill`: a student of a trained teacher passes the held-out accuracy gate, keeps the
/// teacher's inputs, normalisation and metadata, records the teacher's SHA-256 and is smaller; a
/// student forced too small (one unit, one epoch) fails the gate, says so with the numbers and writes
/// nothing.
#[test]
fn distill_gates_on_held_out_data_inherits_meta_and_records_the_teacher() {
    let f = fixture();
    let teacher_path = f.dir.join("teacher.fwt");
    ok(
        train(
            &teacher_path,
            &["--hidden", "32,32", "--epochs", "6", "--seed", "3"],
        ),
        "train teacher",
    );
    let teacher = read_file(&teacher_path).unwrap();
    let student_path = f.dir.join("student.fwt");
    let distill_from = |teacher: &Path, out: &Path, extra: &[&str]| -> Output {
        let mut args = vec![
            "distill",
            s(teacher),
            "--dataset",
            s(&f.ds),
            "-o",
            s(out),
            "--threads",
            "2",
            "--quiet",
        ];
        args.extend_from_slice(extra);
        frictl(&args)
    };
    let distill = |out: &Path, extra: &[&str]| distill_from(&teacher_path, out, extra);
    let out = ok(
        distill(
            &student_path,
            &[
                "--hidden", "16,16", "--epochs", "30", "--batch", "256", "--lr", "3e-3",
            ],
        ),
        "distill",
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(text.contains("all") && text.contains("ok"), "{text}");
    let notice = "no training report of the teacher";
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains(notice),
        "the report next to the teacher is found"
    );
    let student = read_file(&student_path).unwrap();
    let (tm, sm) = (&teacher.meta, &student.meta);
    assert_eq!(sm.features, tm.features);
    assert_eq!(sm.joint_name, tm.joint_name);
    assert_eq!(sm.gear_ratio, tm.gear_ratio);
    assert_eq!(sm.kt_nm_per_a, tm.kt_nm_per_a);
    assert_eq!(sm.scv, tm.scv);
    assert_eq!(sm.training.filtering, tm.training.filtering);
    assert_eq!(sm.training.input_range, tm.training.input_range);
    assert_eq!(sm.training.dataset_sha256, tm.training.dataset_sha256);
    assert_eq!(student.mlp.norm, teacher.mlp.norm);
    let sizes: Vec<usize> = student.mlp.layers.iter().map(|l| l.n_out).collect();
    assert_eq!(sizes, [16, 16, 1]);
    let teacher_sha: [u8; 32] = Sha256::digest(std::fs::read(&teacher_path).unwrap()).into();
    assert_eq!(sm.training.teacher_sha256, Some(teacher_sha));
    assert_eq!(tm.training.teacher_sha256, None);
    // The gate's test RMSE is stored, and it is within 1.05× the teacher's (same held-out chunks:
    // the split of the teacher's report).
    let (st, tt) = (sm.training.test_rmse_nm, tm.training.test_rmse_nm);
    assert!(
        st.is_finite() && st <= 1.05 * tt + 1e-6,
        "student {st} teacher {tt}"
    );
    let shown =
        String::from_utf8_lossy(&ok(frictl(&["inspect", s(&student_path)]), "inspect").stdout)
            .into_owned();
    assert!(
        shown.contains(
            &teacher_sha
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect::<String>()
        ),
        "{shown}"
    );

    let tiny = f.dir.join("tiny.fwt");
    let e = err_text(
        distill(&tiny, &["--hidden", "1", "--epochs", "1"]),
        "distill into one unit",
    );
    assert!(
        e.contains("not within 1.05") && e.contains("not written"),
        "{e}"
    );
    assert!(!tiny.exists(), "a failed student must not be written");

    // A student with a shorter history reads the newest samples of each of the teacher's blocks,
    // with the teacher's normalisation of those inputs (the gate is opened wide: this checks the
    // plumbing, not the accuracy).
    let h = tm.features.history;
    assert!(h >= 3, "the fixture's teacher has H {h}");
    let short = f.dir.join("short.fwt");
    ok(
        distill(
            &short,
            &[
                "--hidden",
                "8",
                "--epochs",
                "2",
                "--history",
                "2",
                "--max-rmse-ratio",
                "1000",
            ],
        ),
        "distill --history 2",
    );
    let short = read_file(&short).unwrap();
    assert_eq!(short.meta.features.history, 2);
    assert_eq!(short.meta.features.set, tm.features.set);
    let n_blocks = tm.features.set.n_blocks();
    assert_eq!(
        short.mlp.n_inputs(),
        2 * n_blocks + usize::from(tm.features.temperature)
    );
    for b in 0..n_blocks {
        for k in 0..2 {
            let (si, ti) = (b * 2 + k, b * h + h - 2 + k);
            assert_eq!(
                short.mlp.norm.mean[si], teacher.mlp.norm.mean[ti],
                "block {b}"
            );
            assert_eq!(
                short.mlp.norm.scale[si], teacher.mlp.norm.scale[ti],
                "block {b}"
            );
        }
    }
    for bad in ["0", &(h + 1).to_string()] {
        let out = f.dir.join(format!("bad_history_{bad}.fwt"));
        let e = err_text(
            distill(&out, &["--hidden", "8", "--epochs", "1", "--history", bad]),
            "distill --history out of range",
        );
        assert!(e.contains(&format!("--history {bad}")), "{e}");
        assert!(!out.exists());
    }

    // A teacher without its training report: distill says which Δθ latch and warm-up it assumes.
    let lone_dir = f.dir.join("lone");
    std::fs::create_dir_all(&lone_dir).unwrap();
    let lone = lone_dir.join("teacher.fwt");
    std::fs::copy(&teacher_path, &lone).unwrap();
    let lone_out = distill_from(
        &lone,
        &lone_dir.join("student.fwt"),
        &["--hidden", "1", "--epochs", "1"],
    );
    let e = String::from_utf8_lossy(&lone_out.stderr).into_owned();
    assert!(
        e.contains(notice)
            && e.contains("lone/teacher.train.json")
            && e.contains("--teacher-report"),
        "{e}"
    );
}

/// `frictl distill --probes-only`: without any dataset, a student learns the teacher inside its
/// stored input range and is written only when its output RMSE against the teacher on the gate
/// probes is within `--max-rmse-nm`; the written student's stored test RMSE is that gate figure, and
/// an independent draw of inputs inside the range (made here, on the kernel frictiond runs) agrees
/// with it. A student that cannot fit (one unit, one epoch) fails the gate and writes nothing;
/// `--dataset` with `--probes-only` is refused.
#[test]
fn distill_probes_only_gates_on_the_teacher_inside_its_input_range() {
    let f = fixture();
    let teacher_path = f.dir.join("probe_teacher.fwt");
    ok(
        train(
            &teacher_path,
            &["--hidden", "32,32", "--epochs", "4", "--seed", "5"],
        ),
        "train teacher",
    );
    let teacher = read_file(&teacher_path).unwrap();
    let range = teacher
        .meta
        .training
        .input_range
        .expect("train stores the input range");
    let distill = |out: &Path, extra: &[&str]| -> Output {
        let mut args = vec![
            "distill",
            s(&teacher_path),
            "-o",
            s(out),
            "--threads",
            "2",
            "--quiet",
        ];
        args.extend_from_slice(extra);
        frictl(&args)
    };
    let student_path = f.dir.join("probe_student.fwt");
    let bound_nm = 0.3f32;
    let out = ok(
        distill(
            &student_path,
            &[
                "--probes-only",
                "8000",
                "--hidden",
                "16,16",
                "--epochs",
                "60",
                "--batch",
                "256",
                "--lr",
                "3e-3",
                "--max-rmse-nm",
                &bound_nm.to_string(),
            ],
        ),
        "distill --probes-only",
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        text.contains("RMSE vs teacher") && text.contains(": ok"),
        "{text}"
    );
    let student = read_file(&student_path).unwrap();
    let sm = &student.meta;
    assert_eq!(sm.features, teacher.meta.features);
    assert_eq!(student.mlp.norm, teacher.mlp.norm);
    assert_eq!(sm.training.input_range, teacher.meta.training.input_range);
    let teacher_sha: [u8; 32] = Sha256::digest(std::fs::read(&teacher_path).unwrap()).into();
    assert_eq!(sm.training.teacher_sha256, Some(teacher_sha));
    let gate_rmse = sm.training.test_rmse_nm;
    assert!(gate_rmse <= bound_nm, "stored gate RMSE {gate_rmse}");
    // An independent draw inside the stored range, on the kernel.
    let spec = teacher.meta.features;
    let (h, n) = (spec.history, spec.n_inputs());
    let mut state = 0x1234_5678_9abc_def0u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut tk = frictionless::kernel::Mlp::new(&teacher.mlp, teacher.dtype).unwrap();
    let mut sk = frictionless::kernel::Mlp::new(&student.mlp, student.dtype).unwrap();
    let (mut sq, mut var_t, mut mean_t, count) = (0f64, 0f64, 0f64, 4000);
    let mut ys = Vec::with_capacity(count);
    for _ in 0..count {
        let x: Vec<f32> = (0..n)
            .map(|i| {
                let [lo, hi] = if i < spec.set.n_blocks() * h {
                    range.blocks[i / h]
                } else {
                    range.temperature
                };
                lo + (hi - lo) * uniform()
            })
            .collect();
        let (t, st) = (tk.forward(&x), sk.forward(&x));
        sq += f64::from(t - st).powi(2);
        ys.push(f64::from(t));
    }
    for y in &ys {
        mean_t += y / count as f64;
    }
    for y in &ys {
        var_t += (y - mean_t).powi(2) / count as f64;
    }
    let rmse = (sq / count as f64).sqrt();
    assert!(
        rmse <= 1.3 * f64::from(gate_rmse),
        "independent RMSE vs teacher {rmse} Nm (gate {gate_rmse} Nm)"
    );
    assert!(
        var_t.sqrt() > 10.0 * rmse,
        "the teacher varies ({} Nm std) far more than the student's error ({rmse} Nm)",
        var_t.sqrt()
    );

    // Trajectory probes: the gate says how its probes were drawn and reports the uniform figure
    // beside it, ungated.
    let traj_path = f.dir.join("probe_traj.fwt");
    let out = ok(
        distill(
            &traj_path,
            &[
                "--probes-only",
                "4000",
                "--probe-kind",
                "trajectory",
                "--hidden",
                "16,16",
                "--epochs",
                "30",
                "--batch",
                "256",
                "--lr",
                "3e-3",
                "--max-rmse-nm",
                &bound_nm.to_string(),
            ],
        ),
        "distill --probes-only --probe-kind trajectory",
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        text.contains("trajectory probes") && text.contains("on uniform probes:"),
        "{text}"
    );

    let tiny = f.dir.join("probe_tiny.fwt");
    let e = err_text(
        distill(
            &tiny,
            &[
                "--probes-only",
                "2000",
                "--hidden",
                "1",
                "--epochs",
                "1",
                "--max-rmse-nm",
                "1e-5",
            ],
        ),
        "distill --probes-only into one unit",
    );
    assert!(
        e.contains("not within 0.00001 Nm RMS") && e.contains("not written"),
        "{e}"
    );
    assert!(!tiny.exists(), "a failed student must not be written");
    let e = err_text(
        distill(&tiny, &["--probes-only", "100", "--dataset", s(&f.ds)]),
        "--probes-only with --dataset",
    );
    assert!(
        e.contains("--dataset") && e.contains("--probes-only"),
        "{e}"
    );
    assert!(!tiny.exists());
}

/// `--init prune`: the student starts as the teacher narrowed (its strongest units, the layers after
/// them refitted to the teacher), so at the teacher's own widths it starts at the teacher; a depth or
/// width the teacher does not have is refused before training, naming both.
#[test]
fn distill_init_prune_starts_from_the_teacher_and_refuses_other_shapes() {
    let f = fixture();
    let teacher_path = f.dir.join("prune_teacher.fwt");
    let trained = train(
        &teacher_path,
        &["--hidden", "24,16", "--epochs", "3", "--seed", "8"],
    );
    ok(trained, "train teacher");
    let distill = |out: &Path, extra: &[&str]| -> Output {
        let fixed = [
            "--threads=2",
            "--quiet",
            "--probes-only=6000",
            "--init=prune",
        ];
        let head = ["distill", s(&teacher_path), "-o", s(out)];
        frictl(&[&head[..], &fixed, extra].concat())
    };
    let start_of = |text: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.starts_with("pruned start"))
            .unwrap_or_else(|| panic!("no pruned-start line in {text}"));
        let after = line.split("RMSE vs teacher ").nth(1).unwrap();
        after.split_whitespace().next().unwrap().parse().unwrap()
    };
    // Every unit kept: the refits reproduce the teacher; a tiny learning rate keeps it there.
    let full = f.dir.join("prune_full.fwt");
    let out = ok(
        distill(
            &full,
            &[
                "--hidden",
                "24,16",
                "--epochs",
                "1",
                "--lr",
                "1e-7",
                "--max-rmse-nm",
                "1e-3",
            ],
        ),
        "distill --init prune at the teacher's widths",
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(start_of(&text) < 1e-3, "{text}");
    assert!(full.exists());
    // Narrower: a start much closer to the teacher than its spread.
    let narrow = f.dir.join("prune_narrow.fwt");
    let out = ok(
        distill(
            &narrow,
            &[
                "--hidden",
                "12,8",
                "--epochs",
                "1",
                "--lr",
                "1e-7",
                "--max-rmse-nm",
                "100",
            ],
        ),
        "distill --init prune into narrower layers",
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let start = start_of(&text);
    let std: f64 = text
        .split("teacher output std ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no teacher std in {text}"));
    assert!(
        start < 0.5 * std,
        "pruned start {start} Nm, teacher std {std} Nm"
    );

    for (hidden, what) in [("24,16,8", "deeper"), ("32,16", "wider")] {
        let bad = f.dir.join(format!("prune_{what}.fwt"));
        let e = err_text(
            distill(&bad, &["--hidden", hidden, "--epochs", "1"]),
            "distill --init prune into another shape",
        );
        assert!(
            e.contains("--init prune") && e.contains("[24, 16]"),
            "{what}: {e}"
        );
        assert!(!bad.exists());
    }
}

/// Outputs that are inputs (the teacher's report included), data given twice and counts that cannot
/// be allocated are refused before any work, naming the flag, and leave every file as it was.
#[test]
fn outputs_over_inputs_repeated_data_and_huge_counts_are_refused_before_any_work() {
    let f = fixture();
    let dir = f.dir.join("refusals");
    std::fs::create_dir_all(&dir).unwrap();
    let teacher = dir.join("teacher.fwt");
    ok(
        train(&teacher, &["--hidden", "8,8", "--epochs", "1"]),
        "train teacher",
    );
    let report = dir.join("teacher.train.json");
    let report_bytes = std::fs::read(&report).unwrap();
    let refused = |args: &[&str], says: &[&str]| {
        let r = frictl(args);
        let err = String::from_utf8_lossy(&r.stderr).into_owned();
        // Exit 1 or 2 (an error, not an abort by signal).
        assert!(
            matches!(r.status.code(), Some(1 | 2)),
            "frictl {args:?}: {:?}\n{err}",
            r.status
        );
        for s in says {
            assert!(err.contains(s), "frictl {args:?}: no `{s}` in\n{err}");
        }
    };
    // D1: the teacher's training report, read by default or named, is never the student (before:
    // overwritten with the .fwt, exit 0).
    let distill = ["distill", s(&teacher), "--threads", "1", "--epochs", "1"];
    refused(
        &[&distill[..], &["--dataset", s(&f.ds), "-o", s(&report)]].concat(),
        &["is also an input", "teacher.train.json"],
    );
    let copy = dir.join("copy.train.json");
    std::fs::copy(&report, &copy).unwrap();
    refused(
        &[
            &distill[..],
            &[
                "--dataset",
                s(&f.ds),
                "--teacher-report",
                s(&copy),
                "-o",
                s(&copy),
            ],
        ]
        .concat(),
        &["is also an input"],
    );
    refused(
        &[&distill[..], &["--probes-only", "100", "-o", s(&report)]].concat(),
        &["is also an input"],
    );
    assert_eq!(std::fs::read(&report).unwrap(), report_bytes, "report kept");
    // Two outputs of one command on one file.
    let same = dir.join("same.fwt");
    refused(
        &[
            "train",
            "--dataset",
            s(&f.ds),
            "--scv",
            s(&f.scv),
            "--out",
            s(&same),
            "--report",
            s(&same),
        ],
        &["another output"],
    );
    // D2: counts sizing an allocation are bounded (before: aborted on a 2.4e15-byte allocation).
    let student = dir.join("student.fwt");
    refused(
        &[&distill[..], &["--probes-only", "1e14", "-o", s(&student)]].concat(),
        &["--probes-only", "bound"],
    );
    refused(
        &[
            &distill[..],
            &["--dataset", s(&f.ds), "--probes", "1e14", "-o", s(&student)],
        ]
        .concat(),
        &["--probes", "bound"],
    );
    refused(
        &[
            "convert",
            s(&teacher),
            "-o",
            s(&student),
            "--dtype",
            "f16",
            "--samples",
            "1e14",
        ],
        &["--samples", "bound"],
    );
    assert!(!student.exists());
    // D3: one dataset twice, as training and test data or as two training sets, by path or as a copy
    // (before: accepted; the held-out gate ran on training rows).
    let ds_copy = dir.join("ds_copy.csv");
    std::fs::copy(&f.ds, &ds_copy).unwrap();
    std::fs::copy(f.ds.with_extension("json"), ds_copy.with_extension("json")).unwrap();
    let model = dir.join("m.fwt");
    let base = [
        "train",
        "--scv",
        s(&f.scv),
        "--out",
        s(&model),
        "--dataset",
        s(&f.ds),
    ];
    refused(
        &[&base[..], &["--test-dataset", s(&f.ds)]].concat(),
        &["--test-dataset", "same data as --dataset", "training rows"],
    );
    refused(
        &[&base[..], &["--dataset", s(&f.ds)]].concat(),
        &["same data as --dataset", "twice"],
    );
    refused(
        &[&base[..], &["--test-dataset", s(&ds_copy)]].concat(),
        &["ds_copy.csv", "same data as --dataset"],
    );
    refused(
        &[
            &distill[..],
            &[
                "--dataset",
                s(&f.ds),
                "--test-dataset",
                s(&f.ds),
                "-o",
                s(&student),
            ],
        ]
        .concat(),
        &["same data as --dataset"],
    );
    assert!(!model.exists() && !student.exists());
}
