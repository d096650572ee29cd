//! One long recording (one chunk, as a robot logger writes it) is a normal input of `frictl train`
//! and `frictl robot run`: validation and test are contiguous time blocks of it, a gap of at least
//! the history between blocks, no window across a block boundary; a `--test-dataset` is the test
//! set as it is (no test block carved out then); a recording too short to cut is refused naming the
//! options to use.

use std::path::{Path, PathBuf};

use crate::util::{err_text, frictl, frictl_ok as ok, s};
use frictionless::features::{FeatureSet, FeatureSpec, MAX_HISTORY, WarmupPolicy};
use frictionless_train::data::{BLOCK_GAP_ROWS, Block, ChunkKey, DeltaThetaOffset, SplitSpec};
use frictionless_train::pipeline;

/// `frictl import csv` of one uninterrupted `seconds`-long 1 kHz log of a joint with a motor encoder
/// (θ = r·s − 0.002·τ_F + `zero`), written as `dir/NAME.csv`.
fn one_recording(dir: &Path, name: &str, seconds: f64, phase: f64) -> PathBuf {
    let log = dir.join(format!("{name}.log.csv"));
    let mut text = String::from("t,q,qd,friction,theta\n");
    let n = (seconds * 1000.0) as usize;
    for k in 0..n {
        let t = k as f64 * 1e-3;
        let w = 2.0 + 0.5 * (0.3 * t + phase).sin();
        let (q, v) = (0.4 * (w * t).sin(), 0.4 * w * (w * t).cos());
        let f = 0.3 * (50.0 * v).tanh() + 0.2 * v;
        text += &format!("{t},{q},{v},{f},{}\n", 100.0 * q - 0.002 * f);
    }
    std::fs::write(&log, text).unwrap();
    let out = dir.join(format!("{name}.csv"));
    ok(&[
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
    ]);
    out
}

/// The arguments of `frictl train` of a small network (`hidden` wide, H = 4, one epoch, quiet) on
/// `ds` with the prior `cv`, writing `model`.
fn small_train<'a>(ds: &'a Path, cv: &'a Path, model: &'a Path, hidden: &'a str) -> Vec<&'a str> {
    vec![
        "train",
        "--dataset",
        s(ds),
        "--scv",
        s(cv),
        "--out",
        s(model),
        "--hidden",
        hidden,
        "--history",
        "4",
        "--epochs",
        "1",
        "--quiet",
    ]
}

fn scratch(name: &str) -> PathBuf {
    let d = crate::util::scratch(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn keys(v: &serde_json::Value) -> Vec<ChunkKey> {
    serde_json::from_value(v.clone()).unwrap()
}

#[test]
fn one_recording_is_cut_into_time_blocks_with_no_window_across_a_boundary() {
    let dir = scratch("frictl-one-recording");
    let ds = one_recording(&dir, "ds", 14.0, 0.0);
    let src = pipeline::load_sources(std::slice::from_ref(&ds)).unwrap();
    assert_eq!(
        pipeline::chunks_with_valid_rows(&src).len(),
        1,
        "the log is one chunk"
    );
    let cv = dir.join("cv.json");
    ok(&["fit", "cv", s(&ds), "--json", s(&cv)]);
    let scv = pipeline::load_scv(&cv).unwrap();
    let spec = SplitSpec {
        val_frac: 0.15,
        test_frac: 0.15,
        seed: 2,
        test_chunks: None,
    };
    let split = pipeline::split_for(&src, &spec).unwrap();
    assert!(split.blocks.len() >= 10, "{} blocks", split.blocks.len());
    let sets = [&split.train, &split.val, &split.test];
    assert!(sets.iter().all(|set| !set.is_empty()), "{split:?}");
    let block_of = |k: &ChunkKey| -> Block { *split.blocks.iter().find(|b| b.key == *k).unwrap() };
    let mut all: Vec<ChunkKey> = sets.iter().flat_map(|s| s.iter().copied()).collect();
    all.sort();
    all.dedup();
    assert_eq!(
        all.len(),
        sets.iter().map(|s| s.len()).sum::<usize>(),
        "disjoint sets"
    );
    for (i, b) in split.blocks.iter().enumerate() {
        assert_eq!(b.chunk, 0);
        if i > 0 {
            assert!(
                b.gap_rows >= MAX_HISTORY,
                "the gap is at least the longest history"
            );
        }
    }
    let h = 30;
    let fs = FeatureSpec {
        set: FeatureSet::DeltaThetaJointVel,
        history: h,
        temperature: false,
    };
    let p = pipeline::prepare(
        &src,
        &scv,
        &split,
        &fs,
        WarmupPolicy::HoldZero,
        DeltaThetaOffset::Run,
    )
    .unwrap();
    for (set, chunks) in [
        (&p.train, &split.train),
        (&p.val, &split.val),
        (&p.test, &split.test),
    ] {
        assert!(!set.is_empty());
        for &(_, row) in &set.rows {
            // The sample's block is one of its set's, it lies after the block's gap, and its whole
            // window (row − H + 1 … row) lies inside the block.
            let b = chunks
                .iter()
                .map(block_of)
                .find(|b| (b.start_row..b.end_row).contains(&row))
                .unwrap_or_else(|| panic!("row {row} outside its set's blocks"));
            assert!(row >= b.start_row + b.gap_rows, "row {row} is in a gap");
            assert!(
                row + 1 >= b.start_row + h,
                "window of row {row} leaves its block"
            );
        }
    }
    // The samples between two blocks of different sets are at least the gap apart.
    let mut by_row: Vec<(usize, usize)> = [&p.train, &p.val, &p.test]
        .iter()
        .enumerate()
        .flat_map(|(i, set)| set.rows.iter().map(move |&(_, r)| (r, i)))
        .collect();
    by_row.sort();
    for w in by_row.windows(2) {
        if w[0].1 != w[1].1 {
            assert!(
                w[1].0 - w[0].0 > BLOCK_GAP_ROWS,
                "rows {} and {} of two sets",
                w[0].0,
                w[1].0
            );
        }
    }

    // The documented command runs on it, with validation, and reports the blocks.
    let model = dir.join("m.fwt");
    ok(&small_train(&ds, &cv, &model, "8"));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("m.train.json")).unwrap()).unwrap();
    assert!(r["split"]["val_samples"].as_u64().unwrap() > 0);
    assert!(r["split"]["test_samples"].as_u64().unwrap() > 0);
    assert!(r["rmse_nm"]["val"].is_number());
    assert!(!r["split"]["blocks"].as_array().unwrap().is_empty());

    // A held-out recording is the test set as it is: no test block is carved out of the first.
    let other = one_recording(&dir, "other", 8.0, 1.0);
    ok(&[
        "train",
        "--dataset",
        s(&ds),
        "--test-dataset",
        s(&other),
        "--scv",
        s(&cv),
        "--out",
        s(&model),
        "--hidden",
        "8",
        "--history",
        "4",
        "--epochs",
        "1",
        "--quiet",
    ]);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("m.train.json")).unwrap()).unwrap();
    let test = keys(&r["split"]["test"]);
    assert!(
        !test.is_empty() && test.iter().all(|k| k.dataset == 1),
        "{test:?}"
    );
    assert!(!keys(&r["split"]["val"]).is_empty());
    assert!(keys(&r["split"]["train"]).iter().all(|k| k.dataset == 0));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_recording_too_short_for_blocks_is_refused_naming_the_options() {
    let dir = scratch("frictl-short-recording");
    let ds = one_recording(&dir, "ds", 1.0, 0.0);
    let cv = dir.join("cv.json");
    ok(&["fit", "cv", s(&ds), "--json", s(&cv)]);
    let model = dir.join("m.fwt");
    let e = err_text(
        frictl(&[
            "train",
            "--dataset",
            s(&ds),
            "--scv",
            s(&cv),
            "--out",
            s(&model),
            "--quiet",
        ]),
        "train on 1 s",
    );
    for want in [
        "no training chunk",
        "--val-frac 0",
        "--test-frac 0",
        "--test-dataset",
    ] {
        assert!(e.contains(want), "{want}: {e}");
    }
    assert!(!model.exists());
    // With both fractions 0 it trains on everything.
    ok(&[
        "train",
        "--dataset",
        s(&ds),
        "--scv",
        s(&cv),
        "--out",
        s(&model),
        "--hidden",
        "8",
        "--history",
        "4",
        "--epochs",
        "1",
        "--val-frac",
        "0",
        "--test-frac",
        "0",
        "--quiet",
    ]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--motor-encoder incremental` latches Δθ at every chunk start (the report lists no offset to
/// configure) and is refused together with `--delta-theta-offset`; `absolute` keeps the recording's
/// offset.
#[test]
fn an_incremental_motor_encoder_trains_latched_per_chunk() {
    let dir = scratch("frictl-train-incremental");
    let ds = one_recording(&dir, "ds", 8.0, 0.0);
    let cv = dir.join("cv.json");
    ok(&["fit", "cv", s(&ds), "--json", s(&cv)]);
    let model = dir.join("m.fwt");
    let base = small_train(&ds, &cv, &model, "8");
    let report = || -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join("m.train.json")).unwrap()).unwrap()
    };
    ok(&[&base[..], &["--motor-encoder", "incremental"]].concat());
    let r = report();
    assert_eq!(r["delta_theta_offset"], "chunk");
    assert!(r["datasets"][0]["delta_theta_offset_motor_rad"].is_null());
    ok(&[&base[..], &["--motor-encoder", "absolute"]].concat());
    let r = report();
    assert_eq!(r["delta_theta_offset"], "run");
    assert!(r["datasets"][0]["delta_theta_offset_motor_rad"].is_number());
    let e = err_text(
        frictl(
            &[
                &base[..],
                &[
                    "--motor-encoder",
                    "incremental",
                    "--delta-theta-offset",
                    "run",
                ],
            ]
            .concat(),
        ),
        "incremental with a latch",
    );
    assert!(
        e.contains("--motor-encoder") && e.contains("--delta-theta-offset"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `frictl config` writes one `[[joint]]` for a PINN (its encoder semantics, the offset its training
/// latched for an absolute encoder, its CV fit as the static fallback) or for a fitted model, in a
/// config frictiond's checker accepts; a model trained with a fixed offset is refused for an
/// incremental encoder, a Δθ model without its report for an absolute one, and a limit frictiond
/// refuses is named as frictiond names it.
#[test]
fn frictl_config_writes_checked_joints_for_pinns_and_fits() {
    let dir = scratch("frictl-config");
    let ds = one_recording(&dir, "ds", 8.0, 0.0);
    let (cv, scv) = (dir.join("cv.json"), dir.join("scv.json"));
    ok(&["fit", "cv", s(&ds), "--json", s(&cv)]);
    ok(&["fit", "scv", s(&ds), "--json", s(&scv)]);
    let train = |model: &Path, extra: &[&str]| {
        let base = small_train(&ds, &cv, model, "8");
        ok(&[&base[..], extra].concat());
    };
    let (abs, inc) = (dir.join("abs.fwt"), dir.join("inc.fwt"));
    train(&abs, &[]);
    train(&inc, &["--motor-encoder", "incremental"]);
    let (abs_r, inc_r) = (dir.join("abs.train.json"), dir.join("inc.train.json"));
    let out = dir.join("frictiond.toml");
    ok(&[
        "config",
        "--pinn",
        s(&abs),
        "--train-report",
        s(&abs_r),
        "--fit",
        s(&cv),
        "--max-curr",
        "3",
        "--kfc",
        "0.8",
        "-o",
        s(&out),
    ]);
    let c = frictiond_config::load(&out).unwrap();
    let j = &c.raw.joint[0];
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&abs_r).unwrap()).unwrap();
    let off = report["datasets"][0]["delta_theta_offset_motor_rad"]
        .as_f64()
        .unwrap();
    assert_eq!(j.name, "r_wrist");
    assert_eq!(
        (j.gear_ratio, j.kt, j.max_curr, j.kfc),
        (100.0, 0.1, 3.0, 0.8)
    );
    assert_eq!(j.friction_model, frictiond_config::ModelKind::Pinn);
    assert_eq!(j.delta_theta_offset_motor_rad, Some(off));
    assert_eq!(j.motor_encoder, frictiond_config::MotorEncoder::Absolute);
    assert_eq!(j.ood, frictiond_config::OodMode::Static);
    let fit = frictionless_dataset::fit_file::FittedModel::read_cv(&cv).unwrap();
    assert_eq!(
        (j.kc, j.ka, j.kv),
        (Some(fit.kc), Some(fit.ka), Some(fit.kv))
    );
    // Incremental: no offset, and only a model trained latched per chunk.
    ok(&[
        "config",
        "--pinn",
        s(&inc),
        "--train-report",
        s(&inc_r),
        "--motor-encoder",
        "incremental",
        "--fit",
        s(&cv),
        "--max-curr",
        "3",
        "-o",
        s(&out),
    ]);
    let j = frictiond_config::load(&out).unwrap().raw.joint[0].clone();
    assert_eq!(j.motor_encoder, frictiond_config::MotorEncoder::Incremental);
    assert_eq!(j.delta_theta_offset_motor_rad, None);
    let before = std::fs::read(&out).unwrap();
    let e = err_text(
        frictl(&[
            "config",
            "--pinn",
            s(&abs),
            "--train-report",
            s(&abs_r),
            "--motor-encoder",
            "incremental",
            "--max-curr",
            "3",
            "-o",
            s(&out),
        ]),
        "a fixed-offset model on an incremental encoder",
    );
    assert!(
        e.contains("--motor-encoder incremental") && e.contains("retrain"),
        "{e}"
    );
    let e = err_text(
        frictl(&[
            "config",
            "--pinn",
            s(&abs),
            "--max-curr",
            "3",
            "-o",
            s(&out),
        ]),
        "a Δθ model without its report",
    );
    assert!(e.contains("--train-report"), "{e}");
    let e = err_text(
        frictl(&[
            "config",
            "--pinn",
            s(&abs),
            "--train-report",
            s(&abs_r),
            "--max-curr=-1",
            "-o",
            s(&out),
        ]),
        "a negative current clamp",
    );
    assert!(e.contains("joint[0].max_curr"), "{e}");
    assert_eq!(
        std::fs::read(&out).unwrap(),
        before,
        "a refused config is not written"
    );
    // A fitted model as the joint's model.
    ok(&[
        "config",
        "--fit",
        s(&scv),
        "--joint",
        "r_wrist",
        "--gear-ratio",
        "100",
        "--kt",
        "0.1",
        "--max-curr",
        "3",
        "-o",
        s(&out),
    ]);
    let j = frictiond_config::load(&out).unwrap().raw.joint[0].clone();
    assert_eq!(j.friction_model, frictiond_config::ModelKind::Scv);
    assert!(j.ks.is_some() && j.vs.is_some() && j.alpha.is_some());
    let e = err_text(
        frictl(&["config", "--fit", s(&scv), "--max-curr", "3", "-o", s(&out)]),
        "a fit without a joint",
    );
    assert!(e.contains("--joint"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A log with the motor angle imported without `--gear-ratio` (Δθ = r·s − θ needs r) is refused
/// naming the flag (it said "`gear_ratio_signed` = NaN is invalid"); without the motor angle r is
/// not needed and a set without Δθ trains on the import.
#[test]
fn a_log_with_a_motor_angle_and_no_gear_ratio_is_refused_naming_the_flag() {
    let dir = scratch("frictl-no-gear-ratio");
    let log = dir.join("log.csv");
    let mut text = String::from("t,q,qd,friction,theta\n");
    for k in 0..3000 {
        let t = k as f64 * 1e-3;
        let (q, v) = (0.4 * (2.0 * t).sin(), 0.8 * (2.0 * t).cos());
        let f = 0.3 * (50.0 * v).tanh() + 0.2 * v;
        text += &format!("{t},{q},{v},{f},{}\n", 100.0 * q);
    }
    std::fs::write(&log, text).unwrap();
    let ds = dir.join("ds.csv");
    let import = |extra: &[&str]| {
        let base = [
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
            "-o",
            s(&ds),
        ];
        frictl(&[&base[..], extra].concat())
    };
    // With the motor angle, Δθ needs r: the missing flag is named.
    let e = err_text(
        import(&["--column", "theta=theta"]),
        "θ without --gear-ratio",
    );
    assert!(e.contains("--gear-ratio is not given"), "{e}");
    crate::util::ok(import(&[]), "import without θ");
    let cv = dir.join("cv.json");
    ok(&["fit", "cv", s(&ds), "--json", s(&cv)]);
    let model = dir.join("m.fwt");
    let base = [
        "train",
        "--dataset",
        s(&ds),
        "--scv",
        s(&cv),
        "--out",
        s(&model),
        "--hidden",
        "8",
        "--history",
        "4",
        "--epochs",
        "1",
        "--val-frac",
        "0",
        "--test-frac",
        "0",
        "--quiet",
    ];
    ok(&[&base[..], &["--features", "joint-pos-joint-vel"]].concat());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `frictl distill` on one recording cut into blocks draws its default probes from the training
/// blocks' rows (a quarter of them), not from the dataset's one chunk id, which no block carries.
#[test]
fn distill_on_one_recording_draws_probes_from_its_training_blocks() {
    let dir = scratch("frictl-distill-one-recording");
    let ds = one_recording(&dir, "ds", 14.0, 0.0);
    let cv = dir.join("cv.json");
    ok(&["fit", "cv", s(&ds), "--json", s(&cv)]);
    let teacher = dir.join("t.fwt");
    ok(&small_train(&ds, &cv, &teacher, "16"));
    let out = frictl(&[
        "distill",
        s(&teacher),
        "--dataset",
        s(&ds),
        "--hidden",
        "8",
        "--epochs",
        "1",
        "-o",
        s(&dir.join("s.fwt")),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    let probes: usize = err
        .split(" probes;")
        .next()
        .and_then(|h| h.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no probe count in: {err}"));
    // 14 s at 1 kHz: the training blocks hold well over 4000 valid rows.
    assert!(probes > 1000, "{probes} probes: {err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
